"""Quantities with units in user text (``"2um"``, ``"27.5 kHz"``, ``"20 mm/s"``) to SI floats."""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from hcard.errors import InputError


class UnitError(InputError, ValueError):
    """A quantity's text cannot be read, or its unit does not fit the expected SI unit."""


_PREFIXES = {
    "T": 1e12,
    "G": 1e9,
    "M": 1e6,
    "k": 1e3,
    "": 1.0,
    "c": 1e-2,
    "m": 1e-3,
    "u": 1e-6,
    "µ": 1e-6,
    "μ": 1e-6,
    "n": 1e-9,
    "p": 1e-12,
    "f": 1e-15,
}
_BASE = {
    "m": "m",
    "s": "s",
    "N": "N",
    "V": "V",
    "Hz": "Hz",
    "Pa": "Pa",
    "A": "A",
    "F": "F",
    "Ohm": "Ohm",
    "ohm": "Ohm",
    "Ω": "Ohm",
    "rad": "rad",
    "": "1",
}
_SPECIAL = {
    "mm/s": (1e-3, "m/s"),
    "m/s": (1.0, "m/s"),
    "um/s": (1e-6, "m/s"),
    "cm/s": (1e-2, "m/s"),
    "mm^2": (1e-6, "m^2"),
    "mm2": (1e-6, "m^2"),
    "cm^2": (1e-4, "m^2"),
    "cm2": (1e-4, "m^2"),
    "m^2": (1.0, "m^2"),
    "um^2": (1e-12, "m^2"),
    "deg": (math.pi / 180, "rad"),
    "%": (1e-2, "1"),
    "N/m": (1.0, "N/m"),
    "MN/m": (1e6, "N/m"),
    "kN/m": (1e3, "N/m"),
    "N/mm": (1e3, "N/m"),
    "S/m": (1.0, "S/m"),
    "atm": (101_325.0, "Pa"),
    "bar": (1e5, "Pa"),
    "kPa": (1e3, "Pa"),
    "min": (60.0, "s"),
    "h": (3600.0, "s"),
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


# -- units for people -------------------------------------------------------------------------
_DISPLAY_PREFIXES = {-12: "p", -9: "n", -6: "µ", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}


def display_unit(unit: str, values: Any) -> tuple[float, str]:
    """``(scale, unit)`` to show SI ``values`` readably: value / scale in the returned unit.

    Lengths in um or mm, speeds in mm/s below 1 m/s, areas in mm^2; other units unchanged from
    0.1 to 1000, else with an engineering prefix (kHz, MN/m, uA); pure numbers unchanged.
    """
    finite = np.abs(np.asarray(values, dtype=np.float64))
    finite = finite[np.isfinite(finite) & (finite > 0)]
    largest = float(finite.max()) if finite.size else 0.0
    if not unit or largest == 0.0:
        return 1.0, unit
    if unit == "m/s":
        return (1e-3, "mm/s") if largest < 1.0 else (1.0, unit)
    if unit == "m^2":
        return (1e-6, "mm^2") if largest < 1e-2 else (1.0, unit)
    if "^" in unit or unit in ("rad", "1"):
        return 1.0, unit
    if 0.1 <= largest < 1000.0 and unit != "m":
        return 1.0, unit
    exponent = int(math.floor(math.log10(largest) / 3.0) * 3)
    exponent = min(max(exponent, -12), 9)
    if unit == "m" and exponent < -6:
        exponent = -6
    return 10.0**exponent, _DISPLAY_PREFIXES[exponent] + unit


def format_value(value: float, unit: str) -> str:
    """``"20 mm/s"``, ``"27.5 kHz"``, ``"0.5 N"``: one value with a readable unit."""
    scale, shown = display_unit(unit, [value])
    text = f"{value / scale:.4g}"
    return f"{text} {shown}" if shown else text
