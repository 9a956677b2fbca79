"""Electrostatic force over a discretised finger surface, Eq. 3.18 (section 3.5.2, Fig. 3.8).

The finger is not a flat plate: its pad is curved and ridged, so the air gap varies over the
surface. Eq. 3.18 sums the parallel-plate law of Eq. 3.17 over small patches ``j`` of
projected area ``A^j``, each with its own air gap ``d_a^j`` (and stratum corneum ``d_sc^j``):

``F_e = sum_j eps0 v^2 A^j / (2 (d_sc^j/eps_sc + d_a^j/eps_a + d_i/eps_i)(d_sc^j + d_a^j + d_i))``

(vertical components only, no fringing: footnote to Eq. 3.18).

:class:`FingerGeometry` builds the patches from the Table 3.2 finger: the pad is the surface of
revolution (the axial symmetry of section 3.9) of the elliptical cross-section of width
``a`` = 16.68 mm and height ``b`` = 12.79 mm, so the gap under the point at radius ``r`` from
the lowest point grows by the sag ``(b/2)(1 - sqrt(1 - (2r/a)^2))``; fingerprint ridges of width
``R_w`` = 0.50 mm and height ``R_h`` = 0.15 mm run across the pad as a raised-cosine
corrugation of period ``R_w`` (one ridge per ``R_w``, as in the single-fingerprint cell of
Fig. 3.7), adding up to ``R_h`` of air in the valleys. ``air_gap`` is the distance from the
insulator to the lowest ridge crest. The stratum corneum (0.2 mm) follows the ridges, so
``d_sc^j`` is uniform. The finger is rigid (a hovering finger, section 3.5.3): no flattening
under load.

Because the far parts of a curved finger approach the plate as it comes closer, the force
falls with distance much more slowly than the flat model's (Fig. 3.11b): for the defaults,
``F(0.5 mm) / F(0.25 mm)`` is 0.59 against 0.36 for Eq. 3.17 (2.10 mN at 0.25 mm and
2000 V, 1.25 mN at 0.5 mm: inside the 0.5-4.4 mN spread of Table 3.3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable

from ._common import (
    EPSILON_0,
    air_permittivity_parameter,
    check_finite,
    check_non_negative,
    insulator_parameters,
    sc_parameters,
    voltage_for_force,
)
from .air_layer import AIR_GAP
from .static import FORCE, VOLTAGE

_CHUNK_ELEMENTS = 1 << 22
"""Gap values x patches evaluated at once (bounds the temporary memory to ~100 MB)."""


def discretised_force(
    voltage: np.ndarray | float,
    patch_area: np.ndarray,
    sc_thickness: np.ndarray | float,
    air_gap: np.ndarray | float,
    *,
    sc_permittivity: float,
    insulator_thickness: float,
    insulator_permittivity: float,
    air_permittivity: float = 1.0,
) -> np.ndarray:
    """The total force of Eq. 3.18 in N: the sum over patches of Eq. 3.17.

    ``patch_area`` (m^2), ``sc_thickness`` (m) and ``air_gap`` (m) are per-patch arrays
    (broadcast together along the last axis, which is summed); ``voltage`` (V) broadcasts with
    the remaining leading axes of the result.
    """
    electrical = (
        np.asarray(sc_thickness) / sc_permittivity
        + np.asarray(air_gap) / air_permittivity
        + insulator_thickness / insulator_permittivity
    )
    mechanical = np.asarray(sc_thickness) + np.asarray(air_gap) + insulator_thickness
    per_volt = np.sum(EPSILON_0 * patch_area / (2.0 * electrical * mechanical), axis=-1)
    return per_volt * np.square(voltage)


@dataclass(frozen=True)
class FingerPatches:
    """The discretised finger surface of :class:`FingerGeometry`.

    Attributes:
        x: patch centres across the ridges, m (shape ``(n,)``; 0 under the lowest point).
        y: patch centres along the ridges, m.
        area: projected patch areas ``A^j``, m^2.
        offset: extra air under each patch relative to the lowest ridge crest, m (sag of the
            pad plus ridge valley depth); the local gap is ``air_gap + offset``.
    """

    x: np.ndarray
    y: np.ndarray
    area: np.ndarray
    offset: np.ndarray

    @property
    def total_area(self) -> float:
        """Projected area of the pad, m^2."""
        return float(np.sum(self.area))


class FingerGeometry(Predictor):
    """Electrostatic force on a curved, ridged finger pad, Eq. 3.18 over Table 3.2 geometry.

    Inputs: ``voltage`` (V) and ``air_gap`` (m, >= 0: insulator to the lowest ridge crest;
    default 0, touching without deformation). Output: ``electrostatic_force`` in N, the sum of
    Eq. 3.17 over the patches of :meth:`patches` (vectorised over patches and gaps). Inverse:
    the voltage amplitude for a target force at the given gap.

    Setting ``finger_height`` to 0 and ``ridge_height`` to 0 gives a flat disc of diameter
    ``finger_width``, i.e. Eq. 3.17 with ``A = pi a^2 / 4``.
    """

    name: ClassVar[str] = "ev-finger-geometry"
    calibrated: ClassVar[tuple[str, ...]] = ("finger_width",)
    description: ClassVar[str] = (
        "Electrovibration force summed over a curved, ridged finger pad (Eq. 3.18, Table 3.2)"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter(
            "finger_width",
            "m",
            16.68e-3,
            (1e-3, 5e-2),
            "Table 3.2 (a)",
            "finger pad cross-section width a (diameter of the modelled pad)",
        ),
        Parameter(
            "finger_height",
            "m",
            12.79e-3,
            (0.0, 5e-2),
            "Table 3.2 (b)",
            "finger pad cross-section height b (0: flat pad)",
        ),
        Parameter(
            "ridge_width",
            "m",
            0.50e-3,
            (1e-5, 5e-3),
            "Table 3.2 (R_w)",
            "fingerprint ridge width R_w (ridge period)",
        ),
        Parameter(
            "ridge_height",
            "m",
            0.15e-3,
            (0.0, 2e-3),
            "Table 3.2 (R_h)",
            "fingerprint ridge height R_h (0: no ridges)",
        ),
        *sc_parameters(200e-6, 1650.0, "Table 3.2"),
        *insulator_parameters(90e-6, 3.35, "Table 3.2"),
        air_permittivity_parameter(),
        Parameter(
            "patch_size",
            "m",
            50e-6,
            (1e-6, 1e-3),
            "Fig. 3.8 (discretisation)",
            "side of the square patches; 10 per ridge by default",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (VOLTAGE, AIR_GAP)
    output: ClassVar[Variable] = FORCE
    inverse_input: ClassVar[str | None] = "voltage"

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        # An odd count puts a patch centre under the lowest point (the first ridge crest).
        cells = math.ceil(self["finger_width"] / self["patch_size"]) // 2 * 2 + 1
        if cells > 4000:
            raise PredictorError(
                f"{self.name}: patch_size {self['patch_size']:g} m gives {cells} patches across "
                f"the finger (at most 4000); use larger patches"
            )
        self._patches = self._build_patches(cells)

    def _build_patches(self, cells: int) -> FingerPatches:
        half_width = self["finger_width"] / 2.0
        step = self["finger_width"] / cells
        centres = (np.arange(cells) + 0.5) * step - half_width
        x, y = np.meshgrid(centres, centres, indexing="ij")
        r2 = (x * x + y * y) / (half_width * half_width)
        inside = r2 < 1.0
        x, y, r2 = x[inside], y[inside], r2[inside]
        sag = 0.5 * self["finger_height"] * (1.0 - np.sqrt(1.0 - r2))
        valley = 0.5 * self["ridge_height"] * (1.0 - np.cos(2.0 * np.pi * x / self["ridge_width"]))
        area = np.full(x.shape, step * step)
        return FingerPatches(x=x, y=y, area=area, offset=sag + valley)

    def patches(self) -> FingerPatches:
        """The discretised pad (Fig. 3.8): patch centres, projected areas, extra air gaps."""
        return self._patches

    def coefficient(self, air_gap: np.ndarray | float) -> np.ndarray:
        """``F_e / v^2`` in N/V^2 at each ``air_gap`` (m): Eq. 3.18 at 1 V.

        Vectorised over patches and over the gaps (evaluated in chunks of bounded memory).
        """
        gap = check_non_negative("air_gap", np.asarray(air_gap, dtype=np.float64), "m")
        unique, inverse = np.unique(gap.ravel(), return_inverse=True)
        patches = self._patches
        per_chunk = max(1, _CHUNK_ELEMENTS // patches.area.size)
        values = np.empty(unique.shape)
        for start in range(0, unique.size, per_chunk):
            gaps = unique[start : start + per_chunk, None] + patches.offset[None, :]
            values[start : start + per_chunk] = discretised_force(
                1.0,
                patches.area,
                self["sc_thickness"],
                gaps,
                sc_permittivity=self["sc_permittivity"],
                insulator_thickness=self["insulator_thickness"],
                insulator_permittivity=self["insulator_permittivity"],
                air_permittivity=self["air_permittivity"],
            )
        return values[inverse].reshape(gap.shape)

    def patch_forces(self, voltage: float, air_gap: float) -> np.ndarray:
        """The per-patch terms ``F_ej`` of Eq. 3.18 in N at one voltage (V) and gap (m)."""
        volts = check_finite("voltage", np.asarray(voltage, dtype=np.float64))
        gap = check_non_negative("air_gap", np.asarray(air_gap, dtype=np.float64), "m")
        if volts.ndim or gap.ndim:
            raise PredictorError("patch_forces: voltage and air_gap must be scalars")
        patches = self._patches
        electrical = (
            self["sc_thickness"] / self["sc_permittivity"]
            + (gap + patches.offset) / self["air_permittivity"]
            + self["insulator_thickness"] / self["insulator_permittivity"]
        )
        mechanical = self["sc_thickness"] + gap + patches.offset + self["insulator_thickness"]
        return EPSILON_0 * float(volts) ** 2 * patches.area / (2.0 * electrical * mechanical)

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        voltage = check_finite("voltage", inputs["voltage"])
        return self.coefficient(inputs["air_gap"]) * np.square(voltage)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        return voltage_for_force(target, self.coefficient(inputs["air_gap"]))
