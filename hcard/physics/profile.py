"""Device profiles: a fitted predictor, its effects and the limits of one device.

A device profile is to friction what an ICC profile is to colour: it maps the device-independent
target of a card (relative friction per channel, ``Frames.uv`` in [0, 1] and ``Frames.ev`` in
[1, 4]) to the actuator commands of one device, and the commands back to the friction they
render. It bundles

- a predictor with its parameters: the coupled model of Eq. 4.1 (``"coupled"``: UV and EV),
  a UV relative-friction model whose inverse gives the plate amplitude (``inverse_input ==
  "amplitude"``, for example ``"dimensionless-group"``), or an EV force model whose inverse
  gives the voltage (output in N, ``inverse_input == "voltage"``, e.g. ``"ev-kaczmarek"``);
- optionally a charge-leakage model (Eqs. 3.19-3.23) whose gain at the EV carrier frequency
  scales the voltage that acts on the finger;
- the device limits (:class:`~hcard.physics.device_limits.DeviceLimits`);
- the effects a calibration added (``hcard calibrate`` writes device profiles), each on the UV
  channel, the EV channel or the bare finger (:mod:`hcard.physics.profile_effects`), with what
  the profile was fitted on.

This module holds the profile's physics: its channels, the forward map and the inverses.
Profiles are JSON files (format ``hcard-device-profile/2``, spec/device-profile.md) that
:mod:`hcard.physics.profile_format` reads and writes; :mod:`hcard.physics.actuation` renders
with a profile (target friction to clipped actuator commands).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hcard.errors import HcardError
from hcard.physics.contracts import FrequencyResponse, TwoChannelModel
from hcard.physics.device_limits import (
    COUPLED_STIMULATOR_LIMITS,
    DeviceLimits,
    binding_voltage_limit,
    layer_capacitance,
)
from hcard.physics.predictor import Predictor, PredictorError
from hcard.physics.profile_effects import FittedEffect, solve_decreasing, with_effects
from hcard.physics.profile_error import ProfileError
from hcard.physics.profile_format import (
    document_json,
    parse_profile_json,
    profile_document,
    profile_fields,
    read_json,
    write_profile_file,
)

if TYPE_CHECKING:
    from hcard.plugins.registry import PluginRegistry

AMPLITUDE_SEARCH_FACTOR = 8.0
"""The numerical UV inverse searches amplitudes up to this many times the amplitude limit
(the raw command is then clipped to the limit and the shortfall reported)."""

REFERENCE_VOLTAGE = 1000.0
"""Envelope at which the EV channel's force is evaluated to scale the inverse, V."""

QUADRATIC_TOLERANCE = 1e-6
"""Relative tolerance of the check that an EV force model goes as ``v^2``."""


@dataclass(frozen=True)
class DeviceProfile:
    """A predictor with fitted parameters, the effects a calibration added, and the limits of
    one device (spec/device-profile.md).

    Attributes:
        predictor: the base model: ``coupled`` (UV and EV), a UV relative-friction model with an
            amplitude inverse, an EV force model (N) with a voltage inverse, or (for a profile
            that describes a model but cannot render, e.g. a calibration of the bare finger)
            any predictor.
        limits: the device limits (None: not known; the profile then cannot render).
        leakage: optional charge-leakage model (Eqs. 3.19-3.23), a
            :class:`~hcard.physics.contracts.FrequencyResponse`: its gain at the carrier
            frequency scales the EV voltage that acts on the finger.
        name: a short identifier of the device.
        description: one line.
        effects: the effects a calibration added, in the order added
            (:class:`~hcard.physics.profile_effects.FittedEffect`); each acts on the UV channel,
            the EV channel or the bare finger (:func:`~hcard.physics.profile_effects.channel_of`).
        observation: how the model was compared with a force sensor (``output``: ``"lateral_force"``
            or ``"output"``; ``parameters``: the fitted ``friction_coefficient`` and
            ``force_offset`` with units and uncertainties), or None.
        calibration: what the profile was fitted on and how well (recordings, their conditions,
            held-out errors, verdict, rendering errors), free-form JSON, or None.
    """

    predictor: Predictor
    limits: DeviceLimits | None
    leakage: Predictor | None = None
    name: str = "device"
    description: str = ""
    effects: tuple[FittedEffect, ...] = ()
    observation: Mapping[str, Any] | None = None
    calibration: Mapping[str, Any] | None = None
    _uv: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _ev: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _uv_channel: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _ev_channel: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _carrier_gain: float = field(default=1.0, init=False, repr=False, compare=False)
    _capacitance: float | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.predictor, Predictor):
            raise ProfileError(f"predictor: expected a Predictor, got {type(self.predictor)}")
        if self.limits is not None and not isinstance(self.limits, DeviceLimits):
            raise ProfileError(f"limits: expected DeviceLimits, got {type(self.limits)}")
        object.__setattr__(self, "effects", tuple(self.effects))
        for index, fitted in enumerate(self.effects):
            if not isinstance(fitted, FittedEffect):
                raise ProfileError(f"effects[{index}]: expected a FittedEffect")
        names = [fitted.name for fitted in self.effects]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ProfileError(f"effects: {', '.join(repeated)} appear(s) twice")
        uv, ev = channels_of(self.predictor)
        if uv is None and ev is None and self.limits is not None:
            raise ProfileError(
                f"predictor: model {self.predictor.name!r} can render neither channel; a profile "
                "with limits needs a UV relative-friction model with an amplitude inverse, an EV "
                "force model (N) with a voltage inverse, or 'coupled'"
            )
        uv_channel = self._channel_with_effects("uv", uv)
        ev_channel = self._channel_with_effects("ev", ev)
        if ev is not None and self.limits is not None:
            frequency = self.limits.carrier_frequency
            _check_quadratic(ev_channel or ev, frequency)
            if self.leakage is not None and "frequency" in {v.name for v in ev.inputs}:
                raise ProfileError(
                    f"leakage: the EV model {ev.name!r} already depends on the carrier "
                    "frequency; a separate leakage model would count the leak twice"
                )
        if self.leakage is not None and not isinstance(self.leakage, FrequencyResponse):
            raise ProfileError(
                f"leakage: model {self.leakage.name!r} has no frequency_response(f) method"
            )
        capacitance = self._derive_capacitance(ev)
        if ev is not None and self.limits is not None and capacitance is None:
            raise ProfileError(
                f"limits.load_capacitance: missing, and the EV model {ev.name!r} has no "
                "area and layers to derive it from (Eq. 3.8); give it in F so that "
                "max_current can be enforced"
            )
        # Frozen dataclass: the derived values are set once, here.
        object.__setattr__(self, "_uv", uv)
        object.__setattr__(self, "_ev", ev)
        object.__setattr__(self, "_uv_channel", uv_channel)
        object.__setattr__(self, "_ev_channel", ev_channel)
        object.__setattr__(self, "_carrier_gain", self._leakage_gain())
        object.__setattr__(self, "_capacitance", capacitance)

    def _channel_with_effects(self, channel: str, model: Predictor | None) -> Predictor | None:
        """The channel's model with the profile's effects on it; refuses effects on a channel
        the predictor does not render."""
        mine = self.effects_on(channel)
        if not mine:
            return model
        if model is None:
            raise ProfileError(
                f"effects: {', '.join(f.name for f in mine)} act(s) on the {channel.upper()} "
                f"channel, which model {self.predictor.name!r} does not render"
            )
        try:
            return with_effects(model, mine)
        except PredictorError as exc:
            raise ProfileError(f"effects: {exc}") from None

    def effects_on(self, channel: str) -> tuple[FittedEffect, ...]:
        """The effects acting on ``channel`` (``"uv"``, ``"ev"`` or ``"finger"``), in order."""
        if not self.effects:
            return ()
        return tuple(fitted for fitted in self.effects if fitted.channel == channel)

    def replace(self, **changes: Any) -> DeviceProfile:
        """A copy with some fields changed (``limits``, ``effects``, ``name``, ...)."""
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        return DeviceProfile(**{**values, **changes})

    # -- channels --------------------------------------------------------------------------
    @property
    def uv_model(self) -> Predictor | None:
        """The base relative-friction model of the UV channel (``None``: no UV channel)."""
        return self._uv

    @property
    def ev_model(self) -> Predictor | None:
        """The base electrostatic-force model of the EV channel, N (``None``: no EV channel)."""
        return self._ev

    @property
    def uv_channel(self) -> Predictor | None:
        """The UV channel's model with the profile's UV effects (the base without any)."""
        return self._uv_channel

    @property
    def ev_channel(self) -> Predictor | None:
        """The EV channel's model with the profile's EV effects (the base without any)."""
        return self._ev_channel

    @property
    def carrier_gain(self) -> float:
        """Voltage gain ``|v_e / v|`` at the carrier frequency (Eq. 3.22); 1 without leakage."""
        return self._carrier_gain

    @property
    def load_capacitance(self) -> float | None:
        """Capacitance the EV amplifier drives, F (given in the limits, or from Eq. 3.8)."""
        return self._capacitance

    def rendering_limits(self) -> DeviceLimits:
        """The limits, or :class:`ProfileError` for a profile without them (it cannot render)."""
        if self.limits is None:
            raise ProfileError(
                f"profile {self.name!r} has no limits (it was fitted without a device's "
                "conditions), so it cannot render; give it the device's limits"
            )
        return self.limits

    @property
    def voltage_limit(self) -> tuple[float, str]:
        """The binding peak-voltage limit, V, and its name (``max_voltage`` or ``max_current``).

        ``max_current`` binds when a sinusoidal carrier of peak ``V`` at ``carrier_frequency``
        into :attr:`load_capacitance` would draw more than ``max_current`` (``I = 2 pi f C V``,
        the envelope taken as slow against the carrier).
        """
        cached = self.__dict__.get("_voltage_limit")  # frozen: worked out once
        if cached is not None:
            return cached
        cached = self.__dict__["_voltage_limit"] = self._binding_voltage_limit()
        return cached

    def _binding_voltage_limit(self) -> tuple[float, str]:
        """:attr:`voltage_limit`, worked out."""
        return binding_voltage_limit(self.rendering_limits(), self.load_capacitance)

    def _leakage_gain(self) -> float:
        if not isinstance(self.leakage, FrequencyResponse) or self.limits is None:
            return 1.0  # no leakage (__post_init__ refuses a leakage model without a response)
        frequency = self.limits.carrier_frequency
        try:
            # __post_init__ checked that the leakage model has frequency_response (Eq. 3.22)
            response = np.asarray(self.leakage.frequency_response(
                np.asarray([frequency])))
        except HcardError as exc:
            raise ProfileError(f"leakage: {exc}") from None
        gain = float(np.abs(response).ravel()[0])
        if not math.isfinite(gain) or gain <= 0:
            raise ProfileError(
                f"leakage: gain at the carrier frequency {frequency:g} Hz is {gain:g}; "
                "the EV channel cannot act"
            )
        return gain

    def _derive_capacitance(self, ev: Predictor | None) -> float | None:
        """The limits' load capacitance, else Eq. 3.8 from the EV model's layer parameters
        (:func:`~hcard.physics.device_limits.layer_capacitance`), else None (the current limit
        cannot be checked)."""
        if self.limits is not None and self.limits.load_capacitance is not None:
            return self.limits.load_capacitance
        if ev is None:
            return None
        return layer_capacitance(ev.params)

    # -- forward and rendering -------------------------------------------------------------
    def forward(
        self,
        amplitude: Any,
        voltage: Any,
        speed: Any,
        normal_force: Any,
        *,
        trusted: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Relative friction per channel rendered by actuator commands (Eq. 4.1 factors).

        Args:
            amplitude: peak-to-peak plate amplitude, m.
            voltage: peak EV voltage envelope of the sinusoidal carrier, V.
            speed: finger speed, m/s.
            normal_force: finger normal force, N (> 0 where EV acts).
            trusted: the caller has checked the inputs: float64 arrays of one shape, finite
                and >= 0. The channels' models then skip their own input checks
                (:meth:`~hcard.physics.predictor.Predictor.forward_trusted`); the numbers are
                the same.

        Returns:
            ``(uv, ev)``: ``uv = mu(w)/mu0`` from the UV channel at the plate frequency, and
            ``ev = 1 + <F_e>/F_n`` with ``<F_e>`` the carrier average of the EV force, which for
            a force going as ``v^2`` is ``F_e(g V / sqrt 2)`` (mean of ``sin^2`` = 1/2, ``g``
            the leakage gain at the carrier). ``ev = 1`` where ``F_n = 0``. Their product is
            the total relative friction ``F_t / (mu0 F_n)``. Each channel includes the
            profile's effects on it in their steady state (effects on the bare finger scale
            the friction with and without modulation alike, so they are not in these ratios).
        """
        if not trusted:
            amplitude, voltage, speed, normal_force = np.broadcast_arrays(
                *(np.asarray(a, dtype=np.float64)
                  for a in (amplitude, voltage, speed, normal_force))
            )
        shape = amplitude.shape if trusted else np.shape(amplitude)
        if self._uv_channel is not None:
            uv = self._uv_value(amplitude, speed, normal_force, trusted)
            if (uv.shape if isinstance(uv, np.ndarray) else np.shape(uv)) != shape:
                uv = np.broadcast_to(uv, shape)
        else:
            uv = np.ones(shape)
        if self._ev_channel is not None:
            force = self._force(voltage, normal_force, trusted)
            # 1 + F_e / F_n where F_n > 0, else 1 (no division where F_n = 0)
            if normal_force.size and np.minimum.reduce(normal_force, axis=None) > 0:
                ratio = np.divide(force, normal_force, out=np.empty(shape))  # F_n > 0 everywhere
            else:
                ratio = np.zeros(shape)
                np.divide(force, normal_force, out=ratio, where=normal_force > 0)
            ev = np.add(1.0, ratio, out=ratio)
        else:
            ev = np.ones(shape)
        if not (trusted and _owned(uv, shape)):
            uv = np.array(uv, dtype=np.float64)  # the model's output may be a view or an input
        return uv, ev

    def _uv_call(self, speed: Any, normal_force: Any) -> tuple[Predictor, dict[str, Any]]:
        """The UV channel's model and its inputs: finger state and the plate frequency (those
        it takes)."""
        model, given, takes_speed, takes_force = self._channel_call("uv")
        given = dict(given)
        if takes_speed:
            given["speed"] = speed
        if takes_force:
            given["normal_force"] = normal_force
        return model, given

    def _channel(self, channel: str) -> Predictor:
        model = self._uv_channel if channel == "uv" else self._ev_channel
        if model is None:
            raise ProfileError(f"profile {self.name!r} has no {channel.upper()} channel")
        return model

    def _channel_call(self, channel: str) -> tuple[Predictor, dict[str, float], bool, bool]:
        """The channel's model, its fixed inputs (the plate frequency for UV, the carrier
        frequency for EV, when it takes ``frequency``), and whether it takes ``speed`` and
        ``normal_force``; worked out once per model (the profile is immutable)."""
        model = self._uv_channel if channel == "uv" else self._ev_channel
        cache = self.__dict__.get("_channel_calls")  # frozen: not a field
        if cache is None:
            cache = self.__dict__["_channel_calls"] = {}
        cached = cache.get(channel)
        if cached is None or cached[0] is not model:
            model = self._channel(channel)  # ProfileError without the channel
            names = {v.name for v in model.inputs}
            fixed: dict[str, float] = {}
            if "frequency" in names:
                if channel == "ev":
                    fixed["frequency"] = self.rendering_limits().carrier_frequency
                elif self.limits is not None:
                    fixed["frequency"] = self.limits.plate_frequency
            cached = cache[channel] = (model, fixed, "speed" in names, "normal_force" in names)
        return cached

    def uv_for(self, amplitude: Any, speed: Any, normal_force: Any) -> np.ndarray:
        """UV relative friction ``mu(w)/mu0`` for peak-to-peak amplitude ``w`` (m) at the
        plate frequency, finger speed (m/s) and normal force (N)."""
        return self._uv_value(amplitude, speed, normal_force, False)

    def _uv_value(self, amplitude: Any, speed: Any, normal_force: Any,
                  trusted: bool) -> np.ndarray:
        """:meth:`uv_for`; ``trusted``: inputs checked by the caller (see :meth:`forward`)."""
        model, inputs = self._uv_call(speed, normal_force)
        if trusted:
            return model.forward_trusted(amplitude=amplitude, **inputs)
        return model.forward(amplitude=amplitude, **inputs)

    def amplitude_for(self, uv: Any, speed: Any, normal_force: Any, *,
                      trusted: bool = False) -> np.ndarray:
        """Peak-to-peak plate amplitude (m) giving UV relative friction ``uv`` at the finger
        speed (m/s) and normal force (N): the UV model's inverse, not clipped. With effects on
        the UV channel the forward map is inverted numerically (it falls with the amplitude)
        over ``[0, AMPLITUDE_SEARCH_FACTOR * max_amplitude]``.

        ``trusted``: the caller has checked the inputs (float64 arrays of one shape, ``uv`` in
        (0, 1], speed and force finite and >= 0): the model's inverse skips its input checks
        (:meth:`~hcard.physics.predictor.Predictor.inverse_trusted`); same numbers."""
        if not self.effects_on("uv"):
            model, inputs = self._uv_call(speed, normal_force)
            if trusted:
                return model.inverse_trusted(uv, **inputs)
            return model.inverse(uv, **inputs)
        target, speed_a, force_a = np.broadcast_arrays(
            *(np.asarray(a, dtype=np.float64) for a in (uv, speed, normal_force))
        )
        high = AMPLITUDE_SEARCH_FACTOR * self.rendering_limits().max_amplitude
        return solve_decreasing(lambda w: self.uv_for(w, speed_a, force_a), target, high)

    def _ev_call(self, normal_force: Any) -> tuple[Predictor, dict[str, Any]]:
        """The EV channel's model and its extra inputs: the carrier frequency when it takes
        ``frequency``, the normal force when an effect needs it (the dict is shared: do not
        modify it)."""
        model, given, _, takes_force = self._channel_call("ev")
        if takes_force and normal_force is not None:
            given = {**given, "normal_force": normal_force}
        return model, given

    def force_for(self, voltage: Any, normal_force: Any = None) -> np.ndarray:
        """Carrier-averaged EV force, N, for a peak envelope ``voltage`` (V) on a finger
        pressing with ``normal_force`` (N; used by effects that depend on it).

        ``<F(g V sin)> = F(g V / sqrt 2)`` for a force going as ``v^2`` (mean of ``sin^2`` is
        1/2; ``g`` the leakage gain at the carrier, Eq. 3.22).
        """
        return self._force(voltage, normal_force, False)

    def _force(self, voltage: Any, normal_force: Any, trusted: bool) -> np.ndarray:
        """:meth:`force_for`; ``trusted``: inputs checked by the caller (see :meth:`forward`)."""
        model, inputs = self._ev_call(normal_force)
        effective = self._carrier_gain * np.asarray(voltage, dtype=np.float64) / math.sqrt(2.0)
        if trusted:
            return np.asarray(model.forward_trusted(voltage=effective, **inputs),
                              dtype=np.float64)
        return np.asarray(model.forward(voltage=effective, **inputs), dtype=np.float64)

    def voltage_for(self, force: Any, normal_force: Any = None, *,
                    trusted: bool = False) -> np.ndarray:
        """Peak envelope voltage, V, whose carrier-averaged EV force is ``force`` (N): the
        inverse of :meth:`force_for`, not clipped. With effects on the EV channel the force
        still goes as ``v^2`` (checked when the profile is built), so the voltage is that of a
        reference force scaled by ``sqrt(force / F(V_ref))``.

        ``trusted``: the caller has checked the inputs (float64 arrays of one shape, finite
        and >= 0): the model's inverse skips its input checks; same numbers."""
        if not self.effects_on("ev"):
            model, inputs = self._ev_call(None)
            solved = model.inverse_trusted(force, **inputs) if trusted \
                else model.inverse(force, **inputs)
            effective = np.asarray(solved, dtype=np.float64)
            return effective * math.sqrt(2.0) / self.carrier_gain
        force_a = np.asarray(force, dtype=np.float64)
        reference = self.force_for(np.full(force_a.shape, REFERENCE_VOLTAGE), normal_force)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(reference > 0, np.maximum(force_a, 0.0) / reference, np.inf)
        return REFERENCE_VOLTAGE * np.sqrt(ratio)

    # -- files (the format: hcard.physics.profile_format) -------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready profile (format ``hcard-device-profile/2``, spec/device-profile.md)."""
        return profile_document(
            name=self.name,
            description=self.description,
            predictor=self.predictor,
            leakage=self.leakage,
            limits=self.limits,
            effects=self.effects,
            observation=self.observation,
            calibration=self.calibration,
        )

    def to_json(self) -> bytes:
        """:meth:`to_dict` as UTF-8 JSON text (indented, finite numbers only)."""
        return document_json(self.to_dict(), self.name)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the profile as JSON, atomically (readers see the old file or the new one)."""
        write_profile_file(path, self.to_json())

    @classmethod
    def from_dict(
        cls,
        raw: Any,
        *,
        source: str = "profile",
        registry: PluginRegistry | None = None,
    ) -> DeviceProfile:
        """A profile from its JSON object; errors name ``source`` and the field."""
        values = profile_fields(raw, source=source, registry=registry)
        try:
            return cls(**values)
        except ProfileError as exc:
            raise ProfileError(f"{source}: {exc}") from None

    @classmethod
    def from_json(
        cls, data: bytes, *, source: str = "profile", registry: PluginRegistry | None = None
    ) -> DeviceProfile:
        """A profile from the bytes of a profile file (UTF-8 JSON)."""
        return cls.from_dict(parse_profile_json(data, source=source), source=source,
                             registry=registry)

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], *, registry: PluginRegistry | None = None
    ) -> DeviceProfile:
        """Read a profile file written by :meth:`save` (or by hand)."""
        file = Path(path)
        return cls.from_dict(read_json(file), source=str(file), registry=registry)

    @classmethod
    def coupled_stimulator(
        cls,
        *,
        leakage: Predictor | None = None,
        registry: PluginRegistry | None = None,
        **changes: float,
    ) -> DeviceProfile:
        """The chapter-4 coupled stimulator (:data:`COUPLED_STIMULATOR_LIMITS`) with the
        default ``coupled`` predictor; ``changes`` replace limits (for example
        ``max_amplitude=5e-6``)."""
        if registry is None:
            from hcard.plugins.registry import get_registry

            registry = get_registry()
        try:
            predictor = registry.get("predictor", "coupled")
        except HcardError as exc:
            raise ProfileError(f"coupled stimulator: {exc}") from None
        values = {f.name: getattr(COUPLED_STIMULATOR_LIMITS, f.name) for f in fields(DeviceLimits)}
        unknown = sorted(set(changes) - set(values))
        if unknown:
            raise ProfileError(f"limits.{unknown[0]}: unknown field")
        return cls(
            predictor=predictor,
            limits=DeviceLimits(**{**values, **changes}),
            leakage=leakage,
            name="coupled-stimulator",
            description="UV+EV coupled stimulator of thesis chapter 4",
        )


def _owned(values: Any, shape: tuple[int, ...]) -> bool:
    """``values`` is a float64 array of ``shape`` that owns its memory (a model's new result,
    not a view of an input): the caller may have it without a copy."""
    return (
        type(values) is np.ndarray and values.dtype == np.float64 and values.shape == shape
        and values.base is None and values.flags.writeable
    )


def channels_of(predictor: Predictor) -> tuple[Predictor | None, Predictor | None]:
    """(UV relative-friction model, EV force model) rendered by ``predictor``: the parts of a
    :class:`~hcard.physics.contracts.TwoChannelModel`, else the predictor itself on the channel
    its output and inverse fit."""
    if isinstance(predictor, TwoChannelModel) and isinstance(predictor.uv, Predictor) and (
        isinstance(predictor.ev, Predictor)
    ):
        uv, ev = predictor.uv, predictor.ev
        return (
            uv if uv.inverse_input == "amplitude" else None,
            ev if ev.inverse_input == "voltage" else None,
        )
    if predictor.inverse_input == "amplitude" and predictor.output.unit == "":
        return predictor, None
    if predictor.inverse_input == "voltage" and predictor.output.unit == "N":
        return None, predictor
    return None, None


def _check_quadratic(ev: Predictor, carrier_frequency: float) -> None:
    """:class:`ProfileError` unless ``F(2 v) = 4 F(v)``: the carrier average (mean of sin^2 =
    1/2) and its inverse assume the ``v^2`` law of Eqs. 3.3, 3.12, 3.17, 3.18 and 3.23."""
    extra = {"frequency": carrier_frequency} if "frequency" in {v.name for v in ev.inputs} else {}
    try:
        low, high = ev.forward(voltage=np.asarray([500.0, 1000.0]), **extra)
    except HcardError as exc:
        raise ProfileError(f"predictor: EV model {ev.name!r} cannot be used alone: {exc}") from None
    if not (low > 0 and abs(high / low - 4.0) <= 4.0 * QUADRATIC_TOLERANCE):
        raise ProfileError(
            f"predictor: EV model {ev.name!r} does not go as v^2 "
            f"(F(1000 V) / F(500 V) = {high / low if low else math.nan:g}, expected 4)"
        )
