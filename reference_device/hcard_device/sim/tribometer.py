"""Synthetic tribometer recordings of the simulated finger, with hidden physical effects.

:func:`synthesize` plays a tribometer protocol (:class:`Protocol`: back-and-forth strokes along
x at one random speed and normal force per stroke, sessions of strokes separated by rests with
the finger lifted, a piecewise-constant random UV amplitude and/or a square-wave EV voltage)
on a reference device and returns one :class:`~hcard.calibration.measurement.Measurement` per
ambient pressure, in the format of spec/measurement-format.md. The recordings say nothing about
which effects were switched on: they are test data for calibration ("which effect explains the
residual?").

Clean physics (no effects): the device's own predictors (:func:`.models.device_profile`):

- UV factor ``mu'`` = :class:`DimensionlessGroup` (Eqs. 2.30-2.33) at the device's plate
  frequency, the finger's |speed| and normal force (``mu' = 1`` on the "ev" device, plate off);
- EV force ``F_e`` = :class:`Kaczmarek` (Eq. 3.12) of the instantaneous voltage (0 on "uv");
- lateral force ``F_l = mu_f Fn mu' (1 + F_e / Fn)`` (Eq. 4.1), the bare finger Coulomb:
  ``mu_f`` = the device's ``mu0`` (load index 1, no occlusion, no speed peak).

Effects (name -> true parameter values; missing values take the effect's defaults). The five
below run the physics of their own model, not the calibration effect's formula:

- ``load-index``: ``mu_f`` from :class:`FingerFriction` with ``load_index = n`` (friction
  ``mu0`` at 1 N, no occlusion, ``speed_sensitivity = 0``) at the reaction force ``Fn + F_e``
  (Eq. 2.35 with Eq. 3.1), so ``F_l = k (Fn + F_e)^n mu'``;
- ``occlusion-drift``: :class:`FingerFriction` occlusion over the time in contact since the
  recording began (lifts excluded, Fig. 1.11b), ``friction_initial = mu0``,
  ``friction_occluded = mu0 (1 + gain)``, ``occlusion_time = time_constant``;
- ``charge-leakage``: the voltage acting on the finger is the exact discrete high pass of
  :meth:`ChargeLeakage.simulate` (Eqs. 3.19-3.23) of the applied voltage, a constant ``tau_d =
  time_constant`` (``tau_d_exponent = 0``); the recording's voltage column is the applied
  voltage;
- ``air-layer``: ``F_e`` from :class:`AirLayer` (Eq. 3.17, with the contact layers of the
  device's Kaczmarek model) at ``air_gap = air_gap * (1 N / Fn)``;
- ``actuator-bandwidth``: the plate amplitude follows the commanded amplitude through a
  first-order envelope of time constant ``tau`` (exact discrete step response, zero-order hold,
  as the plate of :mod:`.plate`); the recording's amplitude column is the commanded amplitude.

Every other registered calibration effect (``ultrasonic-speed``, ``skin-recovery``,
``squeeze-film-share``, ``finger-geometry``, plugins' effects) is applied with the effect
plugin's own :meth:`~hcard.physics.effects.Effect.transform_inputs` /
:meth:`~hcard.physics.effects.Effect.transform_output` on the component its ``outputs``
names: ``mu'`` for ``relative_friction``, ``F_e`` for ``electrostatic_force``, the total lateral
force otherwise. Their inputs: ``time`` (s since the recording began), ``stroke`` (strokes since
the finger last rested, 0 for the first stroke after a rest), ``speed`` (|speed|, m/s),
``normal_force`` (true, N), ``pressure`` (Pa), ``amplitude`` (acting, m), ``voltage`` (acting,
V); any other input of an effect takes its default.

``surface-patch`` lies outside the effect library (for testing the "not explained" answer): a
worn band of the plate multiplies the friction by ``1 + depth`` for finger positions x in
``[x0, x0 + width]``, with smooth (smoothstep) 1 mm edges centred on the band's ends.

Nuisances: Gaussian lateral-force noise, recorded normal force = true + Gaussian noise (the
physics uses the true force), a smooth random drift of the lateral sensor's offset (a low-passed
random walk scaled to a peak-to-peak size of ``drift_n`` over each recording). During rests the
recorded normal force is noise clipped to +-9 mN and the lateral force is offset + noise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hcard.calibration.measurement import Measurement
from hcard.physics import Parameter, PredictorError
from hcard.quantities import ATMOSPHERE_PA
from hcard_builtins.physics.electrovibration import AirLayer, ChargeLeakage, Kaczmarek
from hcard_builtins.physics.finger import FingerFriction
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile

DEVICES = ("uv", "ev", "coupled")
"""Devices: E-ViTa (UV only), the coupled stimulator with the plate off (EV only), both."""

PHYSICAL_EFFECTS = (
    "load-index",
    "occlusion-drift",
    "charge-leakage",
    "air-layer",
    "actuator-bandwidth",
)
"""Effects simulated with their own physical model rather than the effect plugin's formula."""

SURFACE_PATCH = "surface-patch"
"""The effect outside the effect library: a worn band of the plate."""

SURFACE_PATCH_PARAMETERS: tuple[Parameter, ...] = (
    Parameter("depth", "", 0.3, (-0.95, 10.0), "synthetic", "relative friction excess"),
    Parameter("x0", "m", 0.01, (-1.0, 1.0), "synthetic", "start of the band along x"),
    Parameter("width", "m", 0.008, (0.0, 1.0), "synthetic", "width of the band along x"),
)
"""Parameters of ``surface-patch``."""

PATCH_EDGE_M = 1e-3
"""Width of the smooth edges of the surface patch, m."""

MAX_AMPLITUDE_M = 3e-6
"""Largest commanded amplitude level of the UV protocol, m peak-to-peak."""

VOLTAGE_RANGE_V = (200.0, 1500.0)
"""Default range of the EV square wave's magnitude, drawn per stroke, V: within the coupled
stimulator's 2 kV amplifier, and the 1.4-2 kV of the thesis's force measurements (Table 3.4),
which a 90 um insulator needs for an electrostatic force comparable to the normal force."""

REST_NOISE_LIMIT_N = 0.009
"""The recorded normal force during rests stays within +- this, N (below the 0.01 N contact
threshold of rule MS2)."""

MIN_CONTACT_FORCE_N = 0.011
"""The recorded normal force in contact never falls below this, N (stays a contact sample)."""

X_START_M = 0.005
"""Position where the first stroke starts, m (strokes run between here and + stroke length)."""

Y_M = 0.025
"""Constant finger position across the strokes, m."""


@dataclass(frozen=True)
class Protocol:
    """What the tribometer does.

    Attributes:
        duration_s: length of each recording, s.
        sample_rate_hz: sampling rate, Hz.
        stroke_length_m: length of the back-and-forth strokes along x, m.
        speed_range_m_s: (low, high) of the speed drawn uniformly per stroke, m/s.
        force_range_n: (low, high) of the normal force drawn uniformly per stroke, N.
        strokes_per_session: strokes before the finger lifts and rests.
        rest_s: rest out of contact between sessions, s.
        amplitude_segment_s: UV: the commanded amplitude takes a new random level in
            0..3 um every segment, s.
        voltage_segment_s: EV: the square wave's polarity flips every segment, s.
        voltage_range_v: (low, high) of the square wave's magnitude, drawn uniformly per
            stroke, V.
        pressures_pa: ambient pressures, one recording each, Pa.
    """

    duration_s: float = 60.0
    sample_rate_hz: float = 1000.0
    stroke_length_m: float = 0.03
    speed_range_m_s: tuple[float, float] = (0.02, 0.15)
    force_range_n: tuple[float, float] = (0.2, 1.5)
    strokes_per_session: int = 5
    rest_s: float = 1.0
    amplitude_segment_s: float = 0.03
    voltage_segment_s: float = 0.04
    voltage_range_v: tuple[float, float] = VOLTAGE_RANGE_V
    pressures_pa: tuple[float, ...] = (ATMOSPHERE_PA,)

    def __post_init__(self) -> None:
        positive = (
            "duration_s",
            "sample_rate_hz",
            "stroke_length_m",
            "amplitude_segment_s",
            "voltage_segment_s",
        )
        for name in positive:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Protocol.{name} must be a finite number > 0, got {value}")
        if not (math.isfinite(self.rest_s) and self.rest_s >= 0):
            raise ValueError(f"Protocol.rest_s must be a finite number >= 0, got {self.rest_s}")
        for name in ("speed_range_m_s", "force_range_n", "voltage_range_v"):
            low, high = getattr(self, name)
            if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
                raise ValueError(f"Protocol.{name} must be (low, high) with 0 < low <= high")
        if self.strokes_per_session < 1:
            raise ValueError("Protocol.strokes_per_session must be >= 1")
        if not self.pressures_pa or not all(math.isfinite(p) and p >= 0 for p in self.pressures_pa):
            raise ValueError("Protocol.pressures_pa must be one or more finite pressures >= 0")
        if round(self.duration_s * self.sample_rate_hz) < 2:
            raise ValueError("Protocol: a recording needs at least 2 samples")


# -- effects ----------------------------------------------------------------------------------
def _library() -> dict[str, Any]:
    from hcard.plugins.registry import get_registry

    return dict(get_registry().calibration_effects)


def available_effects() -> list[str]:
    """Names :func:`synthesize` accepts: the registered calibration effects and
    ``surface-patch``, sorted."""
    return sorted({*_library(), SURFACE_PATCH})


def effect_parameters(name: str) -> tuple[Parameter, ...]:
    """The parameters (name, unit, default, bounds) of effect ``name``.

    Raises:
        ValueError: unknown effect (the message lists the known ones).
    """
    if name == SURFACE_PATCH:
        return SURFACE_PATCH_PARAMETERS
    library = _library()
    if name not in library:
        raise ValueError(
            f"unknown effect {name!r}; known effects: {', '.join(available_effects())}"
        )
    return tuple(library[name].parameters)


def resolve_effects(
    effects: Mapping[str, Mapping[str, float]] | None,
) -> dict[str, dict[str, float]]:
    """``effects`` checked and completed with the defaults of missing parameters.

    Raises:
        ValueError: an unknown effect or parameter name (listing the known ones), or a value
            that is not finite or outside the parameter's bounds.
    """
    resolved: dict[str, dict[str, float]] = {}
    for name, values in (effects or {}).items():
        parameters = effect_parameters(name)
        known = {p.name: p for p in parameters}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ValueError(
                f"effect {name}: unknown parameter(s) {', '.join(unknown)}; its parameters: "
                f"{', '.join(known) or 'none'}"
            )
        out: dict[str, float] = {}
        for parameter in parameters:
            value = values.get(parameter.name, parameter.default)
            try:
                out[parameter.name] = parameter.check(value)
            except (PredictorError, TypeError, ValueError) as exc:
                raise ValueError(f"effect {name}: {exc}") from None
        resolved[name] = out
    return resolved


class _SimulatedFinger(FingerFriction):
    """:class:`FingerFriction` whose load index may take any value the ``load-index`` effect
    allows (0.3..1.5) and whose friction any positive value (same physics)."""

    parameters = tuple(
        Parameter(p.name, p.unit, p.default, (0.3, 1.5), p.source, p.description)
        if p.name == "load_index"
        else Parameter(p.name, p.unit, p.default, (1e-6, 1e3), p.source, p.description)
        if p.name.startswith("friction_")
        else p
        for p in FingerFriction.parameters
    )


# -- protocol -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Schedule:
    """Per-sample kinematics and commands of one recording (true values)."""

    t: np.ndarray
    x: np.ndarray
    speed: np.ndarray
    normal_force: np.ndarray
    contact: np.ndarray
    stroke: np.ndarray  # strokes since the last rest; -1 at rest
    amplitude: np.ndarray
    voltage: np.ndarray


def _schedule(protocol: Protocol, rng: np.random.Generator) -> _Schedule:
    n = round(protocol.duration_s * protocol.sample_rate_hz)
    t = np.arange(n) / protocol.sample_rate_hz
    end = t[-1]
    starts, speeds, forces, magnitudes, strokes, x_starts = [], [], [], [], [], []
    time, x_pos, direction, magnitude = 0.0, X_START_M, 1.0, protocol.voltage_range_v[0]
    while time <= end:
        for k in range(protocol.strokes_per_session):
            stroke_speed = rng.uniform(*protocol.speed_range_m_s)
            stroke_force = rng.uniform(*protocol.force_range_n)
            magnitude = rng.uniform(*protocol.voltage_range_v)
            starts.append(time)
            speeds.append(direction * stroke_speed)
            forces.append(stroke_force)
            magnitudes.append(magnitude)
            strokes.append(k)
            x_starts.append(x_pos)
            time += protocol.stroke_length_m / stroke_speed
            x_pos += direction * protocol.stroke_length_m
            direction = -direction
            if time > end:
                break
        if protocol.rest_s > 0:
            starts.append(time)
            speeds.append(0.0)
            forces.append(0.0)
            magnitudes.append(magnitude)
            strokes.append(-1)
            x_starts.append(x_pos)
            time += protocol.rest_s
    start = np.array(starts)
    index = np.searchsorted(start, t, side="right") - 1
    speed = np.array(speeds)[index]
    x = np.array(x_starts)[index] + speed * (t - start[index])
    force = np.array(forces)[index]
    stroke = np.array(strokes, dtype=np.int64)[index]
    levels = rng.uniform(0.0, MAX_AMPLITUDE_M, size=int(end / protocol.amplitude_segment_s) + 2)
    amplitude = levels[_segment_index(t, protocol.amplitude_segment_s)]
    polarity = 1.0 - 2.0 * (_segment_index(t, protocol.voltage_segment_s) % 2)
    voltage = np.array(magnitudes)[index] * polarity
    return _Schedule(t, x, speed, force, force > 0, stroke, amplitude, voltage)


def _segment_index(t: np.ndarray, segment_s: float) -> np.ndarray:
    """Index of the segment of length ``segment_s`` each time falls in (boundaries exact to
    rounding: 0.232 s / 0.04 s is segment 5, not 4.999...)."""
    return np.floor(np.round(t / segment_s, 9)).astype(np.int64)


def _drift(n: int, sample_rate_hz: float, size: float, rng: np.random.Generator) -> np.ndarray:
    """A smooth random offset: a random walk low-passed (time constant a twentieth of the
    recording, at least 0.5 s), peak-to-peak ``size``."""
    if size <= 0 or n < 2:
        return np.zeros(n)
    walk = np.cumsum(rng.normal(size=n))
    a = math.exp(-1.0 / (max(n / sample_rate_hz / 20.0, 0.5) * sample_rate_hz))
    from scipy.signal import lfilter  # here: scipy.signal costs ~0.6 s to import
    smooth = lfilter([1.0 - a], [1.0, -a], walk - walk[0])
    smooth -= smooth.mean()
    span = float(np.ptp(smooth))
    return smooth * (size / span) if span > 0 else np.zeros(n)


def _patch(x: np.ndarray, x0: float, width: float) -> np.ndarray:
    """Weight 0..1 of the worn band [x0, x0 + width] with smoothstep edges of 1 mm."""

    def step(u: np.ndarray) -> np.ndarray:
        u = np.clip(u, 0.0, 1.0)
        return u * u * (3.0 - 2.0 * u)

    rise = step((x - x0) / PATCH_EDGE_M + 0.5)
    fall = step((x0 + width - x) / PATCH_EDGE_M + 0.5)
    return rise * fall


# -- synthesis --------------------------------------------------------------------------------
def _models(device: str) -> tuple[DeviceConfig, DimensionlessGroup | None, Kaczmarek | None]:
    if device == "uv":
        config = DeviceConfig.evita()
        uv = device_profile(config).predictor
        assert isinstance(uv, DimensionlessGroup)
        return config, uv, None
    config = DeviceConfig.coupled()
    coupled: Any = device_profile(config).predictor
    return config, (coupled.uv if device == "coupled" else None), coupled.ev


def _apply_inputs(effects: list[tuple[Any, dict[str, float]]], inputs: dict) -> dict:
    for effect, params in effects:
        inputs = effect.transform_inputs(inputs, params)
    return dict(inputs)


def _apply_output(
    effects: list[tuple[Any, dict[str, float]]], output: np.ndarray, inputs: dict
) -> np.ndarray:
    for effect, params in effects:
        output = np.asarray(effect.transform_output(output, inputs, params), dtype=np.float64)
    return output


@dataclass(frozen=True)
class _Plan:
    """What one synthesis simulates: the device's models and the hidden effects, sorted by the
    component they act on.

    Attributes:
        device: the device name (:data:`DEVICES`).
        chosen: effect name -> true parameter values (:func:`resolve_effects`).
        config: the device's configuration.
        uv_model: the UV factor's model, or None (plate off).
        ev_model: the EV force's model, or None (no electrodes driven).
        generic: the effects applied with the effect plugin's own transforms, name ->
            (effect, parameters).
        on_uv, on_ev, on_total: those acting on ``mu'``, on ``F_e`` and on the total lateral
            force.
        finger: the bare finger's friction model, or None (Coulomb, ``mu_f = mu0``).
    """

    device: str
    chosen: Mapping[str, Mapping[str, float]]
    config: DeviceConfig
    uv_model: DimensionlessGroup | None
    ev_model: Kaczmarek | None
    generic: dict[str, tuple[Any, dict[str, float]]]
    on_uv: list[tuple[Any, dict[str, float]]]
    on_ev: list[tuple[Any, dict[str, float]]]
    on_total: list[tuple[Any, dict[str, float]]]
    finger: FingerFriction | None


def _check_noise(lateral_noise_n: float, normal_noise_n: float, drift_n: float) -> None:
    """Refuse a noise level (N) that is not a finite number >= 0 (ValueError naming it)."""
    for name, value in (
        ("lateral_noise_n", lateral_noise_n),
        ("normal_noise_n", normal_noise_n),
        ("drift_n", drift_n),
    ):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value}")


def _plan(device: str, effects: Mapping[str, Mapping[str, float]] | None) -> _Plan:
    """The :class:`_Plan` of ``effects`` on ``device``, one of :data:`DEVICES` (the caller
    checks it, before the noise levels), ValueError: unknown effect or parameter, or an effect
    on an output the simulation does not model."""
    chosen = resolve_effects(effects)
    config, uv_model, ev_model = _models(device)
    library = _library()
    generic = {
        name: (library[name], params)
        for name, params in chosen.items()
        if name not in PHYSICAL_EFFECTS and name != SURFACE_PATCH
    }
    on_other = sorted(
        name
        for name, (effect, _) in generic.items()
        if effect.outputs and not {"relative_friction", "electrostatic_force"} & set(effect.outputs)
    )
    if on_other:
        raise ValueError(
            f"effect(s) {', '.join(on_other)} apply to outputs the tribometer simulation does "
            "not model"
        )
    return _Plan(
        device=device,
        chosen=chosen,
        config=config,
        uv_model=uv_model,
        ev_model=ev_model,
        generic=generic,
        on_uv=[e for e in generic.values() if "relative_friction" in e[0].outputs],
        on_ev=[e for e in generic.values() if "electrostatic_force" in e[0].outputs],
        on_total=[e for e in generic.values() if not e[0].outputs],
        finger=_finger(config.mu0, chosen),
    )


def _acting_drive(plan: _Plan, s: _Schedule, sample_rate_hz: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The plate amplitude (m) and voltage (V) acting on the finger: the commanded ones of
    ``s`` (0 where the device lacks the actuator), the amplitude through the actuator's
    first-order envelope (``actuator-bandwidth``, exact discrete step response at
    ``sample_rate_hz``), the voltage through the skin's high pass (``charge-leakage``)."""
    n = s.t.size
    chosen, ev_model = plan.chosen, plan.ev_model
    uv_ok = plan.uv_model is not None
    amplitude = s.amplitude if uv_ok else np.zeros(n)
    if uv_ok and "actuator-bandwidth" in chosen:
        tau = chosen["actuator-bandwidth"]["time_constant"]
        a = math.exp(-1.0 / (sample_rate_hz * tau))
        from scipy.signal import lfilter  # here: scipy.signal costs ~0.6 s to import
        amplitude = lfilter([0.0, 1.0 - a], [1.0, -a], s.amplitude)
    voltage = s.voltage if ev_model is not None else np.zeros(n)
    if ev_model is not None and "charge-leakage" in chosen:
        leakage = ChargeLeakage(  # a constant tau_d: Eq. 3.22 as the pure high pass
            tau_d_curve=None,
            tau_d=chosen["charge-leakage"]["time_constant"], tau_d_exponent=0.0,
            **{p.name: ev_model[p.name] for p in Kaczmarek.parameters},
        )
        voltage = leakage.simulate(s.t, s.voltage).effective_voltage
    return amplitude, voltage


def _effect_inputs(plan: _Plan, s: _Schedule, pressure: float, amplitude: np.ndarray,
                   voltage: np.ndarray) -> dict[str, np.ndarray]:
    """The inputs every effect sees (module docstring), SI units, after the effects on the
    total force transformed them: time (s), stroke (strokes since rest), |speed| (m/s), the
    true normal force (N; 1 N at rest), pressure (Pa), the acting amplitude (m) and voltage
    (V), and each other effect input at its default."""
    n = s.t.size
    session_stroke = np.where(s.stroke >= 0, s.stroke, 0).astype(np.float64)
    base = {
        "time": s.t,
        "stroke": session_stroke,
        "speed": np.abs(s.speed),
        # physics on contact samples; 1 N at rest
        "normal_force": np.where(s.contact, s.normal_force, 1.0),
        "pressure": np.full(n, float(pressure)),
        "amplitude": amplitude,
        "voltage": voltage,
    }
    for effect, _ in plan.generic.values():
        for variable in effect.inputs:
            if variable.name not in base and variable.default is not None:
                base[variable.name] = np.full(n, float(variable.default))
    return _apply_inputs(plan.on_total, base)


def _relative_friction(plan: _Plan, total_in: dict[str, np.ndarray]) -> np.ndarray:
    """The UV factor ``mu'`` (Eqs. 2.30-2.33, dimensionless) with its effects; 1 with the
    plate off."""
    if plan.uv_model is None:
        return np.ones(total_in["time"].size)
    uv_in = _apply_inputs(plan.on_uv, total_in)
    mu_uv = plan.uv_model.forward(
        amplitude=uv_in["amplitude"],
        frequency=plan.config.limits.plate_frequency,
        speed=np.abs(uv_in["speed"]),
        normal_force=uv_in["normal_force"],
    )
    return _apply_output(plan.on_uv, mu_uv, uv_in)


def _electrostatic_force(plan: _Plan, total_in: dict[str, np.ndarray]) -> np.ndarray:
    """The EV force ``F_e`` (Eq. 3.12, or Eq. 3.17 with an ``air-layer``), N, with its
    effects; 0 without electrodes driven."""
    ev_model = plan.ev_model
    if ev_model is None:
        return np.zeros(total_in["time"].size)
    ev_in = _apply_inputs(plan.on_ev, total_in)
    if "air-layer" in plan.chosen:
        air = AirLayer(**{p.name: ev_model[p.name] for p in Kaczmarek.parameters})
        gap = plan.chosen["air-layer"]["air_gap"] / ev_in["normal_force"]
        force_e = air.forward(voltage=ev_in["voltage"], air_gap=gap)
    else:
        force_e = ev_model.forward(voltage=ev_in["voltage"])
    return _apply_output(plan.on_ev, force_e, ev_in)


def _lateral_force(plan: _Plan, s: _Schedule, total_in: dict[str, np.ndarray],
                   mu_uv: np.ndarray, force_e: np.ndarray) -> np.ndarray:
    """The true friction force, N: ``mu_f mu' (Fn + F_e)`` (Eq. 4.1 with Eq. 3.1) with the
    finger's friction, the effects on the total force and a ``surface-patch``; 0 at rest."""
    n = s.t.size
    fn_phys = total_in["normal_force"]
    reaction = fn_phys + force_e  # Eq. 3.1: the attraction presses the skin as well
    if plan.finger is None:
        mu_f = np.full(n, plan.config.mu0)
    else:
        # Eq. 2.35 on the reaction force; occlusion over the time in contact (Fig. 1.11b)
        occlusion_time = np.cumsum(np.diff(s.t, prepend=s.t[:1]) * s.contact)
        mu_f = plan.finger.friction_coefficient(
            normal_force=np.maximum(reaction, 1e-9),
            speed=np.abs(total_in["speed"]),
            contact_time=occlusion_time,
        )
    lateral = mu_f * mu_uv * reaction
    lateral = _apply_output(plan.on_total, lateral, total_in)
    if SURFACE_PATCH in plan.chosen:
        patch = plan.chosen[SURFACE_PATCH]
        lateral = lateral * (1.0 + patch["depth"] * _patch(s.x, patch["x0"], patch["width"]))
    return np.where(s.contact, lateral, 0.0)


def _recorded_forces(s: _Schedule, lateral: np.ndarray, sample_rate_hz: float,
                     lateral_noise_n: float, normal_noise_n: float, drift_n: float,
                     noise: np.random.Generator, drift: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The recorded ``(lateral, normal)`` forces, N: the lateral force signed with the
    direction of motion (rule MF3) plus the sensor's drifting zero (from ``drift``) and white
    noise; the normal force plus white noise, at least 11 mN in contact, clipped to +-9 mN at
    rest (both noises from ``noise``, lateral first)."""
    n = s.t.size
    direction = np.where(s.speed < 0, -1.0, 1.0)
    fl = direction * lateral + _drift(n, sample_rate_hz, drift_n, drift)
    fl = fl + lateral_noise_n * noise.normal(size=n)
    fn_noise = normal_noise_n * noise.normal(size=n)
    fn_rec = np.where(
        s.contact,
        np.maximum(s.normal_force + fn_noise, MIN_CONTACT_FORCE_N),
        np.clip(fn_noise, -REST_NOISE_LIMIT_N, REST_NOISE_LIMIT_N),
    )
    return fl, fn_rec


def synthesize(
    device: str,
    effects: Mapping[str, Mapping[str, float]] | None = None,
    *,
    protocol: Protocol = Protocol(),
    lateral_noise_n: float = 0.002,
    normal_noise_n: float = 0.002,
    drift_n: float = 0.0,
    seed: int = 0,
) -> list[Measurement]:
    """Tribometer recordings of the simulated finger on ``device``, one per pressure.

    Args:
        device: ``"uv"`` (E-ViTa: amplitude column), ``"ev"`` (coupled stimulator, plate off:
            voltage column) or ``"coupled"`` (both).
        effects: effect name -> true parameter values (see the module documentation; missing
            values take the effect's defaults). Nothing in the output names them.
        protocol: what the tribometer does.
        lateral_noise_n: standard deviation of the lateral force noise, N.
        normal_noise_n: standard deviation of the recorded normal force's noise, N.
        drift_n: peak-to-peak size of the lateral sensor's offset drift per recording, N.
        seed: seed of every random draw; the protocol's draws do not depend on the effects or
            the noise levels, so recordings with the same seed share their kinematics.

    Returns:
        One :class:`Measurement` per pressure of ``protocol``: columns t, amplitude (uv,
        coupled), voltage (ev, coupled), x, y, speed (signed), fn, fl; no stroke column.

    Raises:
        ValueError: unknown device, effect or parameter names, bad values or noise levels.
    """
    if device not in DEVICES:
        raise ValueError(f"unknown device {device!r}; devices: {', '.join(DEVICES)}")
    _check_noise(lateral_noise_n, normal_noise_n, drift_n)
    plan = _plan(device, effects)
    uv_ok = plan.uv_model is not None
    recordings = []
    for index, pressure in enumerate(protocol.pressures_pa):
        streams = [np.random.default_rng([seed, index, k]) for k in range(3)]
        s = _schedule(protocol, streams[0])
        n = s.t.size
        amplitude, voltage = _acting_drive(plan, s, protocol.sample_rate_hz)
        total_in = _effect_inputs(plan, s, pressure, amplitude, voltage)
        lateral = _lateral_force(plan, s, total_in, _relative_friction(plan, total_in),
                                 _electrostatic_force(plan, total_in))
        fl, fn_rec = _recorded_forces(s, lateral, protocol.sample_rate_hz, lateral_noise_n,
                                      normal_noise_n, drift_n, streams[1], streams[2])
        recordings.append(
            Measurement(
                t=s.t,
                normal_force=fn_rec,
                lateral_force=fl,
                amplitude=s.amplitude.copy() if uv_ok else None,
                voltage=s.voltage.copy() if plan.ev_model is not None else None,
                x=s.x,
                y=np.full(n, Y_M),
                speed=s.speed,
                conditions={
                    "device": f"hcard reference {device}",
                    "plate_frequency_hz": plan.config.limits.plate_frequency if uv_ok else None,
                    "ambient_pressure_pa": float(pressure),
                    "probe": "simulated finger",
                    "surface": "glass",
                    "notes": f"synthesized by hcard_device.sim.tribometer, seed {seed}",
                },
            )
        )
    return recordings


def _finger(mu0: float, chosen: Mapping[str, Mapping[str, float]]) -> FingerFriction | None:
    """The bare finger's :class:`FingerFriction` for the load-index and occlusion-drift
    effects (None: Coulomb, ``mu_f = mu0``)."""
    if "load-index" not in chosen and "occlusion-drift" not in chosen:
        return None
    params: dict[str, float] = {
        "friction_initial": mu0,
        "friction_occluded": mu0,
        "load_index": 1.0,
        "speed_sensitivity": 0.0,
    }
    if "load-index" in chosen:
        params["load_index"] = chosen["load-index"]["load_index"]
    if "occlusion-drift" in chosen:
        drift = chosen["occlusion-drift"]
        params["friction_occluded"] = mu0 * (1.0 + drift["gain"])
        params["occlusion_time"] = drift["time_constant"]
    return _SimulatedFinger(**params)
