"""Device limits: what a device can do (spec/device-profile.md, ``limits``), and the limits
that follow from them.

A device's commands are clipped to its :class:`DeviceLimits`: plate amplitude, EV voltage, and
the current the EV amplifier may drive through the user, which binds the voltage below
``max_voltage`` when the load capacitance draws more at the carrier frequency
(:func:`binding_voltage_limit`); the capacitance is given, or follows from the EV model's layers
(Eq. 3.8, :func:`layer_capacitance`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from hcard.physics.profile_error import ProfileError
from hcard.quantities import EPSILON_0, UnitError, parse_quantity, parse_unit

LAYER_PARAMETERS = (
    "area", "sc_thickness", "sc_permittivity", "insulator_thickness", "insulator_permittivity"
)
"""Parameters of a layered EV model from which Eq. 3.8 gives the finger capacitance."""


@dataclass(frozen=True)
class DeviceLimits:
    """What a device can do, in SI units; commands are clipped to these.

    Attributes:
        max_amplitude: largest peak-to-peak plate vibration amplitude, m (0: no UV channel).
        max_voltage: largest peak EV voltage of the amplifier, V (0: no EV channel).
        max_current: largest peak current the EV amplifier may drive through the user, A
            (250 uA on the coupled stimulator of chapter 4, section 3.6.3).
        carrier_frequency: frequency of the sinusoidal EV carrier, Hz (440 Hz in chapter 4).
        plate_frequency: resonance frequency of the vibrating plate, Hz (38,220 Hz, chapter 4).
        load_capacitance: capacitance the EV amplifier drives through the finger, F; ``None``
            derives it from the EV model's layers, ``C = eps0 A / (d_sc/eps_sc + d_i/eps_i)``
            (Eq. 3.8; 33 pF for the section 3.6 values). A profile whose EV model has no such
            layers must give it.
    """

    max_amplitude: float
    max_voltage: float
    max_current: float
    carrier_frequency: float
    plate_frequency: float
    load_capacitance: float | None = None

    UNITS: ClassVar[dict[str, str]] = {
        "max_amplitude": "m",
        "max_voltage": "V",
        "max_current": "A",
        "carrier_frequency": "Hz",
        "plate_frequency": "Hz",
        "load_capacitance": "F",
    }
    """SI unit of each field."""

    def __post_init__(self) -> None:
        for name in self.UNITS:
            value = getattr(self, name)
            if value is None and name == "load_capacitance":
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ProfileError(f"limits.{name}: must be a number, got {value!r}")
            value = float(value)
            object.__setattr__(self, name, value)
            strictly = name not in ("max_amplitude", "max_voltage")
            if not math.isfinite(value) or value < 0 or (strictly and value == 0):
                relation = "> 0" if strictly else ">= 0"
                raise ProfileError(
                    f"limits.{name}: must be a finite number {relation} {self.UNITS[name]}, "
                    f"got {value:g}"
                )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{field: {"value": v, "unit": u}}`` (``None`` stays ``None``)."""
        out: dict[str, Any] = {}
        for name, unit in self.UNITS.items():
            value = getattr(self, name)
            out[name] = None if value is None else {"value": value, "unit": unit}
        return out

    @classmethod
    def from_dict(cls, raw: Any, *, source: str) -> DeviceLimits:
        """Limits from a profile's ``limits`` object.

        Each field is a number in SI units, a ``{"value": v, "unit": u}`` object whose unit
        has the right dimension (``"um"`` for ``max_amplitude``), or a string such as
        ``"2.5 um"``. Errors name ``source`` and the field.
        """
        if not isinstance(raw, Mapping):
            raise ProfileError(f"{source}: 'limits' must be an object")
        unknown = sorted(set(raw) - set(cls.UNITS))
        if unknown:
            raise ProfileError(
                f"{source}: limits.{unknown[0]}: unknown field; fields: {', '.join(cls.UNITS)}"
            )
        values: dict[str, float | None] = {}
        for name, unit in cls.UNITS.items():
            where = f"{source}: limits.{name}"
            if name not in raw:
                if name == "load_capacitance":
                    continue
                raise ProfileError(f"{where}: missing ({unit})")
            values[name] = _si_value(raw[name], unit, where, optional=name == "load_capacitance")
        try:
            return cls(**values)  # type: ignore[arg-type]
        except ProfileError as exc:
            raise ProfileError(f"{source}: {exc}") from None


COUPLED_STIMULATOR_LIMITS = DeviceLimits(
    max_amplitude=2.5e-6,
    max_voltage=2000.0,
    max_current=250e-6,
    carrier_frequency=440.0,
    plate_frequency=38_220.0,
)
"""The coupled UV+EV stimulator of chapter 4 (section 4.2.1): aluminium plate at 38,220 Hz,
EV amplifier to 2000 V modulated at 440 Hz, current limited to 250 uA (section 3.6.3); plate
amplitudes up to 2.5 um peak-to-peak, the range "generally implemented in ultrasonic displays"
(section 2.4)."""


def _si_value(raw: Any, unit: str, where: str, *, optional: bool = False) -> float | None:
    """An SI float from a profile field (number, ``{"value", "unit"}`` or ``"2.5 um"``)."""
    if raw is None and optional:
        return None
    if isinstance(raw, str):
        try:
            return parse_quantity(raw, unit)
        except UnitError as exc:
            raise ProfileError(f"{where}: {exc}") from None
    scale = 1.0
    if isinstance(raw, Mapping):
        given_unit = raw.get("unit", unit)
        if not isinstance(given_unit, str):
            raise ProfileError(f"{where}: 'unit' must be a string")
        try:
            scale, dimension = parse_unit(given_unit)
            expected = parse_unit(unit)[1]
        except UnitError as exc:
            raise ProfileError(f"{where}: {exc}") from None
        if dimension != expected:
            raise ProfileError(f"{where}: unit {given_unit!r} is not a unit of {unit}")
        raw = raw.get("value")
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ProfileError(f"{where}: must be a number ({unit}), got {raw!r}")
    return float(raw) * scale


def binding_voltage_limit(limits: DeviceLimits,
                          load_capacitance: float | None) -> tuple[float, str]:
    """The binding peak-voltage limit, V, and its name (``max_voltage`` or ``max_current``).

    ``max_current`` binds when a sinusoidal carrier of peak ``V`` at ``carrier_frequency``
    into ``load_capacitance`` (F) would draw more than ``max_current`` (``I = 2 pi f C V``,
    the envelope taken as slow against the carrier). Without a capacitance (no EV channel)
    nothing draws current and ``max_voltage`` binds.
    """
    if load_capacitance is None:
        return limits.max_voltage, "max_voltage"
    by_current = limits.max_current / (
        2.0 * math.pi * limits.carrier_frequency * load_capacitance)
    if by_current < limits.max_voltage:
        return by_current, "max_current"
    return limits.max_voltage, "max_voltage"


def layer_capacitance(params: Mapping[str, float]) -> float | None:
    """The finger capacitance, F, of an EV model's layer parameters (:data:`LAYER_PARAMETERS`):
    ``C = eps0 A / (d_sc/eps_sc + d_i/eps_i)`` (Eq. 3.8); None when the model lacks one."""
    if not set(LAYER_PARAMETERS) <= set(params):
        return None
    electrical_thickness = (
        params["sc_thickness"] / params["sc_permittivity"]
        + params["insulator_thickness"] / params["insulator_permittivity"]
    )
    return EPSILON_0 * params["area"] / electrical_thickness
