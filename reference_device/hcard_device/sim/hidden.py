"""Physical effects the simulated hardware can hide: ``hcard device serve --effect NAME``.

A device served with an effect behaves differently from its own profile (the firmware's model,
:mod:`.models`) and says nothing about it: no report, no sidecar key names the effect. It is how a
test hides an effect in the hardware that a calibration must find from recordings alone. The
effect runs the physics code of its own model, never the calibration plugin's transform of the
same name:

- ``air-layer`` (coupled stimulator): air trapped between the fingerprint ridges and the
  insulator, a third dielectric in series (Eq. 3.17, Fig. 3.7). The finger's electrostatic force
  is :class:`~hcard_builtins.physics.electrovibration.AirLayer` with the contact layers of the
  device's Kaczmarek model and an air gap the load flattens, ``d_a = d_a1 (1 N / F_n)``, at the
  carrier-averaged voltage ``g V / sqrt 2`` (``g`` the leakage gain at the carrier). Parameter
  ``air_gap`` = ``d_a1``, m (default 10 um: the force falls to about half at 0.5 N).

Effects take their parameters as ``NAME.PARAM=VALUE`` (units accepted:
``air-layer.air_gap=8um``); :data:`HIDDEN_EFFECTS` lists which device each applies to.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from hcard.errors import InputError
from hcard.physics import Parameter, PredictorError
from hcard.physics.profile import DeviceProfile
from hcard_builtins.physics.electrovibration import AirLayer

REFERENCE_FORCE_N = 1.0
"""Normal force at which the air gap is ``air_gap``, N."""
MIN_FORCE_N = 1e-3
"""The air gap is evaluated at no less than this normal force, N (a finger barely touching)."""


class HiddenEffectError(InputError, ValueError):
    """An unknown hidden effect or parameter, a bad value, or an effect the device cannot have."""


@dataclass(frozen=True)
class HiddenEffect:
    """An effect the simulated hardware can hide.

    Attributes:
        name: its name (the calibration library's name for the same physics).
        description: one line: what it is, with its thesis source.
        devices: the device variants (``evita``, ``coupled``) that can have it.
        parameters: its parameters; the defaults are the hidden truth when none is given.
    """

    name: str
    description: str
    devices: tuple[str, ...]
    parameters: tuple[Parameter, ...]


HIDDEN_EFFECTS: dict[str, HiddenEffect] = {
    "air-layer": HiddenEffect(
        "air-layer",
        "air between the fingerprint ridges and the insulator: EV force of AirLayer (Eq. 3.17) "
        "with the gap d_a1 (1 N / Fn)",
        ("coupled",),
        (Parameter("air_gap", "m", 10e-6, (0.0, 1e-3), "Eq. 3.17, Fig. 3.7; value chosen",
                   "air gap d_a1 at a normal force of 1 N"),),
    ),
}
"""The effects a simulated device can hide, by name."""


def resolve(variant: str, effects: Mapping[str, Mapping[str, float]] | None
            ) -> dict[str, dict[str, float]]:
    """``effects`` checked for device ``variant`` and completed with the defaults.

    Raises:
        HiddenEffectError: an unknown effect or parameter (listing the known ones), one the
            device cannot have, or a value outside the parameter's bounds.
    """
    out: dict[str, dict[str, float]] = {}
    for name, values in (effects or {}).items():
        effect = HIDDEN_EFFECTS.get(name)
        if effect is None:
            raise HiddenEffectError(
                f"unknown hidden effect {name!r}; known: {', '.join(HIDDEN_EFFECTS)}")
        if variant not in effect.devices:
            raise HiddenEffectError(
                f"effect {name} needs the {' or '.join(effect.devices)} device, not {variant}")
        known = {p.name: p for p in effect.parameters}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise HiddenEffectError(
                f"effect {name} has no parameter(s) {', '.join(unknown)}; its parameters: "
                f"{', '.join(known)}")
        checked = {}
        for parameter in effect.parameters:
            try:
                checked[parameter.name] = parameter.check(values.get(parameter.name,
                                                                     parameter.default))
            except PredictorError as exc:
                raise HiddenEffectError(f"effect {name}: {exc}") from None
        out[name] = checked
    return out


def parse_assignments(names: Iterable[str], assignments: Iterable[str]
                      ) -> dict[str, dict[str, float]]:
    """Effects from ``--effect NAME`` and ``--effect-param NAME.PARAM=VALUE`` texts (units
    accepted; an assignment switches its effect on).

    Raises:
        HiddenEffectError: a malformed assignment, an unknown effect or parameter, a bad value.
    """
    from hcard.quantities import UnitError, parse_quantity

    chosen: dict[str, dict[str, float]] = {name: {} for name in names}
    for text in assignments:
        key, equals, value = text.partition("=")
        effect, dot, parameter = key.strip().rpartition(".")
        if not equals or not dot or not effect or not parameter or not value.strip():
            raise HiddenEffectError(
                f"{text!r}: expected EFFECT.PARAM=VALUE (air-layer.air_gap=8um)")
        known = HIDDEN_EFFECTS.get(effect)
        if known is None:
            raise HiddenEffectError(
                f"{text!r}: unknown hidden effect {effect!r}; known: {', '.join(HIDDEN_EFFECTS)}")
        units = {p.name: p.unit for p in known.parameters}
        if parameter not in units:
            raise HiddenEffectError(
                f"{text!r}: effect {effect} has no parameter {parameter!r}; its parameters: "
                f"{', '.join(units)}")
        try:
            chosen.setdefault(effect, {})[parameter] = parse_quantity(value.strip(),
                                                                      units[parameter])
        except UnitError as exc:
            raise HiddenEffectError(f"{text!r}: {exc}") from None
    return chosen


class HiddenPhysics:
    """The hidden effects of one simulated device, applied to its finger's physics.

    Args:
        profile: the device's own profile (its EV model gives the contact layers).
        effects: resolved effects (:func:`resolve`).
    """

    def __init__(self, profile: DeviceProfile, effects: Mapping[str, Mapping[str, float]]):
        self.effects = {name: dict(values) for name, values in effects.items()}
        self._air: AirLayer | None = None
        if "air-layer" in self.effects:
            ev = profile.ev_model
            if ev is None:
                raise HiddenEffectError("effect air-layer needs an EV channel")
            layers = {p.name: ev[p.name] for p in AirLayer.parameters if p.name in ev.params}
            self._air = AirLayer(**layers)
            self._gain = profile.carrier_gain

    def __bool__(self) -> bool:
        return bool(self.effects)

    def ev_force(self, voltage: np.ndarray, normal_force: np.ndarray) -> np.ndarray | None:
        """The finger's carrier-averaged EV force, N, at the voltage envelope ``voltage`` (V)
        and ``normal_force`` (N); None when no hidden effect changes it."""
        if self._air is None:
            return None
        gap = self.effects["air-layer"]["air_gap"] * REFERENCE_FORCE_N / np.maximum(
            normal_force, MIN_FORCE_N)
        effective = self._gain * np.asarray(voltage, dtype=np.float64) / math.sqrt(2.0)
        return np.asarray(self._air.forward(voltage=effective, air_gap=gap), dtype=np.float64)
