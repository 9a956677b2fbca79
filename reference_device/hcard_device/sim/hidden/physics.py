"""The hidden effects of one simulated device, run in its physics (:class:`HiddenPhysics`).

Where each acts in :meth:`hcard_device.sim.finger.FingerPhysics.respond` (in this order):

1. the finger's history (:mod:`.finger_clock`): occlusion time, strokes since rest, touch-downs;
2. the amplitude under the finger (``actuator-bandwidth``, ``plate-load-damping``) and the
   voltage acting on the skin (``charge-leakage``), from what the plate's sensing piezos and the
   amplifier measure -- the recorded columns stay the measured ones;
3. the friction felt: the UV factor (``ultrasonic-speed``, ``squeeze-film-share``) and the EV
   force (``air-layer``, ``finger-geometry``) around the device's own models;
4. the bare finger's friction coefficient (``load-index``, ``occlusion-drift``,
   ``skin-recovery``);
5. the lateral force sensor (``force-sensor-resonance``), before its noise.

An effect at its neutral values (:attr:`.catalogue.HiddenEffect.neutral`) is not run at all:
the device is then the un-hidden one exactly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from hcard.physics.contracts import FrequencyResponse
from hcard.physics.profile import DeviceProfile
from hcard.quantities import ATMOSPHERE_PA
from hcard.rates import DEFAULT_FRAME_RATE_HZ
from hcard_builtins.physics.electrovibration import AirLayer
from hcard_device.sim.hidden.catalogue import (
    FINGER_LOAD_INDEX,
    HIDDEN_EFFECTS,
    HiddenEffectError,
)
from hcard_device.sim.hidden.filters import FirstOrderLag, SecondOrderSensor
from hcard_device.sim.hidden.finger_clock import FingerClock, FingerHistory
from hcard_device.sim.hidden.pad import flattened_ratio

if TYPE_CHECKING:
    from hcard_device.sim.finger import FingerTruth

REFERENCE_FORCE_N = 1.0
"""Normal force at which the air gap is ``air_gap`` and the load factors are 1, N."""
MIN_FORCE_N = 1e-3
"""The air gap is evaluated at no less than this normal force, N (a finger barely touching)."""
MIN_SPEED_M_S = 1e-3
"""``ultrasonic-speed`` takes the sliding speed as at least this, m/s (a finger at rest on the
plate keeps the reduction of a 1 mm/s slide, not an unbounded one)."""
CLOCKED = ("occlusion-drift", "skin-recovery")
"""Effects that need the finger's history."""


class HiddenPhysics:
    """The hidden effects of one simulated device (package documentation).

    Args:
        profile: the device's own profile (its EV model gives the contact layers).
        effects: resolved effects (:func:`.catalogue.resolve`).
        frame_rate_hz: the device's frame rate, Hz.
        ambient_pressure_pa: the air pressure around the plate, Pa (``squeeze-film-share``).
    """

    def __init__(self, profile: DeviceProfile, effects: Mapping[str, Mapping[str, float]], *,
                 frame_rate_hz: float = DEFAULT_FRAME_RATE_HZ,
                 ambient_pressure_pa: float = ATMOSPHERE_PA) -> None:
        self.effects = {name: dict(values) for name, values in effects.items()}
        self.ambient_pressure_pa = ambient_pressure_pa
        frame_s = 1.0 / frame_rate_hz
        p = {name: values for name, values in self.effects.items()
             if any(values.get(k, v) != v for k, v in HIDDEN_EFFECTS[name].neutral.items())}
        self.active = frozenset(p)
        """The effects that change the device (the others are at their neutral values)."""
        self._clock = FingerClock(frame_s) if self.active & set(CLOCKED) else None
        self._lag = (FirstOrderLag(p["actuator-bandwidth"]["time_constant"], frame_s)
                     if "actuator-bandwidth" in p else None)
        self._damping_n = p.get("plate-load-damping", {}).get("damping_force")
        self._leak = (carrier_gain_ratio(profile, p["charge-leakage"]["time_constant"])
                      if "charge-leakage" in p else None)
        self._sensor = (SecondOrderSensor(p["force-sensor-resonance"]["natural_frequency"],
                                          p["force-sensor-resonance"]["damping_ratio"], frame_s)
                        if "force-sensor-resonance" in p else None)
        self._speed = p.get("ultrasonic-speed")
        self._share = p.get("squeeze-film-share", {}).get("share")
        self._area_index = p.get("finger-geometry", {}).get("area_index")
        self._load_index = p.get("load-index", {}).get("load_index")
        self._occlusion = p.get("occlusion-drift")
        self._recovery = p.get("skin-recovery")
        self._air: AirLayer | None = None
        self._gain = profile.carrier_gain
        if "air-layer" in p:
            ev = profile.ev_model
            if ev is None:
                raise HiddenEffectError("effect air-layer needs an EV channel")
            layers = {q.name: ev[q.name] for q in AirLayer.parameters if q.name in ev.params}
            self._air = AirLayer(**layers)
            self._air_gap = p["air-layer"]["air_gap"]

    def __bool__(self) -> bool:
        return bool(self.active)

    def new_finger(self) -> None:
        """A new finger on the plate: its history starts over (never touched, rested)."""
        if self._clock is not None:
            self._clock.reset()

    # -- per step, with state ---------------------------------------------------------------
    def advance(self, truth: FingerTruth) -> FingerHistory | None:
        """The finger's history at the frames of ``truth`` (None: no effect needs it)."""
        return self._clock.advance(truth) if self._clock is not None else None

    def amplitude(self, sensed_m: np.ndarray, truth: FingerTruth) -> np.ndarray:
        """The amplitude under the finger, m, of the amplitude the sensing piezos report:
        lagging it by ``tau_a`` (``actuator-bandwidth``), damped by the load to
        ``A / (1 + Fn / F_d)`` (``plate-load-damping``)."""
        amplitude = self._lag.run(sensed_m) if self._lag is not None else sensed_m
        if self._damping_n is not None:
            amplitude = amplitude / (1.0 + truth.normal_force_n / self._damping_n)
        return amplitude

    def voltage(self, envelope_v: np.ndarray, history: FingerHistory | None) -> np.ndarray:
        """The voltage envelope the device's model takes for the one acting on the skin, V:
        scaled by the ratio of the finger's carrier gain to the profile's (``charge-leakage``,
        :func:`carrier_gain_ratio`)."""
        if self._leak is None:
            return envelope_v
        return envelope_v * self._leak

    def sensor(self, force_n: np.ndarray) -> np.ndarray:
        """What the lateral force sensor reads of the true force, N."""
        return self._sensor.run(force_n) if self._sensor is not None else force_n

    # -- per frame, without state -----------------------------------------------------------
    def uv(self, uv: np.ndarray, truth: FingerTruth) -> np.ndarray:
        """The UV factor ``mu'`` with the reduction ``1 - mu'`` scaled by ``(U / U_ref)^a``
        (capped at 1; ``ultrasonic-speed``, Fig. 2.21e) and by ``gamma = 1 - s (1 - p / p0)``
        (``squeeze-film-share``, Eq. 2.10)."""
        if self._speed is None and self._share is None:
            return uv
        reduction = 1.0 - uv
        if self._speed is not None:
            speed = np.maximum(truth.speed_m_s, MIN_SPEED_M_S) / self._speed["reference_speed"]
            reduction = np.minimum(reduction * speed ** self._speed["speed_exponent"], 1.0)
        if self._share is not None:
            reduction = reduction * (
                1.0 - self._share * (1.0 - self.ambient_pressure_pa / ATMOSPHERE_PA))
        return 1.0 - reduction

    def ev(self, ev: np.ndarray, voltage_v: np.ndarray, normal_force_n: np.ndarray
           ) -> np.ndarray:
        """The EV factor ``1 + <F_e> / Fn`` of the device's own ``ev`` with the force of
        ``air-layer`` (AirLayer, Eq. 3.17, at the carrier-averaged voltage ``g V / sqrt 2`` and
        the gap ``d_a1 (1 N / Fn)``) in place of the device's law, times the flattened pad's
        ``C(h(Fn)) / C(h_1)`` (``finger-geometry``, Eq. 3.18)."""
        if self._air is None and self._area_index is None:
            return ev
        pressing = normal_force_n > 0
        if self._air is not None:
            gap = self._air_gap * REFERENCE_FORCE_N / np.maximum(normal_force_n, MIN_FORCE_N)
            effective = self._gain * voltage_v / math.sqrt(2.0)
            force = np.asarray(self._air.forward(voltage=effective, air_gap=gap),
                               dtype=np.float64)
        else:
            force = (ev - 1.0) * normal_force_n
        if self._area_index is not None:
            force = force * flattened_ratio(normal_force_n / REFERENCE_FORCE_N, self._area_index)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(pressing, 1.0 + force / normal_force_n, 1.0)

    def finger_factor(self, truth: FingerTruth, history: FingerHistory | None
                      ) -> np.ndarray | None:
        """The bare finger's friction coefficient relative to the device's own (None: 1):
        ``(Fn / 1 N)^(n - n_0)`` (``load-index``: ``F = k Fn^n``, Eqs. 1.7/2.35, ``n_0`` the
        device finger's), ``1 + g (1 - exp(-t / tau))`` (``occlusion-drift``, Fig. 1.11,
        ``t`` the occlusion time) and ``1 - D exp(-k / k_r)`` (``skin-recovery``, Figs.
        2.25-2.26, ``k`` the strokes since rest)."""
        factor: np.ndarray | None = None

        def times(value: np.ndarray) -> None:
            nonlocal factor
            factor = value if factor is None else factor * value

        if self._load_index is not None:
            force = np.maximum(truth.normal_force_n / REFERENCE_FORCE_N, MIN_FORCE_N)
            times(force ** (self._load_index - FINGER_LOAD_INDEX))
        if self._occlusion is not None:
            assert history is not None
            times(1.0 + self._occlusion["gain"] * -np.expm1(
                -history.occlusion_time_s / self._occlusion["time_constant"]))
        if self._recovery is not None:
            assert history is not None
            times(1.0 - self._recovery["depth"] * np.exp(
                -history.stroke / self._recovery["strokes"]))
        return factor


def carrier_gain_ratio(profile: DeviceProfile, tau_d_s: float) -> float:
    """``|H(f_c)|`` of Eq. 3.22 for a finger whose leakage time constant at 10 Hz is
    ``tau_d_s`` (s) over the profile's own carrier gain: the device's leakage model (Eqs.
    3.19-3.23, ``tau_d`` falling with frequency as Fig. 3.13) with the finger's ``tau_d``, at
    the carrier frequency ``f_c``. The carrier (440 Hz on the coupled stimulator) is far
    faster than any envelope change, so the leak acts as this gain on the envelope; the
    transient at a touch-down or an envelope step is of relative size ``1/(omega tau)``
    squared in the force, under 0.5 % here, and left out."""
    leakage, limits = profile.leakage, profile.limits
    if not isinstance(leakage, FrequencyResponse) or limits is None:
        raise HiddenEffectError("effect charge-leakage needs a device with an EV carrier and "
                                "a leakage model with a frequency response")
    finger = leakage.with_params(tau_d=tau_d_s)
    assert isinstance(finger, FrequencyResponse)
    gain = float(np.abs(np.asarray(finger.frequency_response(
        np.asarray([limits.carrier_frequency])))).ravel()[0])
    return gain / profile.carrier_gain
