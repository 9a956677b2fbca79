"""``hcard calibrate map FILE``: a column map proposed from what a lab file holds
(spec/lab-recordings.md LR13): quantities and units from variable names (``Fn_N``,
``force_mN``, ``pos_counts``), the sample rate from a time vector, and a list of what it could
not decide."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hcard.calibration.lab.column_map import MAP_VERSION
from hcard.calibration.lab.source import LabFile
from hcard.quantities import COLUMN_UNITS

NAME_QUANTITY = (
    ("t", r"t|time|times|timestamp|tt"),
    ("fn", r"fn|fz|normal|normalforce|forcenormal|load"),
    ("fl", r"fl|ft|fx|lateral|friction|tangential|lateralforce|frictionforce"),
    ("amplitude", r"amp|amplitude|vib|vibration|displacement"),
    ("voltage", r"volt|voltage|ev|hv|vev"),
    ("x", r"x|pos|position|posx|enc|encoder"),
    ("y", r"y|posy"),
    ("speed", r"v|speed|vel|velocity"),
    ("frequency", r"f|freq|frequency"),
    ("stroke", r"stroke|strokes|trial"),
)
"""Quantity -> the words of a variable's name (without its unit, lower case) that mean it."""
UNIT_WORDS = {"counts": "counts", "count": "counts", "cnt": "counts", "mm_s": "mm_s",
              "m_s": "m_s", "um_s": "um_s"}


@dataclass
class Proposal:
    """A proposed map and what it left undecided.

    Attributes:
        column_map: the JSON object of the map (LR2); a column whose quantity is undecided has
            ``"quantity": null``, which the map reader refuses until it is set.
        undecided: one line per open question (``channel ai3: unknown quantity, set
            quantity``).
        sample_rate_hz: 1 / the median step of the time variable, Hz, or None.
    """

    column_map: dict[str, Any]
    undecided: list[str] = field(default_factory=list)
    sample_rate_hz: float | None = None
    """The median sample rate of the time variable, Hz, when there is one."""


def _split_unit(name: str) -> tuple[str, str]:
    """``("force", "mn")`` for ``force_mN``: the stem and the unit suffix in lower case."""
    leaf = re.split(r"[./]", name)[-1].lower()
    for unit in sorted({*UNIT_WORDS, *(u for units in COLUMN_UNITS.values() for u in units)},
                       key=len, reverse=True):
        if leaf.endswith("_" + unit) and len(leaf) > len(unit) + 1:
            return leaf[:-len(unit) - 1], UNIT_WORDS.get(unit, unit)
    return leaf, ""


def guess_quantity(name: str) -> tuple[str | None, str]:
    """The quantity and unit a variable's name suggests, ``(None, unit)`` when none."""
    stem, unit = _split_unit(name)
    words = re.sub(r"[^a-z0-9]+", "", stem)
    for quantity, pattern in NAME_QUANTITY:
        if re.fullmatch(pattern, words):
            return quantity, unit
    if unit == "counts":
        return "x", unit
    for quantity, units in COLUMN_UNITS.items():  # the unit alone: mN is a force
        if unit in units and quantity in ("t", "voltage", "frequency"):
            return quantity, unit
    return None, unit


def propose(lab: LabFile) -> Proposal:
    """A column map for ``lab`` and the list of what it could not decide."""
    variables = lab.variables()
    lengths = [int(np.prod(s)) for s in variables.values()
               if len([n for n in s if n != 1]) == 1]
    samples = max(lengths, default=0)
    columns: dict[str, Any] = {}
    undecided: list[str] = []
    taken: dict[str, str] = {}
    result: dict[str, Any] = {"hcard_column_map": MAP_VERSION}
    rate: float | None = None
    for name, shape in variables.items():
        if int(np.prod(shape)) != samples or samples < 2:
            continue
        quantity, unit = guess_quantity(name)
        if quantity is not None and quantity in taken:
            undecided.append(f"channel {name}: {quantity} is already {taken[quantity]}, set "
                             "quantity")
            quantity = None
        entry: dict[str, Any] = {"quantity": quantity}
        if quantity is None and unit in COLUMN_UNITS["fn"]:
            entry["unit"] = unit
            undecided.append(f"channel {name}: a force ({unit}), set quantity fn or fl")
        elif quantity is None:
            undecided.append(f"channel {name}: unknown quantity, set quantity")
        else:
            taken[quantity] = name
        if unit == "counts" and quantity in ("x", "y", None):
            entry["unit"] = "counts"
            values = lab.array(name)
            wrap = _wrap_of(values)
            if wrap is not None:
                entry["wrap"] = wrap
            undecided.append(f"channel {name}: counts, set counts_per_mm")
        elif quantity not in (None, "stroke"):
            assert quantity is not None
            if unit in COLUMN_UNITS[quantity]:
                entry["unit"] = unit
            else:
                si = next(u for u, f in COLUMN_UNITS[quantity].items() if f == 1.0)
                entry["unit"] = si
                undecided.append(f"channel {name}: no unit in the name, set unit (proposed "
                                 f"{si})")
        columns[name] = entry
    result["columns"] = columns
    if "t" in taken:
        t = lab.array(taken["t"]) * COLUMN_UNITS["t"][columns[taken["t"]]["unit"]]
        steps = np.diff(t)
        if steps.size and np.all(steps > 0):
            rate = float(1.0 / np.median(steps))
    else:
        undecided.append("time base: no time variable, set sample_rate_hz")
    for quantity in ("fn", "fl"):
        if quantity not in taken:
            undecided.append(f"{quantity}: no channel found, set a channel's quantity to "
                             f"{quantity}")
    if "amplitude" not in taken and "voltage" not in taken:
        undecided.append("actuation: no amplitude or voltage channel found")
    if "speed" not in taken and "x" in taken:
        result["derive"] = {"speed": "x"}
    result["labels"] = {"device": {"value": "SET-ME"}}
    undecided.append("labels.device: set the device's name")
    return Proposal(result, undecided, rate)


def _wrap_of(values: np.ndarray) -> int | None:
    """2^bits for counts within 0..2^bits-1 (8, 12, 16, 24 or 32 bits) that jump by more than
    half the range somewhere (a wrap), else None."""
    if values.size < 2 or values.min() < 0 or np.any(values != np.round(values)):
        return None
    for bits in (8, 12, 16, 24, 32):
        wrap = 1 << bits
        if values.max() < wrap:
            return wrap if np.any(np.abs(np.diff(values)) > wrap / 2) else None
    return None
