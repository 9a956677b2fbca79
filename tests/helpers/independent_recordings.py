"""Calibration recordings generated independently of the effect plugins.

Every physical effect here is written from the thesis formulas directly, without importing
``builtin_plugins/hcard_builtins/effects.py``, ``hcard.physics.effects`` or any predictor: the base
laws, the effects and the sensor are this module's own code. Where the physics puts an effect
(the dry friction ``mu0`` inside the ultrasonic group Psi, the voltage before the
electrostatic law, a filter that restarts at touch-down), the generator puts it there, whatever
form the library's effect takes.

Devices (base laws, the models the loop is asked to calibrate):

- ``"uv"``: ultrasonic plate, ``F_l = mu0 Fn mu'`` (Eq. 2.34 with Eq. 2.29's ``mu' = mu/mu0``),
  ``mu' = 1 - exp(-Psi / Psi*)`` (Eq. 2.33, sign as section 2.6's derivation requires) with
  ``Psi = U / (w f mu0 (1 + nu))`` (Eq. 2.30); loop base model ``dimensionless-group``.
- ``"ev"``: electrovibration plate, ``F_l = mu (Fn + F_e)`` (Eq. 3.13) with the Kaczmarek law
  ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)(d_sc + d_i))`` (Eq. 3.12); loop base model
  ``ev-kaczmarek``.

Effects (:data:`EFFECTS`; each maps to the library effect the loop should name, or None when the
library has no such effect):

- ``occlusion``: ``mu0`` rises with accumulated contact time from 0.36 to 0.79 (Fig. 1.11,
  section 1.4.2.2, Smith and Scott) with ``tau_o`` = 20 s (Pasumarty et al., Fig. 1.11b); ``mu0``
  enters Psi as well as the force.
- ``load-index``: ``F_l = k_f F^n`` (Eq. 2.35) with ``n`` = 0.8 (``2/3 <= n <= 1``); on the EV
  plate ``F = Fn + F_e`` (the reaction force of Eq. 2.35).
- ``skin-recovery``: the ridges do not spring back fully between passes (Figs. 2.25-2.26): each
  stroke after a rest recovers a fixed share ``r`` of the remaining friction deficit, ``D_k+1 =
  r D_k`` from ``D_0`` (a recursion over strokes, on ``mu0``).
- ``actuator-rise``: the plate's amplitude follows its command through a first-order lag of
  ``tau_a`` = 15 ms (section 4.3, the plate of [86]); the plate keeps vibrating through lifts, so
  the lag runs on in time.
- ``charge-leakage``: the stratum corneum's charge leaks: the force follows the effective
  voltage ``v_e = tau_d s / (1 + tau_d s) v`` (Eqs. 3.19-3.23) with ``tau_d`` = 7.7 ms (section
  3.6.3); at touch-down the skin is uncharged, so the filter restarts there.
- ``air-layer``: air between ridges and insulator (Eq. 3.17) of thickness ``d_a = d_1 (1 N/Fn)``
  (thinner under load).
- ``speed``: the ultrasonic reduction falls with sliding speed faster than Eq. 2.30's Psi ~ U
  gives (spring-slider, Fig. 2.21e): ``1 - mu'`` is scaled by ``(U / 25 mm/s)^a``, with ``a``
  chosen so that at 3 um the reduction at 25 mm/s is 4 times that at 100 mm/s (Fig. 2.30,
  section 2.7).
- ``direction``: anisotropic skin: ``mu0`` is 20 % higher sliding towards -x than towards +x
  (no library effect).

Nuisances (:class:`Nuisances`): a lateral-force sensor offset that drifts, a ``stroke`` column
that carries the stroke number through the lifts, and dropped samples (rows missing, rule MF6).
Sensor noise (:class:`Noise`): white or AR(1) coloured, on both force channels.

:func:`generate` returns a :class:`~hcard.calibration.measurement.Measurement` (what
``hcard calibrate`` reads from a file); :func:`calibration_data` prepares it for the loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.constants

from hcard.calibration.dataset import CalibrationData, prepare
from hcard.calibration.measurement import Measurement

EPS0 = scipy.constants.epsilon_0
"""Vacuum permittivity, F/m."""

# -- base laws and their parameters (the truths) ----------------------------------------------
MU0 = 0.5
"""Dry friction coefficient of the finger (Figs. 2.21, 2.24: ~0.5)."""
POISSON = 0.33
"""Poisson ratio nu of the stratum corneum in Eq. 2.30 (the ``dimensionless-group`` default)."""
PSI_STAR = 2.38
"""Characteristic value of Psi (Eq. 2.33, Fig. 2.24: 2.38 +- 0.21)."""
PLATE_FREQUENCY_HZ = 30e3
"""Vibration frequency of the UV plate, Hz (Fig. 2.29's plates: 25-66 kHz)."""
D_SC, EPS_SC = 200e-6, 1560.0
"""Stratum corneum thickness (m) and relative permittivity (Table 3.2; section 3.6.1)."""
D_I, EPS_I = 90e-6, 3.35
"""Insulator thickness (m) and relative permittivity (line 1416)."""
EV_AREA = 4.4e-5
"""Contact area of the EV law, m^2 (about 0.1 N at 2000 V: a strong, clean signal)."""
EV_MU = 0.5
"""Friction coefficient of Eq. 3.13 on the EV plate."""

# -- effect parameters ------------------------------------------------------------------------
OCCLUSION_START, OCCLUSION_END = 0.36, 0.79
"""Friction coefficient before and at full occlusion (Fig. 1.11, Smith and Scott [46])."""
OCCLUSION_TIME_S = 20.0
"""Time constant of the occlusion rise over accumulated contact time, s (Fig. 1.11b)."""
LOAD_INDEX = 0.8
"""Frictional load index n of Eq. 2.35 (2/3 <= n <= 1)."""
LOAD_FACTOR = 0.52
"""Friction factor k_f of Eq. 2.35, N^(1-n) (Fig. 2.32, 10th cycle: 0.52 +- 0.01); the
recordings use the dry friction coefficient in its place."""
RECOVERY_DEFICIT = 0.3
"""Relative friction deficit of the first stroke after a rest."""
RECOVERY_SHARE = 0.5
"""Share of the deficit left after each further stroke."""
ACTUATOR_TIME_S = 15e-3
"""Actuator time constant, s (section 4.3: 15 ms for the plate of [86])."""
LEAKAGE_TIME_S = 7.7e-3
"""Charge-leakage time constant tau_d, s (section 3.6.3)."""
AIR_GAP_AT_1N_M = 5e-6
"""Air-layer thickness at a normal force of 1 N, m."""
SPEED_RATIO = 4.0
"""Reduction at 25 mm/s over that at 100 mm/s, at 3 um (Fig. 2.30, section 2.7)."""
SPEED_REFERENCE_M_S = 0.025
"""Speed at which the speed factor is 1, m/s."""
DIRECTION_CONTRAST = 0.2
"""Relative rise of mu0 sliding towards -x."""

EFFECTS: dict[str, str | None] = {
    "occlusion": "occlusion-drift",
    "load-index": "load-index",
    "skin-recovery": "skin-recovery",
    "actuator-rise": "actuator-bandwidth",
    "charge-leakage": "charge-leakage",
    "air-layer": "air-layer",
    "speed": "ultrasonic-speed",
    "direction": None,
}
"""Physical effect of this module -> the library effect that should be named (None: none)."""

DEVICE_EFFECTS = {
    "uv": ("occlusion", "load-index", "skin-recovery", "actuator-rise", "speed", "direction"),
    "ev": ("occlusion", "load-index", "skin-recovery", "charge-leakage", "air-layer", "direction"),
}
"""Effects each device can carry."""

BASE_MODEL = {"uv": "dimensionless-group", "ev": "ev-kaczmarek"}
"""The registry predictor the loop calibrates on each device's recordings."""


@dataclass(frozen=True)
class Protocol:
    """A bench's protocol: sessions of back-and-forth strokes with lifts between strokes and
    a rest between sessions.

    Attributes:
        sample_rate_hz: sampling rate, Hz.
        sessions: sessions per recording.
        strokes_per_session: strokes per session.
        stroke_s: contact time of one stroke, s.
        lift_s: finger lifted between strokes, s (shorter than the 0.5 s that rests it).
        rest_s: rest between sessions, s (longer than 0.5 s: the finger rests).
        forces_n: normal-force levels, N, each stroke one of them.
        speeds_m_s: sliding-speed levels, m/s, each stroke one of them.
        amplitudes_m: UV amplitude levels (peak-to-peak), m, a new one every segment.
        voltages_v: EV square-wave magnitudes, V, one per stroke.
        segment_s: UV amplitude segment / EV polarity half-period, s.
        wobble: relative amplitude of the finger's slow normal-force wobble (2 Hz).
    """

    sample_rate_hz: float = 1000.0
    sessions: int = 4
    strokes_per_session: int = 5
    stroke_s: float = 0.8
    lift_s: float = 0.2
    rest_s: float = 1.0
    forces_n: tuple[float, ...] = (0.2, 0.5, 1.0)
    speeds_m_s: tuple[float, ...] = (0.02, 0.05, 0.1)
    amplitudes_m: tuple[float, ...] = (0.0, 1e-6, 1.5e-6, 2e-6, 3e-6)
    voltages_v: tuple[float, ...] = (500.0, 1000.0, 1500.0, 2000.0)
    segment_s: float = 0.05
    wobble: float = 0.05

    def __post_init__(self) -> None:
        for name in ("sample_rate_hz", "stroke_s", "lift_s", "rest_s", "segment_s"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Protocol.{name} must be a finite number > 0, got {value}")
        for name in ("sessions", "strokes_per_session"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Protocol.{name} must be >= 1, got {getattr(self, name)}")
        for name in ("forces_n", "speeds_m_s", "voltages_v"):
            values = getattr(self, name)
            if not values or min(values) <= 0:
                raise ValueError(f"Protocol.{name} must be one or more values > 0")
        if not self.amplitudes_m or min(self.amplitudes_m) < 0:
            raise ValueError("Protocol.amplitudes_m must be one or more values >= 0")
        if not 0 <= self.wobble < 0.5:
            raise ValueError(f"Protocol.wobble must lie in [0, 0.5), got {self.wobble}")


@dataclass(frozen=True)
class Noise:
    """Force-sensor noise, the same law on both channels.

    Attributes:
        sigma_n: standard deviation of the noise, N.
        ar1: lag-1 coefficient of an AR(1) process (0: white), the marginal deviation stays
            ``sigma_n``.
    """

    sigma_n: float = 1.5e-3
    ar1: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_n) and self.sigma_n >= 0):
            raise ValueError(f"Noise.sigma_n must be a finite number >= 0 N, got {self.sigma_n}")
        if not 0 <= self.ar1 < 1:
            raise ValueError(f"Noise.ar1 must lie in [0, 1), got {self.ar1}")

    @property
    def label(self) -> str:
        """``"white"`` or ``"AR(1) 0.9"``."""
        return "white" if self.ar1 == 0 else f"AR(1) {self.ar1:g}"


WHITE = Noise(1.5e-3, 0.0)
COLOURED = Noise(1.5e-3, 0.9)


@dataclass(frozen=True)
class Nuisances:
    """What a real bench adds that is not friction.

    Attributes:
        offset_drift_n: the lateral-force sensor's zero drifts linearly by this much over the
            recording, N (plus a constant offset of the same size).
        stroke_column: write a ``stroke`` column that carries the stroke number through the
            lifts and rests (every sample then claims a stroke).
        dropped_fraction: share of rows dropped at random (lost samples, rule MF6).
    """

    offset_drift_n: float = 0.0
    stroke_column: bool = False
    dropped_fraction: float = 0.0

    def __post_init__(self) -> None:
        if not math.isfinite(self.offset_drift_n):
            raise ValueError("Nuisances.offset_drift_n must be finite")
        if not 0 <= self.dropped_fraction < 0.5:
            raise ValueError(
                f"Nuisances.dropped_fraction must lie in [0, 0.5), got {self.dropped_fraction}"
            )

    @property
    def label(self) -> str:
        """Short description, ``"none"`` when there is none."""
        parts = []
        if self.offset_drift_n:
            parts.append(f"offset drift {self.offset_drift_n * 1e3:g} mN")
        if self.stroke_column:
            parts.append("stroke column through lifts")
        if self.dropped_fraction:
            parts.append(f"{self.dropped_fraction:.0%} dropped")
        return ", ".join(parts) or "none"


NO_NUISANCE = Nuisances()
ALL_NUISANCES = Nuisances(offset_drift_n=3e-3, stroke_column=True, dropped_fraction=0.02)


@dataclass(frozen=True)
class Scenario:
    """One kind of recording: a device and the effects hidden in it.

    Attributes:
        device: ``"uv"`` or ``"ev"``.
        effects: physical effects of :data:`EFFECTS` present.
    """

    device: str
    effects: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.device not in DEVICE_EFFECTS:
            raise ValueError(
                f"Scenario.device must be one of {', '.join(DEVICE_EFFECTS)}, got {self.device!r}"
            )
        for effect in self.effects:
            if effect not in DEVICE_EFFECTS[self.device]:
                raise ValueError(
                    f"Scenario.effects: {effect!r} is not an effect of the {self.device} device "
                    f"({', '.join(DEVICE_EFFECTS[self.device])})"
                )

    @property
    def name(self) -> str:
        """E.g. ``"uv: occlusion + load-index"`` or ``"ev: clean"``."""
        return f"{self.device}: {' + '.join(self.effects) or 'clean'}"

    @property
    def expected(self) -> frozenset[str]:
        """Library effects the loop should name (empty for clean data)."""
        return frozenset(EFFECTS[e] for e in self.effects if EFFECTS[e] is not None)

    @property
    def out_of_library(self) -> bool:
        """Whether an effect without a library counterpart is hidden."""
        return any(EFFECTS[e] is None for e in self.effects)

    @property
    def kind(self) -> str:
        """``"clean"``, ``"single"``, ``"pair"`` or ``"out-of-library"``."""
        if self.out_of_library:
            return "out-of-library"
        return {0: "clean", 1: "single"}.get(len(self.effects), "pair")


# -- the protocol as a time line --------------------------------------------------------------
@dataclass(frozen=True)
class Timeline:
    """The true state of the bench at every sample.

    Attributes (arrays of shape (n,)): t (s), contact (bool), normal_force (N, the finger's
    true load; 0 lifted), speed (m/s, signed; 0 lifted), stroke (global stroke index; the last
    one through lifts), since_rest (strokes since the finger last rested), touchdown (index of
    the sample where the current contact began), command (UV amplitude command, m, or EV
    voltage, V).
    """

    t: np.ndarray
    contact: np.ndarray
    normal_force: np.ndarray
    speed: np.ndarray
    stroke: np.ndarray
    since_rest: np.ndarray
    touchdown: np.ndarray
    command: np.ndarray


def _levels(values: tuple[float, ...], count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` draws that use every level about equally often, in random order."""
    repeats = np.resize(np.asarray(values, dtype=np.float64), count)
    return rng.permutation(repeats)


def timeline(device: str, protocol: Protocol, rng: np.random.Generator) -> Timeline:
    """The bench's protocol sampled at ``protocol.sample_rate_hz`` (see :class:`Timeline`)."""
    dt = 1.0 / protocol.sample_rate_hz
    strokes = protocol.sessions * protocol.strokes_per_session
    forces = _levels(protocol.forces_n, strokes, rng)
    speeds = _levels(protocol.speeds_m_s, strokes, rng)
    volts = _levels(protocol.voltages_v, strokes, rng)
    pieces: list[tuple[int, bool, int, int, float, float, float]] = []
    # (samples, contact, global stroke, strokes since rest, force, speed, voltage)
    n_stroke = round(protocol.stroke_s / dt)
    n_lift = round(protocol.lift_s / dt)
    n_rest = round(protocol.rest_s / dt)
    k = 0
    for _session in range(protocol.sessions):
        pieces.append((n_rest, False, max(k - 1, 0), 0, 0.0, 0.0, 0.0))
        for j in range(protocol.strokes_per_session):
            direction = 1.0 if k % 2 == 0 else -1.0
            pieces.append((n_stroke, True, k, j, forces[k], direction * speeds[k], volts[k]))
            if j < protocol.strokes_per_session - 1:
                pieces.append((n_lift, False, k, j, 0.0, 0.0, volts[k]))
            k += 1
    pieces.append((n_rest, False, k - 1, 0, 0.0, 0.0, 0.0))
    sizes = np.array([p[0] for p in pieces])
    n = int(sizes.sum())
    t = np.arange(n) * dt
    contact = np.repeat([p[1] for p in pieces], sizes)
    stroke = np.repeat([p[2] for p in pieces], sizes)
    since_rest = np.repeat([p[3] for p in pieces], sizes)
    load = np.repeat([p[4] for p in pieces], sizes)
    speed = np.repeat([p[5] for p in pieces], sizes)
    magnitude = np.repeat([p[6] for p in pieces], sizes)
    phase = rng.uniform(0, 2 * np.pi)
    load = load * (1.0 + protocol.wobble * np.sin(2 * np.pi * 2.0 * t + phase))
    starts = np.flatnonzero(np.diff(contact.astype(np.int8), prepend=0) == 1)
    touchdown = np.zeros(n, dtype=np.int64)
    touchdown[starts] = starts
    touchdown = np.maximum.accumulate(touchdown)
    segment = np.floor(t / protocol.segment_s).astype(np.int64)
    if device == "uv":
        levels = rng.choice(np.asarray(protocol.amplitudes_m), size=int(segment.max()) + 1)
        command = levels[segment]
    else:
        command = magnitude * np.where(segment % 2 == 0, 1.0, -1.0)
    return Timeline(t, contact, load, speed, stroke, since_rest, touchdown, command)


# -- physics (written from the thesis, not imported) ------------------------------------------
def first_order_lag(command: np.ndarray, dt: float, tau: float,
                    restart: np.ndarray | None = None) -> np.ndarray:
    """Response ``y`` of ``tau dy/dt = u - y`` to a command ``u`` that holds each sample's value
    until the next sample (exact for that zero-order hold): the sample where the command
    changes shows no response yet. ``restart`` (bool, shape (n,)): samples where the state is
    reset to 0. Units of ``command``."""
    a = math.exp(-dt / tau)
    y = np.zeros_like(command, dtype=np.float64)
    state = 0.0
    for i in range(1, command.size):
        state = a * state + (1.0 - a) * command[i - 1]
        if restart is not None and restart[i]:
            state = 0.0
        y[i] = state
    return y


def occlusion_mu0(contact_time_s: np.ndarray) -> np.ndarray:
    """Friction coefficient after ``contact_time_s`` of accumulated contact (Fig. 1.11):
    ``0.36 + (0.79 - 0.36)(1 - exp(-t / 20 s))``."""
    rise = 1.0 - np.exp(-np.asarray(contact_time_s, dtype=np.float64) / OCCLUSION_TIME_S)
    return OCCLUSION_START + (OCCLUSION_END - OCCLUSION_START) * rise


def load_index_force(force_n: np.ndarray, factor: np.ndarray | float = LOAD_FACTOR,
                     index: float = LOAD_INDEX) -> np.ndarray:
    """Eq. 2.35, ``F_l = k_f F^n``, N, for the reaction force ``F`` in N, the friction factor
    ``k_f`` (N^(1-n)) and the load index ``n``."""
    return factor * np.power(np.maximum(np.asarray(force_n, dtype=np.float64), 1e-9), index)


def recovery_deficit(strokes_since_rest: np.ndarray) -> np.ndarray:
    """Relative friction deficit of each stroke after a rest: ``D_0`` = 0.3, then each stroke
    keeps :data:`RECOVERY_SHARE` of it (a recursion over strokes)."""
    k = np.asarray(strokes_since_rest, dtype=np.int64)
    table = [RECOVERY_DEFICIT]
    for _ in range(int(k.max(initial=0))):
        table.append(table[-1] * RECOVERY_SHARE)
    return np.asarray(table)[np.maximum(k, 0)]


def relative_friction(speed: np.ndarray, amplitude: np.ndarray, mu0: np.ndarray) -> np.ndarray:
    """Eq. 2.33 with Eq. 2.30: ``1 - exp(-Psi/Psi*)``, ``Psi = |U| / (w f mu0 (1 + nu))``;
    1 where the plate does not vibrate."""
    denominator = amplitude * PLATE_FREQUENCY_HZ * mu0 * (1.0 + POISSON)
    with np.errstate(divide="ignore", invalid="ignore"):
        psi = np.where(denominator > 0, np.abs(speed) / denominator, np.inf)
    return 1.0 - np.exp(-psi / PSI_STAR)


def speed_exponent() -> float:
    """Exponent ``a`` of the speed factor: Eq. 2.33 alone gives the reduction ratio
    ``r0 = exp(-Psi(25 mm/s)/Psi*) / exp(-Psi(100 mm/s)/Psi*)`` at 3 um; ``(1/4)^a r0 = 4``
    (Fig. 2.30)."""
    slow = 1.0 - relative_friction(np.array([0.025]), np.array([3e-6]), np.array([MU0]))[0]
    fast = 1.0 - relative_friction(np.array([0.100]), np.array([3e-6]), np.array([MU0]))[0]
    return -math.log(SPEED_RATIO / (slow / fast)) / math.log(4.0)


def speed_scaled_reduction(reduction: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """``1 - mu'`` scaled by ``(|U| / 25 mm/s)^a`` (:func:`speed_exponent`), capped at 1."""
    scale = np.power(np.maximum(np.abs(speed), 1e-6) / SPEED_REFERENCE_M_S, speed_exponent())
    return np.minimum(reduction * scale, 1.0)


def electrostatic_force(voltage: np.ndarray, air_gap_m: np.ndarray | float = 0.0) -> np.ndarray:
    """Eq. 3.17 (Eq. 3.12 at ``d_a = 0``): ``eps0 A v^2 / (2 (d_sc/eps_sc + d_a + d_i/eps_i)
    (d_sc + d_a + d_i))``, N, air permittivity 1."""
    gap = np.asarray(air_gap_m, dtype=np.float64)
    electrical = D_SC / EPS_SC + gap + D_I / EPS_I
    return EPS0 * EV_AREA * np.square(voltage) / (2.0 * electrical * (D_SC + gap + D_I))


def true_friction(scenario: Scenario, line: Timeline) -> np.ndarray:
    """The friction force opposing the motion, N, at every sample (0 lifted)."""
    effects = set(scenario.effects)
    dt = float(line.t[1] - line.t[0])
    contact = line.contact
    fn = line.normal_force
    accumulated = np.cumsum(contact) * dt
    index = LOAD_INDEX if "load-index" in effects else 1.0
    mu0 = np.full(line.t.shape, MU0 if scenario.device == "uv" else EV_MU)
    if "occlusion" in effects:
        mu0 = occlusion_mu0(accumulated)
    if "skin-recovery" in effects:
        mu0 = mu0 * (1.0 - recovery_deficit(line.since_rest))
    if "direction" in effects:
        mu0 = mu0 * np.where(line.speed < 0, 1.0 + DIRECTION_CONTRAST, 1.0)
    if scenario.device == "uv":
        amplitude = line.command
        if "actuator-rise" in effects:
            amplitude = first_order_lag(line.command, dt, ACTUATOR_TIME_S)
        reduction = relative_friction(line.speed, amplitude, mu0)
        if "speed" in effects:
            reduction = 1.0 - speed_scaled_reduction(1.0 - reduction, line.speed)
        # Eq. 2.35 with k_f = mu0 (n = 1: Coulomb, Eq. 2.34)
        force = load_index_force(fn, mu0, index) * reduction
    else:
        voltage = line.command
        if "charge-leakage" in effects:
            # Eq. 3.22: v_e = v - (low-pass of v), the skin uncharged at every touch-down
            touchdown = np.zeros(line.t.shape, dtype=bool)
            touchdown[np.flatnonzero(np.diff(contact.astype(np.int8), prepend=0) == 1)] = True
            voltage = voltage - first_order_lag(voltage, dt, LEAKAGE_TIME_S, restart=touchdown)
        gap = AIR_GAP_AT_1N_M / np.maximum(fn, 1e-3) if "air-layer" in effects else 0.0
        # Eq. 3.13 (n = 1), or Eq. 2.35 on the reaction force Fn + F_e
        force = load_index_force(fn + electrostatic_force(voltage, gap), mu0, index)
    return np.where(contact, force, 0.0)


def sensor_noise(noise: Noise, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples of the sensor noise, N: white, or AR(1) ``e_k = rho e_k-1 + sqrt(1 -
    rho^2) sigma eta_k`` started from its stationary law."""
    eta = rng.standard_normal(n) * noise.sigma_n
    if noise.ar1 == 0:
        return eta
    out = np.empty(n)
    out[0] = eta[0]
    scale = math.sqrt(1.0 - noise.ar1**2)
    for i in range(1, n):
        out[i] = noise.ar1 * out[i - 1] + scale * eta[i]
    return out


def generate(
    scenario: Scenario,
    seed: int,
    *,
    noise: Noise = WHITE,
    nuisances: Nuisances = NO_NUISANCE,
    protocol: Protocol | None = None,
) -> Measurement:
    """One recording of ``scenario`` (module docstring), reproducible from ``seed``.

    Columns: ``t``, ``fn``, ``fl`` (signed by the direction of motion, plus the sensor zero),
    ``speed`` (signed), ``amplitude`` (UV, the command) or ``voltage`` (EV), and with
    ``nuisances.stroke_column`` a ``stroke`` column carried through the lifts. The sidecar names
    the generator, the scenario, the seed and (UV) the plate frequency.
    """
    protocol = protocol or Protocol()
    rng = np.random.default_rng(seed)
    line = timeline(scenario.device, protocol, rng)
    friction = true_friction(scenario, line)
    n = line.t.size
    direction = np.where(line.speed < 0, -1.0, 1.0)
    zero = nuisances.offset_drift_n * (1.0 + line.t / line.t[-1])
    lateral = direction * friction + zero + sensor_noise(noise, n, rng)
    normal = line.normal_force + sensor_noise(noise, n, rng)
    keep = np.ones(n, dtype=bool)
    if nuisances.dropped_fraction:
        drop = rng.choice(n - 2, size=round(nuisances.dropped_fraction * n), replace=False) + 1
        keep[drop] = False
    conditions: dict = {
        "device": f"independent generator ({scenario.device})",
        "notes": f"{scenario.name}; seed {seed}; noise {noise.label}; nuisances {nuisances.label}",
    }
    if scenario.device == "uv":
        conditions["plate_frequency_hz"] = PLATE_FREQUENCY_HZ
    return Measurement(
        t=line.t[keep],
        normal_force=normal[keep],
        lateral_force=lateral[keep],
        amplitude=line.command[keep] if scenario.device == "uv" else None,
        voltage=line.command[keep] if scenario.device == "ev" else None,
        speed=line.speed[keep],
        stroke=line.stroke[keep].astype(np.int64) if nuisances.stroke_column else None,
        conditions=conditions,
    )


def calibration_data(
    scenario: Scenario,
    seed: int,
    *,
    noise: Noise = WHITE,
    nuisances: Nuisances = NO_NUISANCE,
    protocol: Protocol | None = None,
) -> CalibrationData:
    """:func:`generate` made ready for the loop (``prepare``: stroke split drawn with ``seed``,
    contact from the forces, the sensor zero measured at the lifts)."""
    recording = generate(scenario, seed, noise=noise, nuisances=nuisances, protocol=protocol)
    return prepare([recording], seed=seed)


# -- the test set -----------------------------------------------------------------------------
CLEAN = (Scenario("uv"), Scenario("ev"))
SINGLES = (
    Scenario("uv", ("occlusion",)),
    Scenario("uv", ("load-index",)),
    Scenario("uv", ("skin-recovery",)),
    Scenario("uv", ("actuator-rise",)),
    Scenario("uv", ("speed",)),
    Scenario("ev", ("charge-leakage",)),
    Scenario("ev", ("air-layer",)),
    Scenario("ev", ("load-index",)),
)
PAIRS = (
    Scenario("uv", ("occlusion", "load-index")),
    Scenario("ev", ("charge-leakage", "load-index")),
)
OUT_OF_LIBRARY = (Scenario("uv", ("direction",)),)
SCENARIOS = CLEAN + SINGLES + PAIRS + OUT_OF_LIBRARY
"""Every scenario of the set: clean, each in-library effect alone, pairs, one out-of-library."""
