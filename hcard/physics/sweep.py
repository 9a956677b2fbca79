"""User text for predictor inputs and sweeps: ``name=value`` and ``name=start:stop:count``.

``hcard predict`` takes ``--param kn=3.9MN/m``, ``--input speed=20mm/s`` and
``--sweep amplitude=0:5um:51``. Values carry optional units (:func:`hcard.quantities.
parse_quantity`); inside the code everything is SI (:mod:`hcard.quantities`).

A sweep is ``START:STOP:COUNT`` with an optional fourth field ``lin`` (default, evenly spaced)
or ``log`` (geometrically spaced, both ends > 0). When only one end carries a unit the other
takes the same unit, so ``0:5um:51`` runs from 0 um to 5 um and ``1:5um:5`` from 1 um to 5 um
(never from 1 m).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from hcard.errors import InputError
from hcard.quantities import UnitError, parse_quantity

MAX_SWEEP_POINTS = 1_000_000
"""Largest COUNT of a sweep (a bigger one is a typo, not a plot)."""

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.]*$")
_NUMBER_PREFIX = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*")


class SweepError(InputError, ValueError):
    """A ``name=value`` assignment or a sweep specification cannot be read."""


@dataclass(frozen=True)
class Sweep:
    """Values of one variable: ``count`` points from ``start`` to ``stop`` (SI units).

    Attributes:
        name: the input (or parameter) swept.
        start: first value, SI.
        stop: last value, SI.
        count: number of points, >= 2.
        spacing: ``"lin"`` (even steps) or ``"log"`` (even ratios).
    """

    name: str
    start: float
    stop: float
    count: int
    spacing: str = "lin"

    def values(self) -> np.ndarray:
        """The swept values, SI, shape ``(count,)``; the ends are exact."""
        if self.spacing == "log":
            values = np.geomspace(self.start, self.stop, self.count)
        else:
            values = np.linspace(self.start, self.stop, self.count)
        values[0], values[-1] = self.start, self.stop
        return values


def split_assignment(text: str, what: str) -> tuple[str, str]:
    """``"speed=20mm/s"`` -> ``("speed", "20mm/s")``.

    Args:
        text: the option value.
        what: the option, for messages (``"--input"``).

    Raises:
        SweepError: no ``=``, an empty or malformed name, or an empty value.
    """
    name, sep, value = text.partition("=")
    name, value = name.strip(), value.strip()
    if not sep or not value:
        raise SweepError(f"{what} {text!r}: expected NAME=VALUE")
    if not _NAME.match(name):
        raise SweepError(f"{what} {text!r}: {name!r} is not a valid name")
    return name, value


def quantity(text: str, unit: str, what: str) -> float:
    """The SI value of ``text`` for a quantity in ``unit``; errors name ``what``.

    A bare number is in ``unit``. A unit that :mod:`hcard.quantities` does not know is
    accepted only when written exactly as ``unit`` (for units such as ``"F/m"``).

    Raises:
        UnitError: unreadable number, unknown unit or a unit of another dimension.
    """
    try:
        value = parse_quantity(text, unit)
    except UnitError as exc:
        prefix = _NUMBER_PREFIX.match(text)
        written = text[prefix.end():].strip() if prefix else ""
        if prefix and unit and written == unit:
            value = float(text[: prefix.end()])
        else:
            raise UnitError(f"{what}: {exc}") from None
    if not math.isfinite(value):
        raise UnitError(f"{what}: {text!r} is not a finite number")
    return value


def _unit_of(text: str) -> str:
    """The unit written after the number in ``text`` ("" for a bare number)."""
    prefix = _NUMBER_PREFIX.match(text)
    return text[prefix.end():].strip() if prefix else ""


def parse_sweep(name: str, spec: str, unit: str) -> Sweep:
    """A :class:`Sweep` of ``name`` (a quantity in ``unit``) from ``"START:STOP:COUNT[:log]"``.

    Raises:
        SweepError: not three or four fields, COUNT not an integer in [2, 1e6], equal ends,
            an unknown spacing, or a log sweep through zero.
        UnitError: an end is unreadable or in a unit of another dimension.
    """
    where = f"--sweep {name}={spec}"
    fields = [field.strip() for field in spec.split(":")]
    if len(fields) not in (3, 4) or not all(fields):
        raise SweepError(f"{where}: expected START:STOP:COUNT (for example 0:5um:51)")
    start_text, stop_text, count_text = fields[:3]
    spacing = fields[3].lower() if len(fields) == 4 else "lin"
    if spacing not in ("lin", "log"):
        raise SweepError(f"{where}: spacing must be 'lin' or 'log', not {fields[3]!r}")
    start_unit, stop_unit = _unit_of(start_text), _unit_of(stop_text)
    if start_unit and not stop_unit:
        stop_text += start_unit
    elif stop_unit and not start_unit:
        start_text += stop_unit
    start = quantity(start_text, unit, f"{where}: START")
    stop = quantity(stop_text, unit, f"{where}: STOP")
    try:
        count = int(count_text)
    except ValueError:
        raise SweepError(f"{where}: COUNT must be an integer, not {count_text!r}") from None
    if not 2 <= count <= MAX_SWEEP_POINTS:
        raise SweepError(f"{where}: COUNT must be between 2 and {MAX_SWEEP_POINTS}, not {count}")
    if start == stop:
        raise SweepError(f"{where}: START and STOP are equal")
    if spacing == "log" and (start <= 0 or stop <= 0):
        raise SweepError(f"{where}: a log sweep needs START and STOP > 0")
    return Sweep(name, start, stop, count, spacing)
