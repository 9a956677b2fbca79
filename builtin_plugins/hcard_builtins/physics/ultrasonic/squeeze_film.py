"""Squeeze film levitation: the classic model of UV friction reduction (thesis section 2.2).

Kept as the model that the measurements of sections 2.2-2.3 contradict: it predicts friction
falling to zero at a finite amplitude (Fig. 2.4), a dependence on plate roughness, no dependence
on sliding speed (section 2.5.5), and a reduction proportional to the ambient pressure
(``gamma = 0.5`` at ``p0/2``, Eq. 2.10), where the measured reduction is unchanged (Fig. 2.12).

Geometry (Eq. 2.1, Fig. 2.3): the air gap under a 1-D finger pad with sinusoidal ridges is
``h(x, t) = h_r + h_vib (1 + cos wt) + h_e (1 + cos(2 pi x / L))``. Its peak-to-peak plate motion
is ``2 h_vib``, so ``h_vib = w/2`` for the peak-to-peak amplitude ``w`` used throughout hcard.
Normalised by the mean gap ``h_m = h_r + h_vib + h_e`` (``h0 + h_e`` of Eq. 2.6, ``h0 = h_r +
h_vib``) the gap is ``H = 1 + eps cos T + delta cos(k X)`` with ``eps = h_vib / h_m``,
``delta = h_e / h_m`` and ``k = 2 pi l0 / L`` (Eq. 2.6), ``X = x / l0`` in [-1/2, 1/2].

Pressure (Eq. 2.5, the ``sigma -> inf`` solution of the Reynolds equation 2.3)::

    P_inf / p = a sqrt(b^2 + 1.5 eps^2) / (b (a + eps cos T)),
    a = 1 + delta cos(k X),  b = 1 + delta cos(k / 2),

with ``p`` the ambient pressure. Levitation force (Eq. 2.7): the mean over the period and the
contact of the overpressure, times the loaded area ``l0 x contact_width`` (Eq. 2.7 is per unit
length; Table 2.1 gives only ``l0``, and the width defaults to ``l0``, a 1 cm^2 contact)::

    F_s = p l0 width (1/2pi) int_0^2pi int_-1/2^1/2 (P_inf / p - 1) dX dT.

The time integral is exact, ``(1/2pi) int dT / (a + eps cos T) = 1 / sqrt(a^2 - eps^2)`` (``a >=
1 - delta > eps`` because ``h_r > 0``); the ridge integral uses composite Gauss-Legendre rules
(48 nodes per half ridge period) on a fixed grid shared by all points, one ``points x nodes``
array per chunk.

Friction (Eq. 2.8, read dimensionally): the film carries ``F_s`` of the normal force, so the
Coulomb friction acts on the rest, ``mu' = max(0, 1 - F_s / Fn)``. Since ``P_inf`` scales with
``p``, ``F_s`` does too and ``gamma = (1 - mu'(p)) / (1 - mu'(p0)) = p / p0`` (Eq. 2.10) while
``mu'(p0) > 0``. With Table 2.1 and these readings (``h_vib = w/2``, a 1 cm^2 contact) friction
reaches zero at w = 2.15 um for 0.1 N (section 2.5.5 quotes ~2 um), 3.5 um for 0.2 N and 7.2 um
for 0.5 N.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable
from hcard.quantities import ATMOSPHERE_PA as ATMOSPHERE
from hcard_builtins.physics.ultrasonic._checks import check_inputs

GAUSS_NODES_PER_HALF_PERIOD = 48
CHUNK_ELEMENTS = 1 << 21
_BISECTIONS = 64


class SqueezeFilm(Predictor):
    """Squeeze film levitation (thesis Eqs. 2.1-2.8, Table 2.1): ``mu' = max(0, 1 - F_s/Fn)``.

    ``frequency`` and ``speed`` are accepted so that the UV models share their inputs, but the
    ``sigma -> inf`` solution depends on neither (check :meth:`squeeze_number` > 10 for it to
    hold). ``pressure`` is the ambient pressure. Extras: :meth:`levitation_force` (Eq. 2.7),
    :meth:`gamma` (Eq. 2.10), :meth:`squeeze_number` (Eq. 2.4). The inverse gives the amplitude
    for a target ``mu'`` (``mu' = 0``: the smallest amplitude that levitates the finger).
    """

    name: ClassVar[str] = "squeeze-film"
    calibrated: ClassVar[tuple[str, ...]] = ("roughness",)
    description: ClassVar[str] = (
        "UV squeeze film levitation, mu' = 1 - F_s/Fn (thesis Eqs. 2.1-2.8, Table 2.1); "
        "the classic model that chapter 2's measurements contradict"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter(
            "ridge_amplitude", "m", 50e-6, (1e-7, 1e-3), "Table 2.1 (h_e = 50 um)",
            "amplitude h_e of the sinusoidal fingerprint ridges",
        ),
        Parameter(
            "ridge_period", "m", 350e-6, (1e-6, 1e-2), "Table 2.1 (L = 350 um)",
            "period L of the fingerprint ridges",
        ),
        Parameter(
            "roughness", "m", 1.2e-6, (1e-9, 1e-3), "Table 2.1 (h_r = 1.2 um)",
            "surface roughness h_r of the plate: the smallest air gap",
        ),
        Parameter(
            "contact_length", "m", 1e-2, (1e-4, 0.1), "Table 2.1 (l0 = 1 cm)",
            "contact length l0 along the ridges' normal",
        ),
        Parameter(
            "contact_width", "m", 1e-2, (1e-4, 0.1),
            "assumption: Eq. 2.7 is per unit length; width = l0 (1 cm^2 contact)",
            "contact width that turns the force per length of Eq. 2.7 into a force",
        ),
        Parameter(
            "air_viscosity", "Pa s", 1.85e-5, (1e-6, 1e-3), "Table 2.1 (1.85e-5 Pa s)",
            "dynamic viscosity of air; enters only the squeeze number (Eq. 2.4)",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (
        Variable("amplitude", "m", "peak-to-peak plate vibration amplitude w (h_vib = w/2)"),
        Variable("normal_force", "N", "applied normal force Fn (Table 2.1: 0.1-0.5 N)", 0.5),
        Variable("pressure", "Pa", "ambient air pressure p", ATMOSPHERE),
        Variable("frequency", "Hz", "plate frequency f (no effect for sigma > 10)", 27_500.0),
        Variable("speed", "m/s", "finger sliding speed U (no effect in this model)", 0.020),
    )
    output: ClassVar[Variable] = Variable("relative_friction", "", "mu' = mu / mu0")
    inverse_input: ClassVar[str | None] = "amplitude"

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        self._k = 2 * math.pi * self["contact_length"] / self["ridge_period"]
        half = self._k / 2
        edges = np.append(np.arange(0.0, half, math.pi), half)
        x, w = np.polynomial.legendre.leggauss(GAUSS_NODES_PER_HALF_PERIOD)
        lo, hi = edges[:-1, None], edges[1:, None]
        theta = (lo + (hi - lo) * (x + 1) / 2).ravel()
        weights = ((hi - lo) / 2 * w).ravel()
        # int_{-1/2}^{1/2} F(cos kX) dX = (2/k) int_0^{k/2} F(cos theta) d theta (F is even)
        self._cos_nodes = np.cos(theta)
        self._weights = weights * 2 / self._k

    # -- pieces ----------------------------------------------------------------------------
    def _film(self, amplitude: np.ndarray) -> np.ndarray:
        """``(1/2pi) int int (P_inf/p - 1) dX dT`` (Eq. 2.7 without ``p l0 width``)."""
        h_vib = amplitude.ravel() / 2
        mean_gap = self["roughness"] + h_vib + self["ridge_amplitude"]
        eps = h_vib / mean_gap
        delta = self["ridge_amplitude"] / mean_gap
        b = 1 + delta * math.cos(self._k / 2)
        out = np.empty(h_vib.shape)
        chunk = max(1, CHUNK_ELEMENTS // self._cos_nodes.size)
        for start in range(0, out.size, chunk):
            part = slice(start, start + chunk)
            a = 1 + np.multiply.outer(delta[part], self._cos_nodes)
            q = (eps[part, None] / a) ** 2
            root = np.sqrt(1 - q)
            # a / sqrt(a^2 - eps^2) - 1 = 1/sqrt(1-q) - 1, written without cancellation
            excess = (q / (root * (1 + root))) @ self._weights
            time_space = 1 + excess
            edge = 1.5 * (eps[part] / b[part]) ** 2
            edge_excess = edge / (np.sqrt(1 + edge) + 1)  # sqrt(b^2 + 1.5 eps^2) / b - 1
            out[part] = edge_excess * time_space + excess
        return out.reshape(amplitude.shape)

    def _force(self, amplitude: np.ndarray, pressure: np.ndarray) -> np.ndarray:
        area = self["contact_length"] * self["contact_width"]
        return pressure * area * self._film(amplitude)

    def levitation_force(self, **inputs: Any) -> np.ndarray:
        """The squeeze film force ``F_s`` (N) carried by the air film (Eq. 2.7 times area)."""
        arrays = self._checked(self._inputs(inputs))
        return self._force(arrays["amplitude"], arrays["pressure"])

    def gamma(self, reference_pressure: float = ATMOSPHERE, **inputs: Any) -> np.ndarray:
        """``gamma = (1 - mu'(p)) / (1 - mu'(p0))`` (Eq. 2.10), ``p0 = reference_pressure``.

        ``p / p0`` while the friction at ``p0`` has not reached zero (0.5 at ``p0/2``).
        """
        arrays = self._checked(self._inputs(inputs))
        reference = check_inputs(
            self.name, {"pressure": reference_pressure}, positive=("pressure",)
        )
        at_p = self._relative(arrays)
        at_p0 = self._relative({**arrays, "pressure": reference["pressure"]})
        with np.errstate(divide="ignore", invalid="ignore"):
            return (1 - at_p) / (1 - at_p0)

    def squeeze_number(self, **inputs: Any) -> np.ndarray:
        """``sigma = 12 eta omega l0^2 / (h_m^2 p)`` (Eq. 2.4), the mean gap ``h_m`` as gap.

        Eq. 2.5 assumes ``sigma -> inf``; ``sigma > 10`` is taken as enough (section 2.2.1),
        which with Table 2.1 holds from 19.4 kHz at 1 um and 19.8 kHz at 2 um (12.6 at 25 kHz
        and 2 um), close to the thesis's "> 25 kHz"; 1 atm ambient pressure.
        """
        arrays = self._checked(self._inputs(inputs))
        gap = self["roughness"] + arrays["amplitude"] / 2 + self["ridge_amplitude"]
        omega = 2 * math.pi * arrays["frequency"]
        with np.errstate(divide="ignore"):
            return (
                12 * self["air_viscosity"] * omega * self["contact_length"] ** 2
                / (gap**2 * arrays["pressure"])
            )

    def _checked(self, arrays: dict[str, Any]) -> dict[str, np.ndarray]:
        return check_inputs(self.name, arrays, positive=("normal_force",))

    def _relative(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        force = self._force(arrays["amplitude"], arrays["pressure"])
        return np.clip(1 - force / arrays["normal_force"], 0.0, 1.0)

    # -- maps ------------------------------------------------------------------------------
    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        return self._relative(self._checked(inputs))

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        """Amplitude (m) with ``F_s(w) = (1 - mu') Fn`` for a target ``mu'`` in [0, 1].

        ``F_s`` rises monotonically with ``w``: bracket by doubling from 1 um, then bisect.
        ``mu' = 0`` gives the smallest amplitude at which the film carries the whole load.
        """
        outside = ~((target >= 0) & (target <= 1))
        if np.any(outside):
            raise PredictorError(
                f"{self.name}: target relative_friction must be in [0, 1], got "
                f"{target[outside].flat[0]:g}"
            )
        arrays = self._checked({**inputs, "target": target})
        goal = arrays.pop("target")
        needed = (1 - goal) * arrays["normal_force"]
        pressure = arrays["pressure"]
        if np.any((pressure == 0) & (needed > 0)):
            raise PredictorError(
                f"{self.name}: input pressure is 0 Pa: no film, so no friction reduction"
            )
        low = np.zeros(goal.shape)
        high = np.full(goal.shape, 1e-6)
        short = self._force(high, pressure) < needed
        while short.any():
            if high.max() > 1.0:
                raise PredictorError(f"{self.name}: target needs an amplitude above 1 m")
            low = np.where(short, high, low)
            high = np.where(short, 2 * high, high)
            short = self._force(high, pressure) < needed
        for _ in range(_BISECTIONS):
            middle = (low + high) / 2
            short = self._force(middle, pressure) < needed
            low = np.where(short, middle, low)
            high = np.where(short, high, middle)
        return np.where(needed > 0, high, 0.0)
