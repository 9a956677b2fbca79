"""The device profiles ``device.profile-upload`` uploads (spec/device-profile.md), and how it
reads which profile a device renders with (spec/conformance.md 4.10, U4).

A profile maps target relative friction to plate amplitude (m) and EV voltage (V) at the
finger's speed (m/s) and normal force (N). Which one a device renders with shows in what it
renders: the measured amplitude and voltage of its STATE reports, mapped back to relative
friction through a profile's forward map (:func:`friction_error`), give the card's target
through the profile in force and miss it through another. For that the check needs a profile
the device's own cannot pass for (:func:`distinct_profile`): its published profile with one
parameter of the model scaled, such that rendering with either misses the other's friction by
:data:`SEPARATION` times the threshold. It also uploads a profile whose models do not render
the device's channels (:func:`wrong_channels`, PU9) and one whose ``limits`` are above the
device's hardware limits (:func:`raised_limits`, PU10).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hcard.device.protocol import (
    AMPLITUDE_UNIT_M,
    CURRENT_UNIT_A,
    VOLTAGE_UNIT_V,
    Capability,
    DeviceInfo,
    State,
)
from hcard.errors import HcardError
from hcard.physics.actuation import actuate
from hcard.physics.profile import DeviceProfile, channels_of
from hcard.quantities import M_PER_MM
from hcard_conformance.check_names import DEVICE_PROFILE_UPLOAD as CHECK
from hcard_conformance.device_checks.host_finger import FINGER_FORCE_N
from hcard_conformance.device_checks.link_session import FINGER_SPEED_MM_S
from hcard_conformance.result import CannotAssess

FINGER_SPEED_M_S = FINGER_SPEED_MM_S * M_PER_MM
"""Speed of the host's finger circling on the surface (the link session's), m/s: the speed
every profile is evaluated at."""
PARAMETER_FACTORS = (0.5, 2.0)
"""Factors tried on each parameter of the published profile's model, in order
(:func:`distinct_profile`)."""
SEPARATION = 2.0
"""The friction each profile predicts from the other's commands must miss the target by at
least this many times the threshold: a device rendering with the wrong profile then fails by
as much as the threshold again."""
RAISED_FACTOR = 2.0
"""The ``limits`` of :func:`raised_limits` are this many times the device's hardware limits
(DEVICE_INFO)."""


@dataclass(frozen=True)
class DistinctProfile:
    """A profile the check puts in force, and how far it is from the device's own.

    Attributes:
        profile: the device's published profile with one model parameter scaled.
        parameter: the parameter's name.
        factor: the factor applied to it.
        own_through_it: relative error of the friction ``profile`` predicts from the commands
            the own profile gives for the target.
        it_through_own: relative error of the friction the own profile predicts from the
            commands ``profile`` gives for it.
    """

    profile: DeviceProfile
    parameter: str
    factor: float
    own_through_it: float
    it_through_own: float

    @property
    def data(self) -> bytes:
        """The profile's bytes as uploaded (UTF-8 JSON, spec/device-profile.md)."""
        return self.profile.to_json()


def commands_for(profile: DeviceProfile, target: float, uv: bool) -> tuple[float, float, bool]:
    """(amplitude m, voltage V, clipped) ``profile`` commands for ``target`` on the UV channel
    (``uv``) or the EV channel, for the host's finger (:data:`FINGER_SPEED_M_S`,
    ``FINGER_FORCE_N``)."""
    commands = actuate(profile, [target if uv else 1.0], [1.0 if uv else target],
                       FINGER_SPEED_M_S, FINGER_FORCE_N)
    clipped = bool(commands.uv_clipped.any() or commands.ev_clipped.any())
    return float(commands.amplitude[0]), float(commands.voltage[0]), clipped


def predicted(profile: DeviceProfile, amplitude: float, voltage: float) -> float:
    """Relative friction ``profile`` predicts for ``amplitude`` (m) and ``voltage`` (V) under
    the host's finger."""
    uv, ev = profile.forward(amplitude, voltage, FINGER_SPEED_M_S, FINGER_FORCE_N)
    return float(uv * ev)


def distinct_profile(own: DeviceProfile, info: DeviceInfo, target: float,
                     threshold: float) -> DistinctProfile:
    """``own`` with the first parameter of its model (in the model's order) scaled by the first
    of :data:`PARAMETER_FACTORS` within the parameter's bounds such that, for ``target`` under
    the host's finger: the commands each profile gives are not clipped, and the friction each
    predicts from the other's commands misses ``target`` by at least :data:`SEPARATION` x
    ``threshold`` (relative). A device with UV renders ``target`` by UV, one without by EV.

    Raises:
        CannotAssess: the own profile clips ``target``, or no parameter and factor does.
    """
    uv = bool(info.capabilities & Capability.UV)
    a_own, v_own, clipped = commands_for(own, target, uv)
    if clipped:
        raise CannotAssess(f"the device's own profile clips the target {target:g} at "
                           f"{FINGER_SPEED_MM_S:g} mm/s")
    model = own.predictor
    for parameter in model.parameters:
        value = model.params[parameter.name]
        low, high = parameter.bounds
        for factor in PARAMETER_FACTORS:
            scaled = value * factor
            if scaled == value or not low <= scaled <= high:
                continue
            try:
                candidate = own.replace(
                    predictor=model.with_params(**{parameter.name: scaled}),
                    name=f"{own.name} ({parameter.name} x {factor:g})",
                    description=f"conformance check {CHECK}: {own.name}'s profile with "
                                f"{parameter.name} x {factor:g}")
                a_it, v_it, clipped = commands_for(candidate, target, uv)
            except (HcardError, ValueError):  # a model that refuses the value
                continue
            if clipped:
                continue
            own_through_it = abs(predicted(candidate, a_own, v_own) - target) / target
            it_through_own = abs(predicted(own, a_it, v_it) - target) / target
            if min(own_through_it, it_through_own) >= SEPARATION * threshold:
                return DistinctProfile(candidate, parameter.name, factor, own_through_it,
                                       it_through_own)
    raise CannotAssess(f"no parameter of the model {model.name!r} of the device's profile, "
                       f"scaled by {' or '.join(f'{f:g}' for f in PARAMETER_FACTORS)}, moves "
                       f"the target {target:g} by {SEPARATION:g} x {threshold:g} without "
                       "clipping: no profile of the check's can be told from the device's")


def wrong_channels(info: DeviceInfo) -> DeviceProfile:
    """A valid device profile whose models do not render exactly the channels of the device
    ``info`` describes (protocol PU9: INVALID_PROFILE): on a device with EV, the coupled
    stimulator's UV channel alone (no EV); on one without, the whole coupled stimulator (an EV
    channel the device lacks)."""
    coupled = DeviceProfile.coupled_stimulator()
    if not info.capabilities & Capability.EV:
        return coupled
    uv, _ev = channels_of(coupled.predictor)
    assert uv is not None  # the coupled model has both channels
    return DeviceProfile(predictor=uv, limits=coupled.limits, name="UV channel alone",
                         description=f"conformance check {CHECK}: no EV channel")


def raised_limits(own: DeviceProfile, info: DeviceInfo) -> DeviceProfile:
    """``own`` with its ``limits`` at :data:`RAISED_FACTOR` x the device's hardware limits
    (DEVICE_INFO; the current at least ``own``'s, a profile's being > 0): a profile that asks
    for more than the device may do (protocol PU10)."""
    assert own.limits is not None  # a published profile renders, so it has limits
    limits = dataclasses.replace(
        own.limits,
        max_amplitude=RAISED_FACTOR * info.max_amplitude_nm * AMPLITUDE_UNIT_M,
        max_voltage=RAISED_FACTOR * info.max_voltage_dv * VOLTAGE_UNIT_V,
        max_current=RAISED_FACTOR * max(info.max_current_10na * CURRENT_UNIT_A,
                                        own.limits.max_current))
    return own.replace(limits=limits, name=f"{own.name} (limits x {RAISED_FACTOR:g})")


def friction_error(states: Sequence[State], profile: DeviceProfile, target: float,
                   info: DeviceInfo) -> float:
    """RMS relative error against ``target`` of the friction ``profile`` maps the measured
    amplitude and voltage of ``states`` to, at :data:`FINGER_SPEED_M_S` and the measured normal
    force (``FINGER_FORCE_N`` on a device without CORNER_FORCES); NaN without reports."""
    if not states:
        return math.nan
    amplitude = np.array([s.amplitude_m for s in states])
    voltage = np.array([s.voltage_v for s in states])
    if info.capabilities & Capability.CORNER_FORCES:
        normal = np.maximum(np.array([s.normal_force_n for s in states]), 1e-3)
    else:
        normal = np.full(len(states), FINGER_FORCE_N)
    uv, ev = profile.forward(amplitude, voltage, np.full(len(states), FINGER_SPEED_M_S), normal)
    error = (uv * ev - target) / target
    return float(np.sqrt(np.mean(error**2)))
