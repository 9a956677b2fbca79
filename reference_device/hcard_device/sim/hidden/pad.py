"""The finger pad of Table 3.2 pressed flat by the load (``finger-geometry``, Eq. 3.18).

The pad (:class:`~hcard_builtins.physics.electrovibration.geometry.FingerGeometry` at its
Table 3.2 defaults: an ellipsoidal cap of width ``a`` and height ``b`` carrying ridges) touches
the insulator at its lowest point. A normal force presses it flat to a depth ``h``: every patch
whose sag ``b/2 (1 - sqrt(1 - r^2/(a/2)^2))`` is under ``h`` lies on the insulator, the others
keep an air gap ``sag - h``; the ridge valleys keep their air (the ridged epidermis is stiffer
than the pulp, section 1.4.2.1). The force per volt squared of Eq. 3.18 summed over the patches
is ``C(h)``, tabulated here at :data:`DEPTHS` depths (quadratically spaced: dense near ``h = 0``
where it rises fastest) and interpolated linearly. Beyond the rim's sag the whole pad is flat.

The depth follows the load as ``h = h_1 (Fn / 1 N)^m``: for the near-paraboloidal pad the flat
area is proportional to ``h``, so ``m`` is the areal load index of Eq. 1.4 (``A = k_1 Fn^m``,
Hertz ``m = 2/3``, Eq. 1.5), and ``h_1`` = :data:`DEPTH_AT_1N` flattens about 1 cm^2 at 1 N, the
contact area of section 3.6.1.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hcard_builtins.physics.electrovibration import geometry

DEPTH_AT_1N = 1.75e-3
"""Flattened depth at 1 N, m (1.03 cm^2 of the Table 3.2 pad flat; ~2 mm pulp displacement at
~1 N, Fig. 1.7)."""
DEPTHS = 161
"""Depths at which ``C(h)`` is tabulated."""


@lru_cache(maxsize=1)
def _table() -> tuple[np.ndarray, np.ndarray]:
    """``(h, C(h))``: depths (m) from 0 to the rim's sag and the force per volt squared
    (N/V^2) of the pad flattened to each."""
    pad = geometry.FingerGeometry()
    patches = pad.patches()
    half = pad["finger_width"] / 2.0
    r2 = np.minimum((patches.x**2 + patches.y**2) / half**2, 1.0)
    sag = 0.5 * pad["finger_height"] * (1.0 - np.sqrt(1.0 - r2))
    valley = np.maximum(patches.offset - sag, 0.0)
    depths = float(sag.max()) * np.linspace(0.0, 1.0, DEPTHS) ** 2
    per_volt = np.array([
        geometry.discretised_force(
            1.0, patches.area, pad["sc_thickness"], np.maximum(sag - h, 0.0) + valley,
            sc_permittivity=pad["sc_permittivity"],
            insulator_thickness=pad["insulator_thickness"],
            insulator_permittivity=pad["insulator_permittivity"],
            air_permittivity=pad["air_permittivity"])
        for h in depths])
    return depths, per_volt


def flattened_ratio(normal_force_n: np.ndarray, area_index: float) -> np.ndarray:
    """``C(h(Fn)) / C(h_1)``: the pad's EV force at ``Fn`` (N) relative to its force at 1 N,
    with the areal load index ``area_index`` (``m``)."""
    depths, per_volt = _table()
    reference = np.interp(DEPTH_AT_1N, depths, per_volt)
    depth = DEPTH_AT_1N * np.power(np.maximum(normal_force_n, 0.0), area_index)
    return np.interp(np.minimum(depth, depths[-1]), depths, per_volt) / reference
