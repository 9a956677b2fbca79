"""The dimensionless group of ultrasonic friction reduction (thesis section 2.7, Eqs. 2.29-2.33).

To first order the contact time is ``t_c ~ F_reac / (kn w f)`` and the time to slip
``t_s ~ mu0 F_reac / (kl U)``, so friction is governed by their ratio (Eq. 2.29)::

    Psi = kl U / (kn w f mu0),

which for a finger pad, whose normal and lateral springs share one contact area so that
``kl / kn ~ G_sc / E_sc``, becomes (Eq. 2.30)::

    Psi = U / (w f mu0 (1 + nu)).

A first-order rate law ``d mu' / d Psi = b (1 - mu')`` (Eqs. 2.31-2.32) with ``mu' = 0`` at
``Psi = 0`` integrates to (Eq. 2.33, whose printed form lost the minus sign)::

    mu' = 1 - exp(-Psi / Psi*).

``Psi*`` is the characteristic value. Presets (:data:`PSI_STAR_PRESETS`, fitted against the
Eq. 2.30 group; ``nu = 0.33`` is the Table 2.3 value, used here for all of them): 2.38 for the
FE model (Fig. 2.24), 4.69 in vivo
for one participant (Fig. 2.36), 0.70 for the artificial probe (Fig. 2.37), and the population
fit ``Psi*(Fn) = 1.80 - 0.094 Fn`` (Fn in N, Fig. 2.39). The predictor carries ``psi_star`` and
``psi_star_normal_force_slope`` so that ``Psi*(Fn) = psi_star + slope Fn`` covers all four.

The inverse is closed form: the amplitude giving a target ``mu'`` at the current speed,
``w = U / (Psi f mu0 (1 + nu))`` with ``Psi = -Psi* ln(1 - mu')``; it is what velocity-compensated
rendering uses.

Range. The thesis states the correlation for amplitudes above 1 um only: "the data at smaller
amplitudes diverge from the correlation since there is a significant dependence on [Young's
moduli and normal force] that is not taken into account" (section 2.7.1) and "the vibrational
amplitude must be > 1 um for the range of frequencies examined" (section 2.10).
:data:`EQ_2_33_MIN_AMPLITUDE` carries that bound; :func:`hcard.physics.actuation.actuate`
flags every frame whose chosen amplitude falls below it. The spring-slider
(:mod:`.spring_slider`, Eqs. 2.19-2.28) has no such bound and an amplitude inverse of its own.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable
from hcard_builtins.physics.ultrasonic._checks import check_inputs

EQ_2_33_MIN_AMPLITUDE = 1e-6
"""Smallest peak-to-peak amplitude, m, for which the thesis states Eq. 2.33 (sections 2.7.1,
2.10: w > 1 um)."""


class PsiStarPreset(NamedTuple):
    """A published ``Psi*``: ``Psi*(Fn) = psi_star + normal_force_slope Fn``."""

    psi_star: float
    normal_force_slope: float
    source: str


PSI_STAR_PRESETS: dict[str, PsiStarPreset] = {
    "fe": PsiStarPreset(2.38, 0.0, "FE model of a fingerprint ridge, Fig. 2.24 (2.38 +/- 0.21)"),
    "in_vivo": PsiStarPreset(4.69, 0.0, "participant p5, Fig. 2.36 (4.69 +/- 0.32)"),
    "probe": PsiStarPreset(0.70, 0.0, "artificial fingertip probe, Fig. 2.37 (0.70 +/- 0.04)"),
    "population": PsiStarPreset(
        1.80, -0.094, "mean of participants p1-p6, linear fit in Fn, Fig. 2.39"
    ),
}
"""Published characteristic values of the dimensionless group, by name."""


class PsiStarFit(NamedTuple):
    """Least-squares fit of Eq. 2.33: the characteristic value and the RMSE in ``mu'``."""

    psi_star: float
    rmse: float


def fit_psi_star(psi: Any, relative_friction: Any) -> PsiStarFit:
    """Fit ``mu' = 1 - exp(-Psi / Psi*)`` (Eq. 2.33) to data by least squares in ``mu'``.

    ``psi`` and ``relative_friction`` are matching arrays (dimensionless); points with an
    infinite ``psi`` (no vibration) carry no information and are skipped. The search runs over
    ``log Psi*`` in [1e-4, 1e4].
    """
    x = np.asarray(psi, dtype=np.float64).ravel()
    y = np.asarray(relative_friction, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise PredictorError(
            f"fit_psi_star: psi and relative_friction differ in size ({x.size} vs {y.size})"
        )
    keep = np.isfinite(x)
    x, y = x[keep], y[keep]
    if x.size == 0 or not np.all(np.isfinite(y)) or np.any(x < 0):
        raise PredictorError("fit_psi_star: needs finite relative friction and psi >= 0")

    def sse(log_psi_star: float) -> float:
        residual = 1.0 - np.exp(-x / math.exp(log_psi_star)) - y
        return float(residual @ residual)

    from scipy.optimize import minimize_scalar  # a fitting helper: hosts that only predict
    # (a conformance run under TCG) never import scipy.optimize

    best = minimize_scalar(
        sse, bounds=(math.log(1e-4), math.log(1e4)), method="bounded",
        options={"xatol": 1e-10},
    )
    return PsiStarFit(math.exp(best.x), math.sqrt(sse(best.x) / x.size))


class DimensionlessGroup(Predictor):
    """``mu' = 1 - exp(-Psi / Psi*)``, ``Psi = U / (w f mu0 (1 + nu))`` (Eqs. 2.30, 2.33).

    ``Psi*`` may depend linearly on the normal force (Fig. 2.39). Build a published variant with
    :meth:`from_preset`. Without vibration (``w = 0`` or ``f = 0``) ``mu' = 1``; a resting
    finger (``U = 0``) under vibration has ``Psi = 0`` and ``mu' = 0``, the boundary condition of
    Eq. 2.33.
    """

    name: ClassVar[str] = "dimensionless-group"
    calibrated: ClassVar[tuple[str, ...]] = ("mu0", "psi_star")
    description: ClassVar[str] = (
        "UV friction from the dimensionless group Psi = U/(w f mu0 (1+nu)): "
        "mu' = 1 - exp(-Psi/Psi*) (thesis Eqs. 2.29-2.33)"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter(
            "mu0", "", 0.5, (0.01, 5.0), "Figs. 2.21, 2.24 (0.5)",
            "intrinsic friction coefficient without vibration",
        ),
        Parameter(
            "poisson_ratio", "", 0.33, (0.0, 0.5), "Table 2.3; Eq. 2.30",
            "Poisson's ratio nu of the stratum corneum (kl/kn ~ G/E)",
        ),
        Parameter(
            "psi_star", "", PSI_STAR_PRESETS["fe"].psi_star, (1e-3, 1e3),
            "Eq. 2.33; Fig. 2.24 (FE, 2.38); presets 4.69 (Fig. 2.36), 0.70 (Fig. 2.37), "
            "1.80 (Fig. 2.39)",
            "characteristic value of Psi at zero normal force",
        ),
        Parameter(
            "psi_star_normal_force_slope", "1/N", 0.0, (-100.0, 100.0),
            "Fig. 2.39 (population fit: -0.094 /N)",
            "dPsi*/dFn: Psi*(Fn) = psi_star + slope Fn",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (
        Variable("amplitude", "m", "peak-to-peak plate vibration amplitude w"),
        Variable("frequency", "Hz", "plate vibration frequency f (Fig. 2.24: 27.5 kHz)", 27_500.0),
        Variable("speed", "m/s", "finger sliding speed U (Fig. 2.24: 20 mm/s)", 0.020),
        Variable(
            "normal_force", "N", "applied normal force Fn (only through Psi*(Fn))", 0.5
        ),
    )
    output: ClassVar[Variable] = Variable("relative_friction", "", "mu' = mu / mu0")
    inverse_input: ClassVar[str | None] = "amplitude"
    valid_amplitude_min: ClassVar[float] = EQ_2_33_MIN_AMPLITUDE
    """Below this amplitude (m) the model is outside its stated range (sections 2.7.1, 2.10)."""
    valid_amplitude_source: ClassVar[str] = "Eq. 2.33 holds for w > 1 um (sections 2.7.1, 2.10)"

    @classmethod
    def from_preset(cls, preset: str, **params: float) -> DimensionlessGroup:
        """An instance with the ``Psi*`` of a named preset (:data:`PSI_STAR_PRESETS`).

        Other parameters (``mu0``, ``poisson_ratio``) may be given too.
        """
        try:
            chosen = PSI_STAR_PRESETS[preset]
        except KeyError:
            raise PredictorError(
                f"{cls.name}: unknown preset {preset!r}; presets: {', '.join(PSI_STAR_PRESETS)}"
            ) from None
        values = {
            "psi_star": chosen.psi_star,
            "psi_star_normal_force_slope": chosen.normal_force_slope,
            **params,
        }
        return cls(**values)

    # -- pieces ----------------------------------------------------------------------------
    def psi(self, **inputs: Any) -> np.ndarray:
        """The dimensionless group ``Psi = U / (w f mu0 (1 + nu))`` (Eq. 2.30).

        ``inf`` without vibration (``w f = 0``, whatever the speed), which gives ``mu' = 1``.
        """
        arrays = self._checked(self._inputs(inputs))
        return self._psi(arrays)

    def psi_star_at(self, normal_force: Any) -> np.ndarray:
        """``Psi*(Fn) = psi_star + slope Fn`` (Fig. 2.39); must be positive."""
        force = check_inputs(self.name, {"normal_force": normal_force}, positive=())[
            "normal_force"
        ]
        return self._psi_star(force)

    def _psi_star(self, force: np.ndarray) -> np.ndarray:
        """``Psi*(Fn)`` (Fig. 2.39) at checked forces ``force`` (N); :class:`PredictorError`
        where it is not positive."""
        value = self["psi_star"] + self["psi_star_normal_force_slope"] * force
        if np.any(value <= 0):
            bad = force[value <= 0].flat[0]
            raise PredictorError(
                f"{self.name}: Psi*(Fn) = {self['psi_star']:g} "
                f"{self['psi_star_normal_force_slope']:+g} Fn is not positive at "
                f"normal_force = {bad:g} N"
            )
        return value

    def _psi_star_trusted(self, force: np.ndarray) -> np.ndarray | float:
        """:meth:`_psi_star` for finite forces: without a force slope ``Psi*`` is the constant
        ``psi_star`` (``psi_star + 0 Fn`` is exactly that, and its bounds keep it positive)."""
        values = self._values
        slope, psi_star = values["psi_star_normal_force_slope"], values["psi_star"]
        if isinstance(slope, float) and slope == 0.0 and isinstance(psi_star, float):
            return psi_star
        return self._psi_star(force)

    def _checked(self, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return check_inputs(self.name, arrays)

    def _psi(self, arrays: Mapping[str, np.ndarray]) -> np.ndarray:
        """Eq. 2.30 of checked inputs: ``U / (w f mu0 (1 + nu))``, ``inf`` where ``w f = 0``
        (no division there)."""
        values = self._values
        denominator = np.asarray(  # an array even for scalar inputs (0-d)
            arrays["amplitude"] * arrays["frequency"] * values["mu0"]
            * (1 + values["poisson_ratio"])
        )
        speed = arrays["speed"]
        shape = denominator.shape
        speed_shape = getattr(speed, "shape", ())
        if speed_shape != shape:
            shape = np.broadcast_shapes(speed_shape, shape)
        psi = np.empty(shape)
        # an amplitude so small that U / (w f ...) overflows is Psi = inf, the limit of no
        # vibration (mu' = 1): exact, not worth a warning
        with np.errstate(over="ignore"):
            if denominator.size and np.minimum.reduce(denominator, axis=None) > 0:
                return np.divide(speed, denominator, out=psi)  # vibrating everywhere
            psi.fill(np.inf)
            np.divide(speed, denominator, out=psi, where=denominator > 0)
        return psi

    # -- maps ------------------------------------------------------------------------------
    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        arrays = self._checked(inputs)
        psi_star = self.psi_star_at(arrays["normal_force"])
        with np.errstate(over="ignore"):  # Psi near the float limit: Psi / Psi* = inf, mu' = 1
            return -np.expm1(-self._psi(arrays) / psi_star)

    def forward_trusted(self, **inputs: Any) -> np.ndarray:
        """:meth:`forward` (Eqs. 2.30, 2.33) for inputs already checked (finite, >= 0; see
        :meth:`Predictor.forward_trusted`): the same numbers without the input checks."""
        arrays = self._trusted_inputs(inputs)
        psi_star = self._psi_star_trusted(arrays["normal_force"])
        mu = self._psi(arrays)  # a new array: computed in place, as -expm1(-Psi / Psi*)
        np.negative(mu, out=mu)
        np.divide(mu, psi_star, out=mu)
        np.expm1(mu, out=mu)
        return np.negative(mu, out=mu)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        """Amplitude (m) for a target ``mu'`` in (0, 1]: ``w = U / (Psi f mu0 (1 + nu))`` with
        ``Psi = -Psi* ln(1 - mu')``. ``mu' = 1`` needs no vibration (0 m). At ``U = 0`` no
        amplitude reaches a target below 1 (any vibration gives ``mu' = 0``); 0 m is returned."""
        outside = ~((target > 0) & (target <= 1))
        if np.any(outside):
            raise PredictorError(
                f"{self.name}: target relative_friction must be in (0, 1], got "
                f"{target[outside].flat[0]:g} (mu' = 0 needs an infinite amplitude)"
            )
        arrays = self._checked({**inputs, "target": target})
        goal = arrays.pop("target")
        if np.any(arrays["frequency"] <= 0):
            raise PredictorError(f"{self.name}: input frequency must be > 0 Hz for the inverse")
        return self._amplitude(goal, arrays, self.psi_star_at(arrays["normal_force"]))

    def inverse_trusted(self, target: Any, **inputs: Any) -> np.ndarray:
        """:meth:`inverse` for a target in (0, 1] and inputs already checked (finite, >= 0,
        frequency > 0; see :meth:`Predictor.inverse_trusted`): the same numbers without the
        input checks."""
        arrays = self._trusted_inputs({**inputs, "amplitude": 0.0})
        return self._amplitude(np.asarray(target, dtype=np.float64), arrays,
                               self._psi_star_trusted(arrays["normal_force"]))

    def _amplitude(self, goal: np.ndarray, arrays: Mapping[str, np.ndarray],
                   psi_star: np.ndarray | float) -> np.ndarray:
        """The inverse of Eq. 2.33 through Eq. 2.30: ``w = U / (Psi f mu0 (1 + nu))`` with
        ``Psi = -Psi* ln(1 - mu')`` (m) for checked ``goal`` (mu') and inputs."""
        with np.errstate(divide="ignore"):
            psi = -psi_star * np.log1p(-goal)
        frequency: np.ndarray | float = arrays["frequency"]
        if np.ndim(frequency) == 0:  # one plate frequency: the same product, in floats
            frequency = float(frequency)
        scale = frequency * self["mu0"] * (1 + self["poisson_ratio"])
        return arrays["speed"] / (psi * scale)
