"""Intermittent contact: the massless spring-slider of thesis section 2.6 (Eqs. 2.19-2.28).

A fingerprint ridge is a massless Coulomb slider (friction coefficient ``mu0``) held by a normal
spring ``kn`` and a lateral spring ``kl`` to a finger pad that does not move at ultrasonic
frequencies. The plate below moves as ``(w/2) sin(2 pi f t)`` for a peak-to-peak amplitude ``w``
and slides past at the finger speed ``U``.

Normal direction (Eqs. 2.19-2.21, 2.27, 2.28). With the preload offset ``h`` the plate reaction
is ``F_reac = kn ((w/2) sin(2 pi f t) + h)`` while positive, else 0 (loss of contact); ``h``
solves ``mean(F_reac) = Fn`` over a period. Writing ``s = h / (w/2)`` and ``rho = Fn / (kn w/2)``,
the mean of the clipped sinusoid has the closed form (the integral of Eq. 2.28)::

    g(s) = (sqrt(1 - s^2) + s (pi/2 + arcsin s)) / pi = rho,      -1 < s < 1,

increasing and convex in ``s`` with ``g'(s) = (pi/2 + arcsin s) / pi``, the contact fraction
``t_c / T``. For ``rho >= 1`` (``w/2 <= Fn/kn``, the critical amplitude of Eq. 2.20) contact is
never lost, ``h = Fn/kn`` (Eq. 2.19), the lateral spring never unloads and the slider slips
throughout: ``mu' = 1``.

Lateral direction (Eqs. 2.22-2.26). The lateral spring is unloaded at each contact onset
(Eq. 2.26); in contact its compression grows at the sliding speed (stick, ``F_l = kl U t``,
Eq. 2.24) until the spring force reaches ``mu0 F_reac`` (Eq. 2.22); then the slider slips and the
force stays at ``mu0 F_reac`` (Eq. 2.25), following it down as the reaction falls to detachment.
``mu' = mean(F_l) / (mu0 Fn)`` over a period (Eq. 2.18). As a formula, with ``tau`` the time
since onset and the Coulomb cap ``C = mu0 F_reac`` (``C(0) = 0``)::

    F_l(tau) = min over tau' <= tau of [C(tau') + kl U (tau - tau')],

which is the simpler ``min(kl U tau, C(tau))`` whenever contact starts on the concave part of the
sinusoid (``h <= 0``, i.e. ``w/2 >= pi Fn / kn``; so over the whole parameter range of the bench):
then the spring sticks once, slips once, and follows ``C`` down. Just above the critical amplitude
(``h > 0``) the cap first rises slower than ``kl U``, the slider slips from the start, and when
``C`` steepens the spring reloads from the slip value rather than from ``kl U tau`` (a slipped
spring does not get its compression back). ``mu'`` is then lower than with ``min(kl U tau, C)``: by
up to 0.06 within 10% above the critical amplitude, 3e-3 above ``w/2 = 1.5 Fn/kn`` and 3e-4 above
``2 Fn/kn`` (measured over f 20-60 kHz, U 5-100 mm/s, mu0 0.25-1, Fn 0.1-1 N). This reading
reproduces the values of Eqs. 2.19-2.28 that tests/builtins/test_ultrasonic.py checks (0.387,
0.247, 0.135 at w = 1, 2, 5 um; the frequency and speed series), is the exact solution of the
massless Coulomb spring-slider, and is the ``v_r -> inf`` limit of the finite-recovery model
below. The other reading, a lateral force that once slipping is held at the largest value
reached, gives 0.447 at 1 um and ``mu' > 1`` at 100 mm/s, so it is rejected.

Finite lateral recovery (Figs. 2.25-2.26, section 2.7.2). The unloading of the lateral spring is
retarded to a constant speed ``v_r``: with compression ``x``, ``dx/dt = U`` while ``kl x`` is
below the cap (stick), ``x`` is held at the cap while the cap rises faster than that, and where
the cap is below ``kl x`` (falling reaction, or no contact) ``x`` unloads towards it at ``v_r``;
``F_l = min(kl x, mu0 F_reac)``. Compression left at the next onset accumulates over the cycles,
so friction climbs to a steady value slightly below ``mu0 F_reac`` for slow recovery (Fig. 2.25)
and lower for faster recovery (Fig. 2.26); ``v_r -> inf`` is the instantaneous model above. The
steady state is found as the smallest fixed point of the onset compression over one period (a
monotone map) by bisection. ``lateral_recovery_speed = 0`` stands for instantaneous recovery.

Numerics: ``s`` by a vectorised Newton iteration from the right (monotone for a convex increasing
``g``); the lateral force on a fixed grid of phase samples spanning the contact interval of each
period (a ``points x samples`` array in chunks; the running minimum above is a cumulative minimum
along the samples). 512 samples give ``mu'`` within 3e-6 of a 65536-sample reference over the
parameter ranges (1.1e-5 just above the critical amplitude). The finite-recovery model
is stepped sample by sample (vectorised over points): 38 periods of ``samples`` steps each for
the steady state (36 bisections of the onset compression, then two more periods).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable
from hcard_builtins.physics.ultrasonic._checks import check_inputs

SAMPLES = 512
"""Phase samples over the contact interval of one period."""

CHUNK_ELEMENTS = 1 << 21
"""Largest ``points x samples`` block evaluated at once (16 MiB of float64)."""

_NEWTON_ITERATIONS = 60
_NEWTON_TOLERANCE = 1e-13
_FIXED_POINT_BISECTIONS = 36

INVERSE_DOUBLINGS = 40
"""Doublings of the amplitude above ``w_c`` tried to bracket a target (up to ``w_c 2^40``)."""
INVERSE_BISECTIONS = 26
"""Halvings of the one-octave bracket in ``log w``: amplitude to a relative 1e-8."""


def contact_offset(ratio: Any) -> np.ndarray:
    """The normalised preload ``s = h / (w/2)`` for ``rho = Fn / (kn w/2)`` (Eq. 2.28).

    Solves ``g(s) = (sqrt(1 - s^2) + s (pi/2 + arcsin s)) / pi = rho`` for ``0 < rho < 1``
    element-wise. Newton's method starts from ``min(1, -1 + (3 pi rho / (2 sqrt 2))^(2/3))``,
    which lies right of the root because ``g`` is at least its leading term near ``s = -1``,
    ``(2 sqrt 2 / (3 pi)) (1 + s)^(3/2)``; from there the iterates of a convex increasing
    function decrease monotonically to the root.
    """
    rho = np.asarray(ratio, dtype=np.float64)
    if rho.size and (np.any(rho <= 0) or np.any(rho >= 1)):
        raise ValueError("contact_offset needs 0 < ratio < 1")
    s = np.minimum(1.0, -1.0 + (3 * math.pi * rho / (2 * math.sqrt(2))) ** (2 / 3))
    for _ in range(_NEWTON_ITERATIONS):
        arc = np.arcsin(s)
        g = (np.sqrt(np.maximum(1.0 - s * s, 0.0)) + s * (math.pi / 2 + arc)) / math.pi
        slope = (math.pi / 2 + arc) / math.pi
        step = (g - rho) / slope
        s = np.maximum(s - step, -1.0)
        if not step.size or np.max(np.abs(step)) < _NEWTON_TOLERANCE:
            break
    return s


@dataclass
class _Contact:
    """Per-point quantities of the intermittent contact, flattened (only points with w > w_c).

    Phases are those of the plate motion measured from the contact onset; the Coulomb cap at
    phase ``p`` is ``scale * (s (1 - cos p) + r sin p)`` (``sin(theta0 + p) + s`` with
    ``sin theta0 = -s``, ``cos theta0 = r``), zero at ``p = 0`` and ``p = length``.
    """

    scale: np.ndarray  # mu0 kn w/2 (N)
    s: np.ndarray  # h / (w/2)
    r: np.ndarray  # sqrt(1 - s^2)
    length: np.ndarray  # contact phase length 2 pi f t_c = pi + 2 arcsin s (rad)
    omega: np.ndarray  # 2 pi f (rad/s)
    speed: np.ndarray  # U (m/s)
    lateral_stiffness: np.ndarray  # kl (N/m)
    recovery_speed: np.ndarray  # v_r (m/s); inf for instantaneous recovery
    friction_scale: np.ndarray  # mu0 Fn (N)

    def _cap(self, part: slice, phase: np.ndarray) -> np.ndarray:
        cap = np.cos(phase)
        np.subtract(1.0, cap, out=cap)
        cap *= (self.scale[part] * self.s[part])[:, None]
        sine = np.sin(phase)
        sine *= (self.scale[part] * self.r[part])[:, None]
        cap += sine
        return cap

    def _phases(self, part: slice, samples: int) -> np.ndarray:
        return np.multiply.outer(self.length[part], (np.arange(samples) + 0.5) / samples)

    def _per_period(self, part: slice, mean_in_contact: np.ndarray) -> np.ndarray:
        return mean_in_contact * self.length[part] / (2 * math.pi) / self.friction_scale[part]

    def instantaneous(self, samples: int = SAMPLES) -> np.ndarray:
        """``mu'`` with instantaneous lateral recovery (unloaded at every onset)."""
        out = np.empty_like(self.scale)
        chunk = max(1, CHUNK_ELEMENTS // samples)
        for start in range(0, out.size, chunk):
            part = slice(start, start + chunk)
            phase = self._phases(part, samples)
            cap = self._cap(part, phase)
            line = phase
            line *= (self.lateral_stiffness[part] * self.speed[part] / self.omega[part])[:, None]
            # F = line + min(0, running min of (cap - line)); the 0 is the onset, C(0) = 0
            cap -= line
            np.minimum.accumulate(cap, axis=1, out=cap)
            np.minimum(cap, 0.0, out=cap)
            line += cap
            out[part] = self._per_period(part, line.mean(axis=1))
        return out

    def period(self, x_on: np.ndarray, samples: int = SAMPLES) -> tuple[np.ndarray, np.ndarray]:
        """One period of the finite-recovery model from onset compressions ``x_on`` (m).

        Returns ``mu'`` of the period and the compression at the next onset. The compression
        is stepped from sample to sample (half steps from the onset and to the detachment);
        out of contact it unloads at ``v_r`` for ``T - t_c``.
        """
        everything = slice(None)
        phase = self._phases(everything, samples)
        caps = self._cap(everything, phase) / self.lateral_stiffness[:, None]  # in m
        step_time = self.length / self.omega / samples
        grow, relax = self.speed * step_time, self.recovery_speed * step_time
        x = np.asarray(x_on, dtype=np.float64).copy()
        total = np.zeros_like(x)
        for k in range(samples):
            fraction = 0.5 if k == 0 else 1.0
            cap = caps[:, k]
            x = np.minimum(x + fraction * grow, np.maximum(cap, x - fraction * relax))
            total += np.minimum(x, cap)
        x = np.maximum(x - 0.5 * relax, 0.0)
        off_time = (2 * math.pi - self.length) / self.omega
        x_next = np.maximum(x - self.recovery_speed * off_time, 0.0)
        mean_in_contact = self.lateral_stiffness * total / samples
        return self._per_period(everything, mean_in_contact), x_next

    def slip_compression(self) -> np.ndarray:
        """``mu0 max(F_reac) / kl`` (m): no compression in the model exceeds it."""
        return self.scale * (1 + self.s) / self.lateral_stiffness

    def steady(self, samples: int = SAMPLES) -> np.ndarray:
        """Steady ``mu'`` of the finite-recovery model.

        The onset compression after one period, ``P(x)``, is nondecreasing in ``x`` with
        slope at most 1 and ``P(slip_compression) <= slip_compression``; the iteration from
        ``x = 0`` (sliding starts unloaded) converges to the smallest ``x`` with ``P(x) <= x``,
        found here by bisection.
        """
        low = np.zeros_like(self.scale)
        high = self.slip_compression()
        for _ in range(_FIXED_POINT_BISECTIONS):
            middle = (low + high) / 2
            _, after = self.period(middle, samples)
            climbing = after > middle
            low = np.where(climbing, middle, low)
            high = np.where(climbing, high, middle)
        _, after_low = self.period(low, samples)
        start = np.where(after_low > low, high, low)
        return self.period(start, samples)[0]


def _contact(
    *,
    amplitude: np.ndarray,
    frequency: np.ndarray,
    speed: np.ndarray,
    normal_force: np.ndarray,
    normal_stiffness: np.ndarray,
    lateral_stiffness: np.ndarray,
    mu0: np.ndarray,
    lateral_recovery_speed: np.ndarray,
) -> tuple[np.ndarray, _Contact]:
    """Mask of intermittent points (input shape) and their :class:`_Contact` (flattened)."""
    half = amplitude / 2
    with np.errstate(divide="ignore", invalid="ignore"):  # 0/0 at w = Fn = 0
        ratio = normal_force / (normal_stiffness * half)
    mask = (ratio > 0) & (ratio < 1) & (frequency > 0)  # Fn = 0: the vanishing-load limit, 1
    s = contact_offset(ratio[mask])
    recovery = lateral_recovery_speed[mask]
    contact = _Contact(
        scale=mu0[mask] * normal_stiffness[mask] * half[mask],
        s=s,
        r=np.sqrt(np.maximum(1.0 - s * s, 0.0)),
        length=math.pi + 2 * np.arcsin(s),
        omega=2 * math.pi * frequency[mask],
        speed=speed[mask],
        lateral_stiffness=lateral_stiffness[mask],
        recovery_speed=np.where(recovery > 0, recovery, np.inf),
        friction_scale=mu0[mask] * normal_force[mask],
    )
    return mask, contact


def _checked(model: str, inputs: dict[str, Any]) -> dict[str, np.ndarray]:
    return check_inputs(
        model,
        inputs,
        positive=("normal_stiffness", "lateral_stiffness", "mu0"),
    )


def _steady(contact: _Contact, samples: int) -> np.ndarray:
    out = np.empty_like(contact.scale)
    finite = np.isfinite(contact.recovery_speed)
    if (~finite).any():
        out[~finite] = _subset(contact, ~finite).instantaneous(samples)
    if finite.any():
        chosen = np.flatnonzero(finite)
        chunk = max(1, CHUNK_ELEMENTS // samples)
        for start in range(0, chosen.size, chunk):
            part = chosen[start : start + chunk]
            out[part] = _subset(contact, part).steady(samples)
    return np.clip(out, 0.0, 1.0)


def _subset(contact: _Contact, pick: np.ndarray) -> _Contact:
    return _Contact(**{name: value[pick] for name, value in vars(contact).items()})


def relative_friction(
    amplitude: Any,
    frequency: Any,
    speed: Any,
    normal_force: Any,
    *,
    normal_stiffness: Any,
    lateral_stiffness: Any,
    mu0: Any,
    lateral_recovery_speed: Any = 0.0,
    samples: int = SAMPLES,
) -> np.ndarray:
    """Steady-state ``mu' = mean(F_l) / (mu0 Fn)`` of the spring-slider (Eqs. 2.19-2.28).

    All arguments broadcast together, parameters included, so a calibration can vary them per
    point. Units: amplitude (peak-to-peak) m, frequency Hz, speed m/s, normal force N,
    stiffnesses N/m, recovery speed m/s (0: instantaneous, Eq. 2.26). ``mu' = 1`` in full
    contact (``w/2 <= Fn/kn``), for ``f = 0``, and for ``Fn = 0``, the limit of a vanishing
    load (the contact shrinks to the top of the stroke, where the slider slips throughout:
    ``mu'`` is already 1 below ~1e-4 N at 20 mm/s, 38 kHz, 2 um).
    """
    arrays = _checked(
        "spring-slider",
        {
            "amplitude": amplitude, "frequency": frequency, "speed": speed,
            "normal_force": normal_force, "normal_stiffness": normal_stiffness,
            "lateral_stiffness": lateral_stiffness, "mu0": mu0,
            "lateral_recovery_speed": lateral_recovery_speed,
        },
    )
    mask, contact = _contact(**arrays)
    out = np.ones(mask.shape)
    out[mask] = _steady(contact, samples)
    return out


class SpringSlider(Predictor):
    """Massless spring-slider of intermittent contact (thesis section 2.6, Eqs. 2.19-2.28).

    ``forward(amplitude=..., frequency=..., speed=..., normal_force=...)`` gives the steady
    relative friction ``mu'``; see the module docstring for the model and the reading of
    Eqs. 2.22-2.26 that it implements. Extras: :meth:`phase_shift` (Eq. 2.11, Fig. 2.23),
    :meth:`cycles` (the climb over cycles with a finite lateral recovery speed, Fig. 2.25),
    :meth:`preload` and :meth:`contact_fraction`.
    """

    name: ClassVar[str] = "spring-slider"
    calibrated: ClassVar[tuple[str, ...]] = ("mu0", "lateral_stiffness")
    description: ClassVar[str] = (
        "UV intermittent contact: massless spring-slider, mu' = mean(F_l)/(mu0 Fn) "
        "(thesis Eqs. 2.19-2.28)"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter(
            "normal_stiffness", "N/m", 3.9e6, (1e3, 1e9),
            "Fig. 2.25 (3.9 MN/m); Fig. 2.23 spans 0.2-4 MN/m",
            "normal spring kn of a fingerprint ridge",
        ),
        Parameter(
            "lateral_stiffness", "N/m", 1.5e6, (1e3, 1e9), "Fig. 2.25 (1.5 MN/m)",
            "lateral spring kl of a fingerprint ridge",
        ),
        Parameter(
            "mu0", "", 0.5, (0.01, 5.0), "Figs. 2.21, 2.25 (0.5); Table 2.3 range 0.1-2.0",
            "intrinsic (Coulomb) friction coefficient without vibration",
        ),
        Parameter(
            "lateral_recovery_speed", "m/s", 0.0, (0.0, 10.0),
            "Eq. 2.26 (0: instantaneous); Figs. 2.25-2.26 (1.5-15 mm/s)",
            "speed at which the lateral spring unloads; 0 = instantaneous",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (
        Variable("amplitude", "m", "peak-to-peak plate vibration amplitude w"),
        Variable("frequency", "Hz", "plate vibration frequency f (Fig. 2.21: 27.5 kHz)", 27_500.0),
        Variable("speed", "m/s", "finger sliding speed U (Fig. 2.21: 20 mm/s)", 0.020),
        Variable("normal_force", "N", "applied normal force Fn (Fig. 2.25: 0.5 N)", 0.5),
    )
    output: ClassVar[Variable] = Variable("relative_friction", "", "mu' = mu / mu0")
    inverse_input: ClassVar[str | None] = "amplitude"

    samples: ClassVar[int] = SAMPLES
    """Phase samples per contact interval."""

    def _params(self) -> dict[str, float]:
        return {p.name: self[p.name] for p in self.parameters}

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        return relative_friction(**inputs, **self._params(), samples=self.samples)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        """Peak-to-peak amplitude (m) giving the target ``mu'`` in (0, 1], found numerically.

        Unlike the dimensionless group (Eq. 2.33, stated for w > 1 um) this holds at any
        amplitude, so velocity compensation through it is valid over the whole range a device
        plays. ``mu' = 1`` needs no vibration (0 m). Below the critical amplitude
        ``w_c = 2 Fn / kn`` (Eq. 2.20) contact is never lost and ``mu' = 1``; above it ``mu'``
        falls with the amplitude, so the answer is bracketed between ``w_c`` and ``w_c``
        doubled until ``mu'`` is at or below the target, then bisected in ``log w``
        (:data:`INVERSE_BISECTIONS` halvings: relative precision 1e-8). At a slow finger
        ``mu'`` drops at ``w_c`` from 1 straight to a value well below 1 (0.29 at 5 mm/s,
        38.2 kHz, 0.5 N with the defaults): targets inside that gap cannot be rendered at any
        amplitude, and the amplitude whose friction is nearer (0 or just above ``w_c``) is
        returned; :func:`hcard.physics.actuation.actuate` reports such frames as unreachable.
        """
        goal = np.asarray(target, dtype=np.float64)
        outside = ~((goal > 0) & (goal <= 1))
        if np.any(outside):
            raise PredictorError(
                f"{self.name}: target relative_friction must be in (0, 1], got "
                f"{goal[outside].flat[0]:g} (mu' = 0 needs an infinite amplitude)"
            )
        arrays = _checked(self.name, {**inputs, "target": goal, **self._params()})
        goal = arrays.pop("target")
        # At Fn = 0 there is no friction to lower and mu' = 1 at any amplitude: no vibration.
        wanted = (goal < 1) & (arrays["normal_force"] > 0)
        moving = (arrays["speed"] > 0) & (arrays["frequency"] > 0)
        if np.any(wanted & ~moving):
            raise PredictorError(
                f"{self.name}: inputs speed and frequency must be > 0 for a target below 1 "
                "(a resting finger under vibration has mu' = 0 at any amplitude above w_c)"
            )
        out = np.zeros(goal.shape)
        if not np.any(wanted):
            return out
        picked = {name: value[wanted] for name, value in arrays.items()}
        picked.pop("amplitude", None)
        aim = goal[wanted]
        critical = 2.0 * picked["normal_force"] / picked["normal_stiffness"]

        def friction(amplitude: np.ndarray) -> np.ndarray:
            return relative_friction(amplitude, **{
                k: v for k, v in picked.items() if k != "lateral_recovery_speed"
            }, lateral_recovery_speed=picked["lateral_recovery_speed"], samples=self.samples)

        low = np.log(critical)
        high = np.log(2.0 * critical)
        for _ in range(INVERSE_DOUBLINGS):
            above = friction(np.exp(high)) > aim
            if not above.any():
                break
            low = np.where(above, high, low)
            high = np.where(above, high + math.log(2.0), high)
        else:
            raise PredictorError(
                f"{self.name}: no amplitude up to {math.exp(float(high.max())):g} m reaches "
                f"target relative_friction {float(aim.min()):g}"
            )
        for _ in range(INVERSE_BISECTIONS):
            middle = 0.5 * (low + high)
            above = friction(np.exp(middle)) > aim
            low = np.where(above, middle, low)
            high = np.where(above, high, middle)
        # mu' jumps at w_c (from 1 to well below at a slow finger): a target inside the jump is
        # reached by neither side; give the side nearer to it (no vibration, or just above w_c).
        reached = friction(np.exp(high))
        out[wanted] = np.where(1.0 - aim < np.abs(reached - aim), 0.0, np.exp(high))
        return out

    def _prepared(
        self, inputs: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], np.ndarray, _Contact]:
        arrays = _checked(self.name, {**self._inputs(inputs), **self._params()})
        mask, contact = _contact(**arrays)
        return arrays, mask, contact

    def cycles(self, count: int, **inputs: Any) -> np.ndarray:
        """``mu'`` of each of the first ``count`` vibration periods after sliding starts.

        The lateral spring starts unloaded. With a finite ``lateral_recovery_speed`` the
        compression left at each contact onset accumulates and ``mu'`` climbs towards the
        steady value of :meth:`forward` (Fig. 2.25); with instantaneous recovery every period
        equals :meth:`forward`. Returns an array of the broadcast input shape plus ``(count,)``.
        """
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 1:
            raise PredictorError(f"{self.name}: cycles needs a positive whole count, got {count}")
        _, mask, contact = self._prepared(inputs)
        out = np.ones((*mask.shape, int(count)))
        if self["lateral_recovery_speed"] == 0:
            out[mask] = np.clip(contact.instantaneous(self.samples), 0.0, 1.0)[:, None]
            return out
        per_point = np.ones((contact.scale.size, int(count)))
        chunk = max(1, CHUNK_ELEMENTS // self.samples)
        for start in range(0, contact.scale.size, chunk):
            part = np.arange(start, min(start + chunk, contact.scale.size))
            subset = _subset(contact, part)
            x_on = np.zeros(part.size)
            for k in range(int(count)):
                friction, x_on = subset.period(x_on, self.samples)
                per_point[part, k] = np.clip(friction, 0.0, 1.0)
        out[mask] = per_point
        return out

    def preload(self, **inputs: Any) -> np.ndarray:
        """The normal preload offset ``h`` (m): ``Fn/kn`` in full contact (Eq. 2.19), else the
        root of Eq. 2.28. Negative when the slider only touches near the top of the stroke."""
        arrays, mask, contact = self._prepared(inputs)
        h = np.array(arrays["normal_force"] / arrays["normal_stiffness"], dtype=np.float64)
        h[mask] = contact.s * arrays["amplitude"][mask] / 2
        return h

    def contact_fraction(self, **inputs: Any) -> np.ndarray:
        """``t_c / T``: the fraction of each period in contact (1 in full contact)."""
        _, mask, contact = self._prepared(inputs)
        out = np.ones(mask.shape)
        out[mask] = contact.length / (2 * math.pi)
        return out

    def phase_shift(self, **inputs: Any) -> np.ndarray:
        """The phase shift ``Phi`` in degrees (Eq. 2.11, Fig. 2.23).

        ``Phi = 360 |t_pa - t_sa| / T`` with ``t_pa`` the time of the plate's peak acceleration
        (``sin(2 pi f t) = -1``) and ``t_sa`` that of the slider, taken at the contact onset
        (section 2.6: "t_sa being the time of contact"). The onset is ``arccos(s)`` of phase after
        the plate's peak and the detachment the same before the next one, so either reading gives
        ``Phi = degrees(arccos(h / (w/2)))``: 0 in full contact, 90 deg at ``h = 0``, rising
        towards 180 deg with amplitude and with ``kn`` (Fig. 2.23).
        """
        _, mask, contact = self._prepared(inputs)
        out = np.zeros(mask.shape)
        out[mask] = np.degrees(np.arccos(np.clip(contact.s, -1.0, 1.0)))
        return out
