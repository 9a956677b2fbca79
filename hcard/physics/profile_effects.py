"""Effects in a device profile: where each one acts, and the channel models that carry it.

A calibrated device profile (spec/device-profile.md) holds the base predictor and the effects a
calibration added (:class:`FittedEffect`: a calibration effect plugin with its fitted parameter
values and uncertainties). Each effect acts on one part of the device's physics
(:func:`channel_of`, rule DP4):

- ``"uv"``: the ultrasonic channel, for an effect on a relative-friction output or on the plate
  amplitude (ultrasonic speed, squeeze-film share, actuator bandwidth);
- ``"ev"``: the electrovibration channel, for an effect on an electrostatic-force output or on the
  voltage (air layer, finger geometry, charge leakage);
- ``"finger"``: the bare finger's friction, for an effect on the friction force as a whole (load
  index, occlusion, skin recovery). It scales the friction with and without modulation alike,
  so it leaves the relative friction a card asks for unchanged; it is part of the fitted
  lateral-force model, not of the rendering. One exception in the physics: occlusion raises
  the dry friction coefficient ``mu0``, which also enters the ultrasonic group ``Psi`` (Eq. 2.30)
  through :meth:`~hcard.physics.effects.Effect.transform_params`, in the share
  ``psi_share`` of its rise; augmenting a UV model with it (:func:`with_effects`) carries that,
  while a model that applies finger effects to the total alone sees only the scaling.

:func:`with_effects` builds a channel model with its effects (:func:`hcard.physics.effects.
augment`), and :func:`solve_decreasing` inverts a monotone channel map numerically where the
effects leave no closed-form inverse.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hcard.physics.effects import SEPARATOR, augment
from hcard.physics.predictor import Predictor, PredictorError

if TYPE_CHECKING:
    from hcard.plugins.registry import PluginRegistry

CHANNELS = ("uv", "ev", "finger")
"""Where an effect acts (module docstring)."""

BISECTION_STEPS = 48
"""Halvings of :func:`solve_decreasing`: the bracket shrinks by 2^-48 (a 10 um bracket to
4e-20 m)."""


class EffectError(PredictorError):
    """An effect entry of a profile is invalid; the message names the field."""


def channel_of(effect: Any) -> str:
    """The part of the physics ``effect`` acts on: ``"uv"``, ``"ev"`` or ``"finger"``."""
    outputs, requires = set(effect.outputs), set(effect.requires)
    if "relative_friction" in outputs or "amplitude" in requires:
        return "uv"
    if "electrostatic_force" in outputs or "voltage" in requires:
        return "ev"
    return "finger"


@dataclass(frozen=True)
class FittedEffect:
    """A calibration effect with the values of its parameters.

    Attributes:
        effect: the effect plugin (:class:`hcard.physics.effects.Effect`).
        values: its parameters by short name, in their units (SI).
        uncertainties: standard uncertainty of each fitted parameter (None: not fitted, or not
            identified by the data).
    """

    effect: Any
    values: Mapping[str, float]
    uncertainties: Mapping[str, float | None] = field(default_factory=dict)

    def __post_init__(self) -> None:
        known = {p.name: p for p in self.effect.parameters}
        unknown = sorted(set(self.values) - set(known))
        if unknown:
            raise EffectError(
                f"effect {self.effect.name}: unknown parameter(s) {', '.join(unknown)}; "
                f"parameters: {', '.join(known) or 'none'}"
            )
        checked = {}
        for name, parameter in known.items():
            try:
                checked[name] = parameter.check(self.values.get(name, parameter.default))
            except PredictorError as exc:
                raise EffectError(f"effect {self.effect.name}: {exc}") from None
        object.__setattr__(self, "values", checked)

    @property
    def name(self) -> str:
        """The effect's name."""
        return str(self.effect.name)

    @property
    def channel(self) -> str:
        """Where it acts (:func:`channel_of`)."""
        return channel_of(self.effect)

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "channel", "parameters": {name: {"value", "unit", "uncertainty"}}}``."""
        return {
            "name": self.name,
            "channel": self.channel,
            "parameters": {
                p.name: {
                    "value": self.values[p.name],
                    "unit": p.unit,
                    "uncertainty": _finite(self.uncertainties.get(p.name)),
                }
                for p in self.effect.parameters
            },
        }

    @classmethod
    def from_dict(cls, raw: Any, *, source: str, registry: PluginRegistry) -> FittedEffect:
        """An effect entry of a profile file; errors name ``source`` (the entry's path)."""
        if not isinstance(raw, Mapping):
            raise EffectError(f"{source}: must be an object with 'name' and 'parameters'")
        name = raw.get("name")
        library = registry.calibration_effects
        effect = library.get(name) if isinstance(name, str) else None
        if isinstance(effect, type):
            effect = effect()
        if effect is None:
            raise EffectError(
                f"{source}.name: unknown calibration effect {name!r}; installed: "
                f"{', '.join(sorted(library)) or 'none'}"
            )
        channel = raw.get("channel", channel_of(effect))
        if channel != channel_of(effect):
            raise EffectError(
                f"{source}.channel: {channel!r}, but effect {name} acts on "
                f"{channel_of(effect)!r}"
            )
        parameters = raw.get("parameters", {})
        if not isinstance(parameters, Mapping):
            raise EffectError(f"{source}.parameters: must be an object")
        units = {p.name: p.unit for p in effect.parameters}
        values: dict[str, float] = {}
        uncertainties: dict[str, float | None] = {}
        for key, entry in parameters.items():
            where = f"{source}.parameters.{key}"
            if key not in units:
                raise EffectError(f"{where}: effect {name} has no such parameter; parameters: "
                                  f"{', '.join(units)}")
            if not isinstance(entry, Mapping):
                raise EffectError(f"{where}: expected an object with 'value' and 'unit'")
            value, unit = entry.get("value"), entry.get("unit", units[key])
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise EffectError(f"{where}.value: expected a number, got {value!r}")
            if unit != units[key]:
                raise EffectError(f"{where}.unit: {unit!r}, but the parameter is in "
                                  f"{units[key]!r} (values are SI)")
            values[key] = float(value)
            sigma = entry.get("uncertainty")
            if sigma is not None and (isinstance(sigma, bool) or not isinstance(sigma,
                                                                                 int | float)):
                raise EffectError(f"{where}.uncertainty: expected a number or null")
            uncertainties[key] = None if sigma is None else float(sigma)
        try:
            return cls(effect, values, uncertainties)
        except EffectError as exc:
            raise EffectError(f"{source}: {exc}") from None


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def with_effects(model: Predictor, effects: Sequence[FittedEffect]) -> Predictor:
    """``model`` with ``effects`` added at their values (``model`` itself when there are none).

    Raises:
        EffectError: an effect cannot act on ``model`` (another output, a missing input).
    """
    if not effects:
        return model
    try:
        augmented = augment(model, [fitted.effect for fitted in effects])
    except PredictorError as exc:
        raise EffectError(str(exc)) from None
    values = {
        f"{fitted.name}{SEPARATOR}{name}": value
        for fitted in effects
        for name, value in fitted.values.items()
    }
    return augmented.with_params(**values)


def solve_decreasing(
    function: Callable[[np.ndarray], np.ndarray],
    target: np.ndarray,
    high: float,
) -> np.ndarray:
    """The ``x`` in ``[0, high]`` with ``function(x) = target``, element by element, for a
    function that does not increase with ``x`` (vectorised bisection, :data:`BISECTION_STEPS`
    halvings). Where even ``high`` leaves the function above the target the answer is ``high``;
    where ``0`` already reaches it, ``0``."""
    target = np.asarray(target, dtype=np.float64)
    low_x = np.zeros(target.shape)
    high_x = np.full(target.shape, float(high))
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low_x + high_x)
        above = np.asarray(function(middle), dtype=np.float64) > target
        low_x = np.where(above, middle, low_x)
        high_x = np.where(above, high_x, middle)
    return high_x
