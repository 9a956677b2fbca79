"""A device profile as a model to fit: the total relative friction its channels render.

A recording made through a device (``hcard play``) carries the measured plate amplitude and EV
voltage envelope, and the device's own profile is the model that says what friction they render
(spec/device-profile.md). :func:`profile_model` turns a
:class:`~hcard.physics.profile.DeviceProfile` into a :class:`~hcard.physics.Predictor` that the
calibration loop fits like any other:

- output: the total relative friction ``uv * ev`` (Eq. 4.1), ``uv`` from the UV channel at the
  measured amplitude, plate frequency, speed and normal force, ``ev = 1 + <F_e> / F_n`` with
  ``<F_e>`` the EV channel's force at the carrier-averaged voltage ``g V / sqrt 2`` (for an
  envelope recording; the instantaneous voltage otherwise);
- parameters: the profile predictor's (same names: ``psi_star`` or ``uv_psi_star``, ``ev_area``,
  ...), and each added effect's (``"<effect>.<parameter>"``);
- effects: each one goes where it acts (:func:`hcard.physics.profile_effects.channel_of`): on the
  UV channel, on the EV channel, or, for the bare finger's effects, on the total friction, so a
  fitted model is exactly a device profile with effects (:func:`fitted_profile`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from hcard.calibration import forward_cache
from hcard.physics import Parameter, Predictor, PredictorError, Variable
from hcard.physics.effects import SEPARATOR, Effect, EffectHost
from hcard.physics.profile import DeviceProfile, channels_of
from hcard.physics.profile_effects import FittedEffect, channel_of, with_effects

OUTPUT = Variable("relative_friction", "", "total relative friction uv * ev (Eq. 4.1)")
LATERAL = Variable("lateral_force", "N",
                   "lateral force: the finger's natural friction times uv * ev")
FINGER_PREFIX = "finger."
"""Prefix of the finger model's parameters in a profile model."""
FINGER_FREE = ("friction_initial", "friction_occluded", "occlusion_time", "load_index",
               "peak_speed", "speed_sensitivity")
"""Finger parameters a calibration fits when the finger model has them."""
MU0_NAMES = ("mu0", "uv_mu0")
"""Friction-coefficient parameters of a base that a finger model replaces."""
SPEED = Variable("speed", "m/s", "finger sliding speed", 0.02)
NORMAL_FORCE = Variable("normal_force", "N", "normal force pressing the finger", 0.5)


def _effect_parameters(effects: Sequence[Effect]) -> tuple[Parameter, ...]:
    return tuple(
        Parameter(f"{e.name}{SEPARATOR}{p.name}", p.unit, p.default, p.bounds, p.source,
                  p.description)
        for e in effects
        for p in e.parameters
    )


def profile_model(profile: DeviceProfile, *, envelope: bool = True,
                  finger: Predictor | None = None) -> Predictor:
    """``profile`` (its predictor and effects at their values) as a model of the total relative
    friction, or of the lateral force with a ``finger`` model (module docstring). ``envelope``:
    the voltage input is the peak envelope of the profile's carrier (a device recording) rather
    than the instantaneous voltage.

    Raises:
        PredictorError: the profile renders neither channel, or ``finger`` does not output a
            lateral force.
    """
    if finger is not None and finger.output.name != "lateral_force":
        raise PredictorError(f"finger model {finger.name} outputs {finger.output.name}, not the "
                             "lateral force of the bare finger")
    uv, ev = channels_of(profile.predictor)
    if uv is None and ev is None:
        raise PredictorError(
            f"profile {profile.name!r}: model {profile.predictor.name!r} renders neither "
            "channel, so there is no friction to fit"
        )
    effects = tuple(fitted.effect for fitted in profile.effects)
    values = {
        f"{fitted.name}{SEPARATOR}{name}": value
        for fitted in profile.effects
        for name, value in fitted.values.items()
    }
    cls = _model_class(profile, effects, envelope, finger)
    finger_values = {} if finger is None else {
        f"{FINGER_PREFIX}{name}": value for name, value in finger.params.items()}
    return cls(**{**profile.predictor.params, **values, **finger_values})


def _model_class(profile: DeviceProfile, effects: tuple[Effect, ...], envelope: bool,
                 finger: Predictor | None = None) -> type[Predictor]:
    base = profile.predictor
    uv_base, ev_base = channels_of(base)
    on = {channel: tuple(e for e in effects if channel_of(e) == channel)
          for channel in ("uv", "ev", "finger")}
    plate = profile.limits.plate_frequency if profile.limits is not None else None
    carrier = profile.limits.carrier_frequency if profile.limits is not None else None
    gain = profile.carrier_gain if envelope else 1.0
    channel_inputs: list[Variable] = []
    if uv_base is not None:
        channel_inputs.append(Variable("amplitude", "m", "measured plate amplitude, "
                                       "peak-to-peak (0: a recording without one, plate off)",
                                       0.0))
        channel_inputs.append(Variable("frequency", "Hz", "plate vibration frequency",
                                       plate if plate is not None else _default(uv_base,
                                                                                "frequency")))
    if ev_base is not None:
        channel_inputs.append(Variable(
            "voltage", "V",
            "EV voltage envelope (peak of the carrier)" if envelope else "EV voltage"))
    names = {v.name for v in channel_inputs}
    extra: list[Variable] = []
    finger_inputs = () if finger is None else finger.inputs
    for variable in (SPEED, NORMAL_FORCE, *finger_inputs, *(v for e in effects for v in e.inputs)):
        if variable.name not in names:
            extra.append(variable)
            names.add(variable.name)
    effect_parameters = _effect_parameters(effects)
    base_names = tuple(p.name for p in base.parameters)
    finger_parameters: tuple[Parameter, ...] = () if finger is None else tuple(
        Parameter(f"{FINGER_PREFIX}{p.name}", p.unit, finger[p.name], p.bounds, p.source,
                  p.description)
        for p in finger.parameters
    )
    calibrated_names = tuple(base.calibrated)
    if finger is not None:
        calibrated_names = tuple(n for n in calibrated_names if n not in MU0_NAMES) + tuple(
            f"{FINGER_PREFIX}{n}" for n in FINGER_FREE if n in finger.params)
    output_variable = OUTPUT if finger is None else LATERAL
    finger_model = finger

    class ProfileModel(EffectHost):
        kind: ClassVar[str] = base.kind
        name: ClassVar[str] = "+".join([profile.name, *(e.name for e in effects)])
        description: ClassVar[str] = (
            f"total relative friction of profile {profile.name} ({base.name})"
            + (f" with {', '.join(e.name for e in effects)}" if effects else "")
        )
        parameters: ClassVar[tuple[Parameter, ...]] = (
            *base.parameters, *finger_parameters, *effect_parameters)
        inputs: ClassVar[tuple[Variable, ...]] = (*channel_inputs, *extra)
        output: ClassVar[Variable] = output_variable
        calibrated: ClassVar[tuple[str, ...]] = calibrated_names
        inverse_input: ClassVar[str | None] = None
        envelope_voltage: ClassVar[bool] = envelope

        def __init__(self, **params: float) -> None:
            super().__init__(**{**{n: base[n] for n in base_names}, **params})
            predictor = base.with_params(**{n: self._values[n] for n in base_names})
            self._finger = None if finger_model is None else finger_model.with_params(**{
                p.name: self._values[f"{FINGER_PREFIX}{p.name}"]
                for p in finger_model.parameters})
            uv, ev = channels_of(predictor)
            self._predictor = predictor
            self._fitted = tuple(
                FittedEffect(e, {p.name: self._values[f"{e.name}{SEPARATOR}{p.name}"]
                                 for p in e.parameters})
                for e in effects
            )
            by_channel = {c: [f for f in self._fitted if f.channel == c] for c in on}
            self._uv = None if uv is None else with_effects(uv, by_channel["uv"])
            self._ev = None if ev is None else with_effects(ev, by_channel["ev"])
            self._finger_effects = by_channel["finger"]

        # -- effects (EffectHost) ---------------------------------------------------------
        def refuses(self, effect: Effect) -> str | None:
            channel = channel_of(effect)
            if effect.name in {e.name for e in effects}:
                return "is already in the model"
            if envelope and "voltage" in getattr(effect, "instantaneous", ()):
                return ("needs the instantaneous voltage, but the recording's voltage is a "
                        "carrier envelope (at one carrier frequency the effect is a constant "
                        "gain, Eq. 3.22, that the base's area absorbs)")
            if channel in ("uv", "ev"):
                model = uv_base if channel == "uv" else ev_base
                if model is None:
                    return (f"acts on the {channel.upper()} channel, which profile "
                            f"{profile.name} does not render")
                return effect.applies_to(model)
            if effect.outputs:
                return (f"applies to {' or '.join(effect.outputs)}, which profile "
                        f"{profile.name} does not output")
            return None

        def with_effects(self, added: Sequence[Effect]) -> Predictor:
            known = [e.name for e in effects]
            new = tuple(e for e in added if e.name not in known)
            cls = _model_class(profile, (*effects, *new), envelope, finger_model)
            defaults = {p.name: p.default for p in _effect_parameters(new)}
            return cls(**{**self._values, **defaults})

        # -- the map ------------------------------------------------------------------------
        def fitted_profile(self) -> DeviceProfile:
            """``profile`` with this model's predictor values and effects."""
            return profile.replace(predictor=self._predictor, effects=self._fitted)

        @property
        def finger(self) -> Predictor | None:
            """The finger model at this instance's values (None without one)."""
            return self._finger

        def _forward(self, **given: np.ndarray) -> np.ndarray:
            arrays: dict[str, np.ndarray] = dict(given)
            for fitted in self._finger_effects:
                arrays = fitted.effect.transform_inputs(arrays, fitted.values)
            fn = arrays["normal_force"]
            reaction = fn
            total = np.ones(np.broadcast(*arrays.values()).shape)
            if self._uv is not None:
                total = total * forward_cache.forward(
                    (type(self), "uv"), self._uv, _take(self._uv, arrays))
            if self._ev is not None:
                effective = dict(arrays)
                effective["voltage"] = gain * arrays["voltage"] / (
                    math.sqrt(2.0) if envelope else 1.0)
                if carrier is not None:
                    effective["frequency"] = np.asarray(carrier, dtype=np.float64)
                force = self._ev.forward(**_take(self._ev, effective))
                with np.errstate(divide="ignore", invalid="ignore"):
                    total = total * np.where(fn > 0, 1.0 + force / fn, 1.0)
                reaction = fn + force  # Eq. 3.1: the attraction adds to the normal force
            if self._finger is not None:
                total = total * forward_cache.forward(
                    (type(self), "finger"), self._finger, _take(self._finger, arrays))
            # the finger's effects act on the friction as a whole, a load index on the
            # reaction force Fn + F_e (Eq. 2.35 with Eq. 3.1)
            finger_inputs = {**arrays, "reaction_force": reaction}
            for fitted in self._finger_effects:
                total = fitted.effect.transform_output_of(
                    output_variable.name, total, finger_inputs, fitted.values)
            return total

    ProfileModel.__name__ = ProfileModel.__qualname__ = f"ProfileModel_{base.name}"
    return ProfileModel


def _default(model: Predictor, name: str) -> float | None:
    for variable in model.inputs:
        if variable.name == name:
            return variable.default
    return None


def _take(model: Predictor, arrays: Mapping[str, Any]) -> dict[str, Any]:
    """The arrays ``model`` takes, by its input names."""
    names = {v.name for v in model.inputs}
    return {name: value for name, value in arrays.items() if name in names}


def fitted_profile(model: Predictor) -> DeviceProfile:
    """The device profile a fitted :func:`profile_model` (possibly wrapped to the lateral force)
    stands for: the base profile with the fitted predictor values and effects.

    Raises:
        PredictorError: ``model`` is not (a wrapping of) a profile model.
    """
    inner: Any = model
    while not hasattr(inner, "fitted_profile"):
        inner = getattr(inner, "inner", None)
        if inner is None:
            raise PredictorError(f"model {model.name} is not a device profile's model")
    return inner.fitted_profile()
