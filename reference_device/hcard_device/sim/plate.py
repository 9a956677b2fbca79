"""The vibrating plate's amplitude envelope under a PI amplitude loop (thesis section 5.1.1).

Plate. Driven at resonance, a mode's amplitude envelope ``A`` (peak-to-peak, m) is first order::

    dA/dt = -sigma(Fn) A + beta u,   sigma = pi f0 / Q(Fn),   1/Q(Fn) = (1 + d Fn) / Q0,

with time constant ``tau = 1/sigma = Q / (pi f0)``, the drive ``u`` in [0, 1] (fraction of the
inverter's full drive, in phase with the vibration) and ``beta = sigma0 A_full`` so that the
unloaded plate settles at ``A_full`` under full drive. The finger pressing with ``Fn`` adds
damping (``d`` per newton), which lowers both the time constant and the gain.

Loop (E-ViTa: a PI running at 60 kHz on the amplitude sensed by two piezos, tuned with the
Ziegler-Nichols method, 400 Hz closed-loop bandwidth at 2 um, held within 50 nm for Fn < 3 N).
At loop sample ``k`` (period ``T``) with reference ``r``::

    e[k] = r[k] - A[k],  u_lin[k] = Kp e[k] + I[k],  u[k] = clip(u_lin[k], 0, u_hi[k]),
    (with a tolerance of 1e-9 of full drive on the bounds, DRIVE_SLACK)
    I[k+1] = I[k] + Ki T e[k]          while u[k] = u_lin[k] (linear),
    I[k+1] = I[k]                      at full drive (conditional integration),
    I[k+1] = max(I[k] + Ki T e[k], 0)  at zero drive (unwinds, never below zero drive),
    I[k+1] = u[k] - Kp e[k]            while the safety clamp acts (tracking),
    A[k+1] = a A[k] + (1 - a) G u[k],  a = exp(-sigma T),  G = beta / sigma,

the exact zero-order-hold discretisation of the envelope.
``u_hi[k] = clip((A_max - a A[k]) / ((1 - a) G), 0, 1)`` is the hard safety clamp: it is the
largest drive that keeps ``A[k+1] <= A_max``, so the amplitude can never exceed the limit
whatever the reference; when it binds the sample is flagged.

Braking. A lowered limit that finds the plate above it (``A[k] > A_max``) takes the drive from
the PI: the inverter reverses its phase and drives in antiphase, at most ``b`` of full drive
(:attr:`PlateLoop.brake_drive`; 0: the drive is only cut), with the drive that lands the
envelope on the limit::

    u[k] = clip((A_max - a A[k]) / ((1 - a) G), -b, 0),   I[k+1] = -Kp e[k]   (flagged),

so at full reverse drive ``A(t) = (A0 + b G) exp(-sigma t) - b G`` reaches the limit ``L``
after ``tau ln((A0 + b G) / (L + b G))`` (:meth:`PlateLoop.brake_time`), and reaches even 0 in
finite time, where a plate left to decay (``b = 0``) only approaches it. The integrator tracks
zero drive meanwhile, so the PI resumes bumplessly at the limit.

Gains (:meth:`PIGains.ziegler_nichols`): the Ziegler-Nichols reaction-curve rule for a first
order process of gain ``K`` and time constant ``tau`` with apparent dead time ``L``::

    Kp = 0.9 tau / (K L),  Ti = L / 0.3,  Ki = Kp / Ti.

Vectorised solution. Between saturation events the loop is linear and time invariant (for a
constant finger force), so :func:`scipy.signal.lfilter` (its C core, :func:`closed_loop`) runs
the closed loop ``r -> A`` with its state carried in; the first sample where ``u_lin`` leaves
``[0, u_hi]`` is found with numpy, and from there the saturated plate (constant drive or the
clamp; integrator frozen, unwinding or tracking) has a closed form until the controller comes back
into range. The finger force is quantised to :data:`FORCE_QUANTUM_N` and the coefficients cached
per quantum. The result is the sample-by-sample recursion above (tests/device/test_sim.py
compares the two). A loop that chatters between modes (a one-sided drive following a reference
that falls faster than the plate decays switches between zero drive and the linear loop every few
samples) would cost a vectorised solve per switch, so after a run of at most
:data:`SHORT_RUN_SAMPLES` samples the loop runs that recursion sample by sample until a mode
lasts longer (:meth:`PlateLoop._steps`; the clamp and the brake are always solved vectorised);
the two differ by rounding (tests/device/test_sim_steps.py).

With the E-ViTa constants (:meth:`hcard_device.sim.DeviceConfig.evita`) the loop has its -3 dB
point at 403 Hz for small references around 2 um (394 Hz at 3 N), a 0 -> 2 um step rises 10-90 %
in 1.49 ms with the drive saturated and no overshoot, and force steps between 0 and 3 N move a
2 um amplitude by at most 30 nm (37 nm at 2.5 um).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

try:  # the C core lfilter hands a filter with feedback to, after checking its arguments
    from scipy.signal._sigtools import _linear_filter
except ImportError:  # pragma: no cover - a SciPy without it: lfilter itself
    _linear_filter = None

FORCE_QUANTUM_N = 0.01
"""Resolution of the finger force seen by the plate model, N (the E-ViTa's damping changes by
0.03 % per quantum)."""

MAX_SEGMENT_SAMPLES = 1200
"""Longest run of loop samples solved in one go (20 ms at 60 kHz): bounds the work a saturation
event costs, since each switch re-solves the rest of its run."""

LIMIT_SLACK = 1e-9
"""Relative slack before an amplitude counts as above the limit: the closed-loop filter and the
state recursion round differently (1e-16), and a plate held at the limit must not read as over
it."""

DRIVE_SLACK = 1e-9
"""Tolerance on the drive bounds, fraction of full drive: the linear loop may run up to this far
past a bound before a saturation counts (and only a clamp that takes more than this from the
drive is reported). A loop at rest (``u = 0``) or holding the limit sits exactly on a bound,
where rounding alone would otherwise switch modes every sample."""

AMPLITUDE_TOLERANCE_M = 1e-14
"""Guarantee of the clamp: the amplitude stays at or under ``limit (1 + LIMIT_SLACK) +
AMPLITUDE_TOLERANCE_M`` (the drive slack lets it pass the limit by at most ``DRIVE_SLACK`` of the
full-drive amplitude, a few femtometres)."""


def closed_loop(num: np.ndarray, den: np.ndarray, reference: np.ndarray,
                state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`scipy.signal.lfilter` ``(num, den, reference, zi=state)`` of float64 arrays
    (``den[0] = 1``, two states): the same numbers without lfilter's argument handling, which
    costs twice the filtering itself on the few hundred samples of a real-time step."""
    if _linear_filter is None:  # pragma: no cover
        return lfilter(num, den, reference, zi=state)
    return _linear_filter(num, den, reference, -1, state)


SHORT_RUN_SAMPLES = 8
"""A mode the vectorised solver finds to last this many loop samples or fewer hands the loop to
the sample recursion, which costs about as much per sample as the vectorised solver costs per
run of samples."""

_LINEAR, _LOW, _HIGH, _OVER = 0, 1, 2, 3
"""Loop modes: linear, drive at 0, drive at its upper bound, plate above the limit."""


@dataclass(frozen=True)
class PlateModel:
    """The amplitude envelope of a plate mode driven at resonance.

    Attributes:
        resonance_hz: mode frequency ``f0``, Hz.
        quality_factor: unloaded quality factor ``Q0``.
        finger_damping_per_n: ``d``: ``1/Q(Fn) = (1 + d Fn) / Q0``, 1/N.
        full_drive_amplitude_m: unloaded steady peak-to-peak amplitude at full drive, m.
    """

    resonance_hz: float
    quality_factor: float
    finger_damping_per_n: float
    full_drive_amplitude_m: float

    def decay_rate(self, normal_force_n: float) -> float:
        """Envelope decay rate ``sigma = pi f0 / Q(Fn)``, 1/s."""
        load = 1.0 + self.finger_damping_per_n * max(normal_force_n, 0.0)
        return math.pi * self.resonance_hz * load / self.quality_factor

    def time_constant(self, normal_force_n: float) -> float:
        """Envelope time constant ``tau = Q(Fn) / (pi f0)``, s."""
        return 1.0 / self.decay_rate(normal_force_n)

    def full_drive_amplitude(self, normal_force_n: float) -> float:
        """Steady peak-to-peak amplitude at full drive under finger force ``Fn``, m."""
        return self.full_drive_amplitude_m / (
            1.0 + self.finger_damping_per_n * max(normal_force_n, 0.0)
        )


@dataclass(frozen=True)
class PIGains:
    """PI gains on the amplitude error.

    Attributes:
        kp: proportional gain, drive fraction per metre of amplitude error (1/m).
        ki: integral gain, drive fraction per metre-second (1/(m s)).
    """

    kp: float
    ki: float

    @classmethod
    def ziegler_nichols(
        cls, plate: PlateModel, dead_time_s: float, normal_force_n: float
    ) -> PIGains:
        """Ziegler-Nichols reaction-curve PI for the plate at ``normal_force_n``:
        ``Kp = 0.9 tau / (K L)``, ``Ti = L / 0.3`` (``K``: full-drive amplitude, m; ``tau``:
        envelope time constant, s; ``L``: apparent dead time, s)."""
        tau = plate.time_constant(normal_force_n)
        gain = plate.full_drive_amplitude(normal_force_n)
        kp = 0.9 * tau / (gain * dead_time_s)
        return cls(kp=kp, ki=kp / (dead_time_s / 0.3))


@dataclass(frozen=True)
class PlateRun:
    """Result of :meth:`PlateLoop.run` over N loop samples.

    Attributes:
        amplitude: (N,) peak-to-peak amplitude after each loop sample, m.
        drive: (N,) drive applied at each sample, fraction of full drive in [-b, 1] (negative:
            antiphase, braking a plate above a lowered limit; ``b`` = ``brake_drive``).
        clamped: (N,) the hard amplitude clamp (or the brake) acted on the sample.
    """

    amplitude: np.ndarray
    drive: np.ndarray
    clamped: np.ndarray


@dataclass(frozen=True)
class _Coefficients:
    """The loop's coefficients at one quantised finger force (module documentation).

    Attributes:
        a: envelope decay per loop sample, ``exp(-sigma T)``.
        g: ``(1 - a) G``: amplitude gained per sample at full drive, m.
        c: ``Ki T``, 1/m.
        num, den: the closed loop ``r -> A`` as a filter.
        phi11, phi12: first row of the state matrix.
        state_slope: ``phi11 + den[1]``: the filter's second state is ``state_slope A +
            phi12 I`` for the loop state ``(A, I)``.
        full: full-drive amplitude ``G``, m.
        decay: ``a ** k`` for ``k = 0 .. MAX_SEGMENT_SAMPLES`` (the saturated plate).
    """

    a: float
    g: float
    c: float
    num: np.ndarray
    den: np.ndarray
    phi11: float
    phi12: float
    state_slope: float
    full: float
    decay: np.ndarray


def _force_runs(normal_force: np.ndarray) -> list[tuple[int, int, int]]:
    """``(start, end, key)`` of each run of loop samples whose finger force (N) falls in one
    quantum of :data:`FORCE_QUANTUM_N` (``key``: the force in quanta, rounded half to even;
    negative forces count as 0). One run for an empty array (key of its first sample)."""
    n = normal_force.shape[0]
    if n and np.minimum.reduce(normal_force) == np.maximum.reduce(normal_force):
        force = float(normal_force[0])  # one force (a held finger): no per-sample keys
        if math.isfinite(force) and force < 1e12:
            return [(0, n, round(max(force, 0.0) / FORCE_QUANTUM_N))]
    keys = np.rint(np.maximum(normal_force, 0.0) / FORCE_QUANTUM_N).astype(np.int64)
    edges = [0, *(np.flatnonzero(keys[1:] != keys[:-1]) + 1).tolist(), n]
    return [(start, end, int(keys[start])) for start, end in itertools.pairwise(edges)]


class PlateLoop:
    """A plate under its PI amplitude loop; state (amplitude, integrator) carries over runs.

    Args:
        plate: the plate envelope model.
        gains: PI gains.
        loop_rate_hz: loop sampling rate, Hz.
        limit_m: hard amplitude limit, m (peak-to-peak).
        brake_drive: largest antiphase drive the inverter applies to a plate above the limit,
            fraction of full drive in [0, 1] (0: the drive is only cut and the plate decays at
            its own rate; see the module documentation).
    """

    def __init__(
        self, plate: PlateModel, gains: PIGains, loop_rate_hz: float, limit_m: float,
        brake_drive: float = 0.0,
    ) -> None:
        self.plate = plate
        self.gains = gains
        self.period_s = 1.0 / loop_rate_hz
        self.amplitude_m = 0.0
        self.integrator = 0.0
        self._limit = 0.0
        self._brake = 0.0
        self._cache: dict[int, _Coefficients] = {}
        self._chattering = False  # the last vectorised run was short: step sample by sample
        self.limit_m = limit_m
        self.brake_drive = brake_drive

    @property
    def limit_m(self) -> float:
        """The hard amplitude limit, m."""
        return self._limit

    @limit_m.setter
    def limit_m(self, value: float) -> None:
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"amplitude limit must be a finite number >= 0 m, got {value}")
        self._limit = float(value)

    @property
    def brake_drive(self) -> float:
        """Largest antiphase drive on a plate above the limit, fraction of full drive."""
        return self._brake

    @brake_drive.setter
    def brake_drive(self, value: float) -> None:
        if not (math.isfinite(value) and 0.0 <= value <= 1.0):
            raise ValueError(f"brake drive must be a fraction of full drive in [0, 1], got {value}")
        self._brake = float(value)

    @property
    def above_limit(self) -> bool:
        """The plate is above the limit by more than the clamp's guarantee
        (:data:`AMPLITUDE_TOLERANCE_M`): a lowered limit it has not reached yet."""
        return self.amplitude_m > self._limit * (1.0 + LIMIT_SLACK) + AMPLITUDE_TOLERANCE_M

    def brake_time(self, from_m: float, to_m: float, normal_force_n: float = 0.0) -> float:
        """Time the brake takes to bring the envelope from ``from_m`` down to ``to_m`` (m), s:
        ``tau(Fn) ln((A0 + b G(Fn)) / (L + b G(Fn)))`` (continuous time; the loop lands on the
        limit within the loop sample that crosses it). The unloaded plate is the slowest: the
        finger's damping shortens ``tau`` more than it lowers ``G``. Infinite when ``b = 0``
        and ``to_m = 0``."""
        if from_m <= to_m:
            return 0.0
        pull = self._brake * self.plate.full_drive_amplitude(normal_force_n)
        if to_m + pull <= 0.0:
            return math.inf
        return self.plate.time_constant(normal_force_n) * math.log((from_m + pull) / (to_m + pull))

    def reset(self) -> None:
        """Plate at rest, integrator cleared."""
        self.amplitude_m = 0.0
        self.integrator = 0.0
        self._chattering = False

    def _coefficients(self, key: int) -> _Coefficients:
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        force = key * FORCE_QUANTUM_N
        a = math.exp(-self.plate.decay_rate(force) * self.period_s)
        full = self.plate.full_drive_amplitude(force)
        g = (1.0 - a) * full
        kp, c = self.gains.kp, self.gains.ki * self.period_s
        # State x = (A, I): x[k+1] = Phi x[k] + Gamma r[k], A = (1, 0) x.
        phi11, phi12, phi21, phi22 = a - g * kp, g, -c, 1.0
        gamma1, gamma2 = g * kp, c
        den = np.array([1.0, -(phi11 + phi22), phi11 * phi22 - phi12 * phi21])
        num = np.array([0.0, gamma1, phi12 * gamma2 - phi22 * gamma1])
        decay = a ** np.arange(MAX_SEGMENT_SAMPLES + 1, dtype=np.float64)
        decay.flags.writeable = False
        co = _Coefficients(a, g, c, num, den, phi11, phi12, float(phi11 + den[1]), full, decay)
        self._cache[key] = co
        return co

    def run(self, reference: np.ndarray, normal_force: np.ndarray) -> PlateRun:
        """Advance the loop over ``len(reference)`` samples.

        Args:
            reference: (N,) amplitude reference per loop sample, m (clipped to [0, limit]).
            normal_force: (N,) finger force on the plate per loop sample, N (0 without
                contact).
        """
        ref = np.maximum(np.asarray(reference, dtype=np.float64), 0.0)
        np.minimum(ref, self._limit, out=ref)  # clipped to [0, limit]
        n = ref.shape[0]
        if self.amplitude_m == 0.0 and self.integrator == 0.0 and not np.logical_or.reduce(ref):
            return PlateRun(np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool))  # at rest
        amplitude = np.empty(n + 1)
        drive = np.empty(n)
        clamped = np.zeros(n, dtype=bool)
        amplitude[0] = self.amplitude_m
        for start, end, key in _force_runs(np.asarray(normal_force, dtype=np.float64)):
            co = self._coefficients(key)
            for s in range(start, end, MAX_SEGMENT_SAMPLES):
                e = min(s + MAX_SEGMENT_SAMPLES, end)
                self._segment(ref[s:e], co, amplitude[s : e + 1], drive[s:e], clamped[s:e])
        return PlateRun(np.maximum(amplitude[1:], 0.0, out=amplitude[1:]), drive, clamped)

    # -- one constant-force run ------------------------------------------------------------
    def _brake_run(
        self, amp: float, lim: float, decay: np.ndarray, co: _Coefficients
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A plate above the limit braked at up to ``-b`` (module documentation): amplitudes
        (from ``amp``, m), the drive of each sample, and where the loop leaves the brake (the
        sample after the one that lands on the limit; none when it is not reached)."""
        n = decay.shape[0] - 1
        pull = self._brake * co.full
        amps = -pull + (amp + pull) * decay  # full reverse drive all along
        applied = np.full(n, -self._brake)
        leave = np.zeros(n, dtype=bool)
        crossed = np.flatnonzero(amps[1:] <= lim * (1.0 + LIMIT_SLACK))
        if crossed.size:
            m = int(crossed[0])  # the sample that lands on the limit
            applied[m] = min(max((lim - co.a * amps[m]) / co.g, -self._brake), 0.0)
            amps[m + 1] = min(max(co.a * amps[m] + co.g * applied[m], 0.0), lim)
            if m + 1 < n:
                leave[m + 1] = True
        return amps, applied, leave

    def _segment(
        self,
        ref: np.ndarray,
        co: _Coefficients,
        amp_out: np.ndarray,
        drive_out: np.ndarray,
        clamp_out: np.ndarray,
    ) -> None:
        """Solve ``len(ref)`` samples; ``amp_out[0]`` holds the starting amplitude and
        ``amp_out[k + 1]`` receives the amplitude after sample ``k``."""
        n = ref.shape[0]
        kp, lim = self.gains.kp, self._limit
        over, a, g, c = lim * (1.0 + LIMIT_SLACK), co.a, co.g, co.c
        amp, integ = self.amplitude_m, self.integrator
        k = 0
        while k < n:
            if self._chattering:
                k, amp, integ = self._steps(ref, k, amp, integ, co, amp_out, drive_out)
                if k >= n:
                    break
            # the mode of sample k: above the limit, or where the PI's drive falls
            if amp > over:
                mode = _OVER
            else:
                u = kp * (float(ref[k]) - amp) + integ
                if u < -DRIVE_SLACK:
                    mode = _LOW
                elif u > min(1.0, max((lim - a * amp) / g, 0.0)) + DRIVE_SLACK:
                    mode = _HIGH
                else:
                    mode = _LINEAR
            rest = ref[k:]
            if mode == _LINEAR:
                zi = np.array((amp, co.state_slope * amp + co.phi12 * integ))
                amps, zf = closed_loop(co.num, co.den, rest, zi)
                err = rest - amps
                integs = err.cumsum()
                integs -= err
                integs *= c
                integs += integ  # integ + c (cumsum(err) - err): the integrator before each
                u = kp * err
                u += integs
                u_hi = a * amps  # (lim - a A) / g + slack, its bound clipped to [0, 1]
                np.subtract(lim, u_hi, out=u_hi)
                u_hi /= g
                np.minimum(np.maximum(u_hi, 0.0, out=u_hi), 1.0, out=u_hi)
                u_hi += DRIVE_SLACK
                bad = u > u_hi
                bad |= u < -DRIVE_SLACK
                j = int(bad.argmax())  # the first sample out of range (0: none, or the first)
                if j == 0 and not bad[0]:
                    j = rest.shape[0]
                if j == 0:  # rounding put the boundary sample out of range: saturate it
                    mode = _LOW if u[0] < -DRIVE_SLACK else _HIGH
                else:
                    drive = drive_out[k : k + j]
                    np.minimum(np.maximum(u[:j], 0.0, out=drive), 1.0, out=drive)
                    if j == rest.shape[0]:
                        amp_out[k + 1 : k + j] = amps[1:j]
                        amp, integ = float(zf[0]), float(integs[-1] + c * err[-1])
                        amp_out[k + j] = amp
                    else:
                        amp_out[k + 1 : k + j + 1] = amps[1 : j + 1]
                        amp, integ = float(amps[j]), float(integs[j])
                        self._chattering = j <= SHORT_RUN_SAMPLES
                    k += j
                    continue
            # Saturated: constant drive, the clamp or the brake. The integrator is frozen at full
            # drive, unwinds at zero drive, tracks the applied drive while the safety clamp acts
            # and zero drive while the brake acts.
            decay = co.decay[: rest.shape[0] + 1]
            integs = np.empty(rest.shape[0] + 1)
            integs[0] = integ
            applied: np.ndarray | None  # the drive while clamped or braked, None at zero drive
            clamp: np.ndarray | None
            if mode == _HIGH:
                amps = co.full + (amp - co.full) * decay
                np.minimum(amps, lim, out=amps)
                amps[0] = amp
                applied = a * amps[:-1]  # ((lim - a A) / g) clipped to [0, 1]
                np.subtract(lim, applied, out=applied)
                applied /= g
                np.minimum(np.maximum(applied, 0.0, out=applied), 1.0, out=applied)
                tracking = applied < 1.0
                err = rest - amps[:-1]
                integs[1:] = np.where(tracking, applied - kp * err, integ)
                u_lin = kp * err
                u_lin += integs[:-1]
                ceiling = applied + DRIVE_SLACK
                leave = u_lin <= ceiling
                clamp = tracking & ~leave  # tracking and above the applied drive
            elif mode == _OVER:
                amps, applied, leave = self._brake_run(amp, lim, decay, co)
                err = rest - amps[:-1]
                clamp = np.ones(rest.shape[0], dtype=bool)
                np.multiply(-kp, err, out=integs[1:])
            else:
                # Zero drive. The error is negative here (u_lin < 0 and I >= 0): the
                # integrator unwinds, down to zero drive at most.
                amps = amp * decay
                err = rest - amps[:-1]
                applied = clamp = None  # zero drive, no clamp (clamp_out is zero already)
                unwound = err.cumsum()
                unwound *= c
                unwound += integ
                np.maximum(unwound, min(integ, 0.0), out=integs[1:])
                u_lin = kp * err
                u_lin += integs[:-1]
                leave = u_lin >= -DRIVE_SLACK
            leave[0] = False
            j = int(leave.argmax())  # the first sample that leaves the mode (0: none)
            if j == 0:
                j = rest.shape[0]
            if applied is None or clamp is None:  # both None at zero drive
                drive_out[k : k + j] = 0.0
            else:
                drive_out[k : k + j] = applied[:j]
                clamp_out[k : k + j] = clamp[:j]
            amp_out[k + 1 : k + j + 1] = amps[1 : j + 1]
            amp, integ = float(amps[j]), float(integs[j])
            self._chattering = mode != _OVER and j <= SHORT_RUN_SAMPLES and k + j < n
            k += j
        self.amplitude_m, self.integrator = amp, integ

    def _steps(
        self,
        ref: np.ndarray,
        k: int,
        amp: float,
        integ: float,
        co: _Coefficients,
        amp_out: np.ndarray,
        drive_out: np.ndarray,
    ) -> tuple[int, float, float]:
        """The recursion of the module documentation sample by sample from sample ``k`` (loop
        state ``amp``, ``integ``) until one mode has lasted :data:`SHORT_RUN_SAMPLES` samples,
        the safety clamp or the brake would act (left to the vectorised solver), or ``ref``
        ends; returns the next sample and the loop state there. Writes the amplitudes and
        drives as :meth:`_segment` does (the clamp never acts here)."""
        n = ref.shape[0]
        kp, lim = self.gains.kp, self._limit
        over, a, g, c, full = lim * (1.0 + LIMIT_SLACK), co.a, co.g, co.c, co.full
        start, last, lasted, handed_back = k, -1, 0, False
        amps: list[float] = []
        drives: list[float] = []
        while k < n and not handed_back:
            for r in ref[k : k + 4 * SHORT_RUN_SAMPLES].tolist():
                if amp > over:
                    handed_back = True  # the brake
                    break
                e = r - amp
                u = kp * e + integ
                if u < -DRIVE_SLACK:  # zero drive; the integrator unwinds, not below zero drive
                    mode, drive = _LOW, 0.0
                    amp, integ = amp * a, max(integ + c * e, min(integ, 0.0))
                else:
                    bound = min(1.0, max((lim - a * amp) / g, 0.0))
                    if u > bound + DRIVE_SLACK:
                        if bound < 1.0:
                            handed_back = True  # the safety clamp
                            break
                        mode, drive = _HIGH, 1.0  # full drive; the integrator holds
                        amp = min(full + (amp - full) * a, lim)
                    else:
                        mode, drive = _LINEAR, min(max(u, 0.0), 1.0)
                        amp, integ = a * amp + g * u, integ + c * e
                amps.append(amp)
                drives.append(drive)
                lasted = lasted + 1 if mode == last else 1
                last = mode
                k += 1
                if lasted >= SHORT_RUN_SAMPLES:
                    handed_back = True
                    break
        self._chattering = not handed_back  # the chatter may go on in the next run
        if k > start:
            amp_out[start + 1 : k + 1] = amps
            drive_out[start:k] = drives
        return k, amp, integ
