"""Friction of a bare finger pad sliding on a smooth surface (thesis sections 1.4.2 and 2.9.2.2).

The finger is not a Coulomb slider. :class:`FingerFriction` combines the three effects the
thesis reviews into one forward map from normal force, sliding speed and contact time to the
lateral (friction) force:

``F_l = mu(t) g(U) F_ref (Fn / F_ref)^n``, ``F_ref = 1 N``

- **Load (Eqs. 1.7, 2.35).** Adhesive friction over a Hertz-like contact area gives a power law
  ``F_l = k Fn^n`` with the frictional load index ``2/3 <= n <= 1`` (``n = 2/3``: Hertzian
  area, Eq. 1.5-1.6; ``n = 1``: Coulomb); the coefficient ``mu = F_l/Fn = k Fn^(n-1)``
  therefore rises as the load falls (Eq. 1.8). ``k`` is written ``mu(t) g(U) F_ref^(1-n)``, so
  ``mu`` is the friction coefficient at ``Fn = 1 N`` and the peak speed. Default ``n = 0.91``,
  the 10th-cycle fit of Fig. 2.32 (``k_f = 0.52``); the 1st cycle gave ``k_f = 0.49``,
  ``n = 1.05`` (:data:`PRESETS`).
- **Occlusion (Fig. 1.11, section 1.4.2.2).** Moisture from the sweat pores plasticises the
  ridges and the real contact area grows, following first-order kinetics:
  ``mu(t) = mu_occ - (mu_occ - mu_0) exp(-t / tau_occ)``, from ``mu_0 = 0.36`` to
  ``mu_occ = 0.79`` (Smith and Scott [46]), with ``tau_occ = 20 s``, the characteristic time
  of occlusion on smooth impermeable surfaces (Dzidek et al., EuroHaptics 2014, co-authored
  with the thesis' reference [40]; Pasumarty et al. [48] found it independent of speed).
  ``friction_initial > friction_occluded`` is allowed: on porous surfaces friction falls
  with contact time instead [40].
- **Speed (Fig. 1.12, section 1.4.2.3).** Stochastic adhesion (Schallamach [51]): bonds
  stretched longer before breaking raise friction with speed until they have no time to
  re-form, giving a maximum inside the exploration range 10-120 mm/s [28]. The shape is a
  peak symmetric in log speed, the Debye-like response of two bond-kinetics times:
  ``g(U) = 1 - s + s * 2 (U/U_p) / (1 + (U/U_p)^2)``, equal to 1 at the peak speed ``U_p``.
  ``U_p = 40 mm/s`` (near the geometric centre of 10-120 mm/s, and the speed of the Fig. 2.32
  fits, so that their ``k_f`` needs no speed correction); the depth ``s = 0.3`` (friction 30 %
  lower far from the peak; 16 % lower at 10 mm/s) is an assumption of the order of the
  variation in Fig. 1.12, whose data the thesis does not tabulate: fit it for a given
  finger and surface.

Output ``lateral_force`` in N; :meth:`FingerFriction.friction_coefficient` gives ``F_l/Fn``.
The inverse gives the normal force that produces a target lateral force.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable

REFERENCE_FORCE = 1.0
"""``F_ref`` in N: the friction coefficients are quoted at this normal force."""

EXPLORATION_SPEED_RANGE = (0.010, 0.120)
"""Speeds of tactile exploration in m/s (section 1.4.2.3, [28]): where Fig. 1.12 peaks."""

PRESETS: dict[str, dict[str, float]] = {
    "occlusion-smith-scott": {
        "friction_initial": 0.36,
        "friction_occluded": 0.79,
        "load_index": 0.91,
    },
    "fig-2.32-cycle-1": {"friction_initial": 0.49, "friction_occluded": 0.49, "load_index": 1.05},
    "fig-2.32-cycle-10": {
        "friction_initial": 0.52,
        "friction_occluded": 0.52,
        "load_index": 0.91,
    },
}
"""Named parameter sets: the default (occlusion from 0.36 to 0.79, Fig. 1.11/[46]) and the
power-law fits of Fig. 2.32 (section 2.9.2.2, k_f and n at 40 mm/s, no occlusion growth)."""


def _check(name: str, value: np.ndarray, unit: str, *, allow_inf: bool = False) -> np.ndarray:
    """``value``, or :class:`PredictorError` naming ``name`` if NaN, infinite or negative."""
    bad = np.isnan(value) if allow_inf else ~np.isfinite(value)
    if np.any(bad):
        raise PredictorError(f"{name}: all values must be finite numbers")
    if np.any(value < 0):
        raise PredictorError(f"{name}: must be >= 0 {unit}, got {float(np.min(value)):g}")
    return value


class FingerFriction(Predictor):
    """Lateral friction force of a bare finger pad: load power law, occlusion, speed peak.

    Inputs: ``normal_force`` (N, >= 0), ``speed`` (m/s, >= 0, default the peak speed 40 mm/s)
    and ``contact_time`` (s since the finger started sliding, >= 0, may be ``inf``; default
    ``inf``, the occluded steady state). Output: ``lateral_force`` in N,

    ``F_l = [mu_occ - (mu_occ - mu_0) exp(-t/tau_occ)] g(U) F_ref (Fn/F_ref)^n``

    (Eqs. 1.7/2.35, Fig. 1.11, Fig. 1.12; see the module documentation). Inverse: the normal
    force for a target lateral force at the given speed and contact time.
    """

    name: ClassVar[str] = "finger-friction"
    calibrated: ClassVar[tuple[str, ...]] = ("friction_initial", "friction_occluded")
    description: ClassVar[str] = (
        "Bare finger friction: F_l = k Fn^n (Eq. 1.7/2.35) with occlusion (Fig. 1.11) and a "
        "speed maximum (Fig. 1.12)"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter(
            "friction_initial",
            "",
            0.36,
            (0.01, 5.0),
            "Fig. 1.11, section 1.4.2.2 (Smith and Scott [46]: 0.36)",
            "friction coefficient at Fn = 1 N and the peak speed, at first contact",
        ),
        Parameter(
            "friction_occluded",
            "",
            0.79,
            (0.01, 5.0),
            "Fig. 1.11, section 1.4.2.2 (Smith and Scott [46]: 0.79)",
            "friction coefficient at Fn = 1 N and the peak speed, fully occluded",
        ),
        Parameter(
            "occlusion_time",
            "s",
            20.0,
            (1e-3, 1e4),
            "Fig. 1.11b (Pasumarty et al. [48]); ~20 s (Dzidek et al. 2014)",
            "first-order time constant of the occlusion rise",
        ),
        Parameter(
            "load_index",
            "",
            0.91,
            (2.0 / 3.0, 1.1),
            "Eq. 1.7, Eq. 2.35; Fig. 2.32 fit, 10th cycle (n = 0.91 +- 0.05)",
            "frictional load index n (theory 2/3..1; bound 1.1 admits the 1st-cycle "
            "fit 1.05 +- 0.08)",
        ),
        Parameter(
            "peak_speed",
            "m/s",
            0.040,
            (1e-4, 10.0),
            "Fig. 1.12 (maximum in the 10-120 mm/s exploration range [28])",
            "sliding speed of maximum friction U_p",
        ),
        Parameter(
            "speed_sensitivity",
            "",
            0.3,
            (0.0, 0.95),
            "Fig. 1.12 (shape; depth assumed, fit per finger and surface)",
            "fractional friction drop far from the peak speed",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (
        Variable("normal_force", "N", "normal force pressing the finger on the surface"),
        Variable("speed", "m/s", "sliding speed of the finger", 0.040),
        Variable(
            "contact_time", "s", "time since sliding contact began (inf: steady)", float("inf")
        ),
    )
    output: ClassVar[Variable] = Variable(
        "lateral_force", "N", "friction force opposing the sliding finger"
    )
    inverse_input: ClassVar[str | None] = "normal_force"

    @classmethod
    def preset(cls, name: str, **overrides: float) -> FingerFriction:
        """An instance with the parameters of :data:`PRESETS` ``[name]`` (and ``overrides``)."""
        if name not in PRESETS:
            raise PredictorError(
                f"{cls.name}: unknown preset {name!r}; presets: {', '.join(PRESETS)}"
            )
        return cls(**{**PRESETS[name], **overrides})

    # -- the three factors ------------------------------------------------------------------
    def occlusion(self, contact_time: Any) -> np.ndarray:
        """``mu(t)``: the friction coefficient at 1 N and the peak speed after ``t`` s of
        sliding (first-order rise from ``friction_initial`` to ``friction_occluded``)."""
        t = _check("contact_time", np.asarray(contact_time, dtype=np.float64), "s", allow_inf=True)
        return self._occlusion(t)

    def _occlusion(self, t: np.ndarray) -> np.ndarray:
        """:meth:`occlusion` of checked contact times ``t`` (s)."""
        mu0, mu_occ = self["friction_initial"], self["friction_occluded"]
        return mu_occ - (mu_occ - mu0) * np.exp(-t / self["occlusion_time"])

    def speed_factor(self, speed: Any) -> np.ndarray:
        """``g(U)``: friction relative to its value at the peak speed (<= 1, Fig. 1.12)."""
        u = _check("speed", np.asarray(speed, dtype=np.float64), "m/s")
        return self._speed_factor(u)

    def _speed_factor(self, u: np.ndarray) -> np.ndarray:
        """:meth:`speed_factor` of checked speeds ``u`` (m/s)."""
        x = u / self["peak_speed"]
        s = self["speed_sensitivity"]
        return 1.0 - s + s * 2.0 * x / (1.0 + x * x)

    def friction_coefficient(self, **inputs: Any) -> np.ndarray:
        """``mu = F_l / Fn`` for the same inputs as :meth:`forward` (Eq. 1.8)."""
        arrays = self._inputs(inputs)
        force = _check("normal_force", arrays["normal_force"], "N")
        if np.any(force == 0):
            raise PredictorError("normal_force: the friction coefficient needs Fn > 0")
        return self._forward(**arrays) / force

    def friction_coefficient_trusted(self, **inputs: Any) -> np.ndarray:
        """:meth:`friction_coefficient` for inputs already checked (finite; ``normal_force``
        > 0, ``speed`` and ``contact_time`` >= 0): the same numbers without the checks."""
        arrays = self._trusted_inputs(inputs)
        force = arrays["normal_force"]
        return self._lateral(force, arrays["speed"], arrays["contact_time"]) / force

    # -- forward and inverse ----------------------------------------------------------------
    def _prefactor(self, speed: np.ndarray, contact_time: np.ndarray) -> np.ndarray:
        return self.occlusion(contact_time) * self.speed_factor(speed) * REFERENCE_FORCE

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        force = _check("normal_force", inputs["normal_force"], "N")
        prefactor = self._prefactor(inputs["speed"], inputs["contact_time"])
        return prefactor * np.power(force / REFERENCE_FORCE, self["load_index"])

    def forward_trusted(self, **inputs: Any) -> np.ndarray:
        """:meth:`forward` for inputs already checked (finite, >= 0; ``contact_time`` may be
        ``inf``): the same numbers without the input checks."""
        arrays = self._trusted_inputs(inputs)
        return self._lateral(arrays["normal_force"], arrays["speed"], arrays["contact_time"])

    def _lateral(self, force: np.ndarray, speed: np.ndarray,
                 contact_time: np.ndarray) -> np.ndarray:
        """``F_l`` (N) of checked inputs: :meth:`occlusion` (Fig. 1.11) times
        :meth:`speed_factor` (Fig. 1.12) times the load power law (Eqs. 1.7/2.35)."""
        prefactor = self._occlusion(contact_time) * self._speed_factor(speed) * REFERENCE_FORCE
        return prefactor * np.power(force / REFERENCE_FORCE, self["load_index"])

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        lateral = _check("target", target, "N")
        prefactor = self._prefactor(inputs["speed"], inputs["contact_time"])
        return REFERENCE_FORCE * np.power(lateral / prefactor, 1.0 / self["load_index"])
