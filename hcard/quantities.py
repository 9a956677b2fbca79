"""The one vocabulary of quantities and units: names, SI units, display units, parsing.

(:mod:`hcard.physics.units` is this module under its former name, for plugins that import it.)

Inside the code every quantity is a float in its SI unit (m, s, N, V, A, Hz, Pa), except
positions on the touch surface, which are in mm like the card and the renderer. This module
holds what crosses that boundary:

- the named conversion factors (``x_mm * M_PER_MM`` is metres, ``force * MN_PER_N`` is mN)
  that replace bare ``1e-3``/``1e3``/``1e6`` literals;
- :data:`SI_UNITS`, the SI unit of each quantity name used in memory (``normal_force``: N);
- :data:`COLUMN_UNITS`, the unit suffixes a measurement column may carry (rule MF4 of
  spec/measurement-format.md) with their scales to SI;
- parsing of user text (``"2um"``, ``"27.5 kHz"``, ``"20 mm/s"``) to SI floats, and the
  units a person reads (``display_unit``, ``format_value``).
"""

from __future__ import annotations

import math
import re
from typing import Any

from hcard.errors import InputError


class UnitError(InputError, ValueError):
    """A quantity's text cannot be read, or its unit does not fit the expected SI unit."""


# -- named conversions: multiply a value in the unit on the right to get the unit on the left --
M_PER_MM = 1e-3
"""Metres in a millimetre (also m/s in a mm/s)."""
MM_PER_M = 1e3
"""Millimetres in a metre (also mm/s in a m/s)."""
UM_PER_M = 1e6
"""Micrometres in a metre."""
UM_PER_MM = 1e3
"""Micrometres in a millimetre."""
NM_PER_M = 1e9
"""Nanometres in a metre."""
S_PER_MS = 1e-3
"""Seconds in a millisecond."""
MS_PER_S = 1e3
"""Milliseconds in a second."""
S_PER_US = 1e-6
"""Seconds in a microsecond."""
US_PER_S = 1e6
"""Microseconds in a second."""
N_PER_MN = 1e-3
"""Newtons in a millinewton."""
MN_PER_N = 1e3
"""Millinewtons in a newton."""
UA_PER_A = 1e6
"""Microamperes in an ampere."""
ATMOSPHERE_PA = 101_325.0
"""One standard atmosphere, Pa (exact by definition)."""
EPSILON_0 = 8.8541878188e-12
"""Vacuum permittivity, F/m (CODATA 2022; Table 3.2 of the thesis lists 8.8542e-12). SciPy 1.15
and later give the same in ``scipy.constants.epsilon_0`` (1.10-1.14: CODATA 2018, 6.8e-10
lower); tests/card/test_quantities.py compares. The physical constants are written out here because
``import scipy.constants`` takes ~0.1 s, and the hosts that only run predictors (the QEMU
guest, a conformance run) import the models that use them."""

SI_UNITS: dict[str, str] = {
    "time": "s",
    "amplitude": "m",
    "voltage": "V",
    "current": "A",
    "x": "m",
    "y": "m",
    "speed": "m/s",
    "normal_force": "N",
    "lateral_force": "N",
    "frequency": "Hz",
    "plate_frequency": "Hz",
    "pressure": "Pa",
    "target": "",
    "stroke": "",
    "direction": "",
}
"""SI unit of each quantity as named in memory ("" for pure numbers): the names of
:class:`hcard.calibration.measurement.Measurement`, the calibration regressors and the
predictor inputs."""


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
    "atm": (ATMOSPHERE_PA, "Pa"),
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
    "bar": (1e5, "Pa"),
    "kPa": (1e3, "Pa"),
    "min": (60.0, "s"),
    "h": (3600.0, "s"),
}
_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


_COLUMN_SPELLING = {
    "s": "s", "ms": "ms", "us": "us",
    "m": "m", "mm": "mm", "um": "um", "nm": "nm",
    "v": "V", "kv": "kV", "mv": "mV",
    "m_s": "m/s", "mm_s": "mm/s", "um_s": "um/s",
    "n": "N", "mn": "mN",
    "hz": "Hz", "khz": "kHz",
    "a": "A", "ma": "mA", "ua": "uA",
}
"""Unit suffix of a measurement column header (lower case, ``_`` for ``/``) -> unit text."""


def column_units(*suffixes: str) -> dict[str, float]:
    """``{suffix: scale to SI}`` for measurement column suffixes (``"mn"`` -> 1e-3)."""
    return {suffix: parse_unit(_COLUMN_SPELLING[suffix])[0] for suffix in suffixes}


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


_TIME = column_units("s", "ms", "us")
_LENGTH = column_units("m", "mm", "um")
_FORCE = column_units("n", "mn")
COLUMN_UNITS: dict[str, dict[str, float]] = {
    "t": _TIME,
    "amplitude": column_units("m", "mm", "um", "nm"),
    "voltage": column_units("v", "kv", "mv"),
    "x": _LENGTH,
    "y": _LENGTH,
    "speed": column_units("m_s", "mm_s", "um_s"),
    "fn": _FORCE,
    "fl": _FORCE,
    "frequency": column_units("hz", "khz"),
    # device columns (rule MF12)
    "current": column_units("a", "ma", "ua"),
    "f_tl": _FORCE,
    "f_tr": _FORCE,
    "f_bl": _FORCE,
    "f_br": _FORCE,
    "echo": _TIME,
}
"""Accepted unit suffixes of each measurement column quantity, SI first: suffix -> scale to
SI (rule MF4 of spec/measurement-format.md; device columns rule MF12)."""


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
    import numpy as np  # here: the device's drivers and the protocol use this module, not numpy

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
