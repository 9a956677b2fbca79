"""Quantities with units in user text (``"2um"``, ``"27.5 kHz"``, ``"20 mm/s"``) to SI floats."""

from __future__ import annotations

import math
import re

from hcard.errors import HcardError


class UnitError(HcardError, ValueError):
    """A quantity's text cannot be read, or its unit does not fit the expected SI unit."""


_PREFIXES = {
    "T": 1e12, "G": 1e9, "M": 1e6, "k": 1e3, "": 1.0, "c": 1e-2, "m": 1e-3,
    "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "n": 1e-9, "p": 1e-12, "f": 1e-15,
}
_BASE = {
    "m": "m", "s": "s", "N": "N", "V": "V", "Hz": "Hz", "Pa": "Pa", "A": "A", "F": "F",
    "Ohm": "Ohm", "ohm": "Ohm", "Ω": "Ohm", "rad": "rad", "": "1",
}
_SPECIAL = {
    "mm/s": (1e-3, "m/s"), "m/s": (1.0, "m/s"), "um/s": (1e-6, "m/s"), "cm/s": (1e-2, "m/s"),
    "mm^2": (1e-6, "m^2"), "mm2": (1e-6, "m^2"), "cm^2": (1e-4, "m^2"), "cm2": (1e-4, "m^2"),
    "m^2": (1.0, "m^2"), "um^2": (1e-12, "m^2"), "deg": (math.pi / 180, "rad"),
    "%": (1e-2, "1"), "N/m": (1.0, "N/m"), "MN/m": (1e6, "N/m"), "kN/m": (1e3, "N/m"),
    "N/mm": (1e3, "N/m"), "S/m": (1.0, "S/m"), "atm": (101_325.0, "Pa"), "bar": (1e5, "Pa"),
    "kPa": (1e3, "Pa"), "min": (60.0, "s"), "h": (3600.0, "s"),
}
_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def parse_unit(unit: str) -> tuple[float, str]:
    """Scale to SI and the SI unit of ``unit`` (``"um"`` -> ``(1e-6, "m")``)."""
    unit = unit.strip()
    if unit in _SPECIAL:
        return _SPECIAL[unit]
    if unit in _BASE:
        return 1.0, _BASE[unit]
    for base in sorted(_BASE, key=len, reverse=True):
        if base and unit.endswith(base) and unit[: -len(base)] in _PREFIXES:
            return _PREFIXES[unit[: -len(base)]], _BASE[base]
    raise UnitError(f"unknown unit {unit!r}")


def parse_quantity(text: str, expected_unit: str) -> float:
    """The SI value of ``text`` (a number with an optional unit) in ``expected_unit``.

    A bare number is taken to be in ``expected_unit`` already. Raises :class:`UnitError` when
    the unit is unknown or of another dimension (``"5 mm"`` where Hz is expected).
    """
    match = _NUMBER.match(text)
    if not match:
        raise UnitError(f"{text!r} is not a number with an optional unit")
    value, unit = float(match.group(1)), match.group(2)
    if not unit:
        return value
    scale, si = parse_unit(unit)
    expected = parse_unit(expected_unit)[1] if expected_unit else "1"
    if si != expected:
        raise UnitError(f"{text!r}: unit {unit!r} is not a unit of {expected_unit or 'a ratio'}")
    return value * scale
