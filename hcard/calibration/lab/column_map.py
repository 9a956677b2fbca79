"""A column map: how one rig's files hold the quantities of a measurement (spec/lab-recordings.md
LR2-LR8).

A map is a JSON file, one per rig, read by :func:`read_column_map`. Each column (or variable)
of the lab's file gets a quantity, a unit, a gain and an offset; the value in SI units is
``(U(raw) - offset) * gain * unit_factor`` (LR4), where ``U`` unwraps a wrapping counter (LR5).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Any

from hcard.calibration.lab.errors import ColumnMapError
from hcard.json_file import read_json_file
from hcard.quantities import COLUMN_UNITS

MAP_VERSION = 1
"""The value of a map's ``hcard_column_map`` key (LR2)."""
QUANTITIES = ("t", "fn", "fl", "amplitude", "voltage", "x", "y", "speed", "frequency", "stroke")
"""The quantities a column may carry (LR3), besides ``ignore``."""
IGNORE = "ignore"
COUNTS = "counts"
"""The unit of an encoder's counts, for ``x`` and ``y`` with ``counts_per_mm`` (LR5)."""
M_PER_MM = 1e-3
LABEL_KEYS = ("participant", "session", "device", "probe", "surface")
"""Labels a map may set, each a string put into the measurement's conditions (LR8)."""
DERIVABLE = {"speed": ("x", "y")}
"""Derived quantity -> the quantities it may be derived from (LR7)."""
MAP_KEYS = {"hcard_column_map", "columns", "sample_rate_hz", "start_s", "derive", "labels",
            "conditions", "delimiter"}
COLUMN_KEYS = {"quantity", "unit", "gain", "offset", "wrap", "counts_per_mm"}
DELIMITERS = (",", "\t", ";")
MAX_COLUMNS = 256
"""Most columns a map may name (LR11)."""
MAX_NAME_CHARS = 256
"""Longest variable name or label pattern, characters (LR11)."""


@dataclass(frozen=True)
class ColumnSpec:
    """How one lab column becomes a measurement column.

    Attributes:
        name: the column's name in the file (a CSV header, a ``.mat`` variable or
            ``struct.field``, an HDF5 dataset path).
        quantity: one of :data:`QUANTITIES`, or ``"ignore"``.
        unit: the unit of ``(U(raw) - offset) * gain``, an MF3 suffix (``"mn"``, ``"um"``),
            ``"counts"`` for a counter, ``""`` for ``stroke`` and ``ignore``.
        unit_factor: the unit's exact factor to SI (``1e-3`` for ``mn``; ``1e-3 /
            counts_per_mm`` for counts), dimensionless.
        gain: multiplies the raw value after the offset (e.g. N per V), finite, non-zero.
        offset: subtracted from the raw value, in the raw value's own unit (e.g. V).
        wrap: a counter's modulus (65536 for a 16-bit counter), or None.
    """

    name: str
    quantity: str
    unit: str = ""
    unit_factor: float = 1.0
    gain: float = 1.0
    offset: float = 0.0
    wrap: int | None = None


@dataclass(frozen=True)
class LabelSource:
    """Where a label's text comes from (LR8): exactly one of a constant ``value``, a string
    ``variable`` of the file, or a ``filename`` regular expression whose first group (or the
    group named ``value``) is the label."""

    value: str | None = None
    variable: str | None = None
    filename: str | None = None


@dataclass(frozen=True)
class ColumnMap:
    """A rig's column map (spec/lab-recordings.md LR2).

    Attributes:
        columns: by name in the file.
        sample_rate_hz: the sample rate of a file without a time column, Hz, or None.
        start_s: the time of the first sample when ``sample_rate_hz`` gives the time, s.
        derive: derived quantity -> the quantity it is computed from (``{"speed": "x"}``).
        labels: label key -> its source.
        conditions: further sidecar keys (spec/measurement-format.md MF9), as written.
        delimiter: a CSV/TSV file's separator, or None to tell it by suffix and header (LR9).
        source: the map's file, for messages.
    """

    columns: dict[str, ColumnSpec]
    sample_rate_hz: float | None = None
    start_s: float = 0.0
    derive: dict[str, str] = field(default_factory=dict)
    labels: dict[str, LabelSource] = field(default_factory=dict)
    conditions: dict[str, Any] = field(default_factory=dict)
    delimiter: str | None = None
    source: str = ""

    def by_quantity(self) -> dict[str, ColumnSpec]:
        """The columns that carry a quantity (not ``ignore``), by quantity."""
        return {c.quantity: c for c in self.columns.values() if c.quantity != IGNORE}


def read_column_map(path: str | os.PathLike[str]) -> ColumnMap:
    """Read and check the column map in the JSON file ``path``.

    Raises:
        ColumnMapError: the file is missing, too large, not JSON, or breaks LR2-LR8 (an
            unknown quantity or unit, a gain that is not a finite non-zero number, ...).
    """
    data = read_json_file(path, ColumnMapError, what="a column map", named="a column map",
                          label="column map")
    return parse_column_map(data, str(path))


def parse_column_map(data: Any, source: str = "column map") -> ColumnMap:
    """The :class:`ColumnMap` of the JSON value ``data`` (LR2-LR8); ``source`` names it in
    errors.

    Raises:
        ColumnMapError: naming ``source`` and the field.
    """
    if not isinstance(data, dict):
        raise ColumnMapError(f"{source}: a column map is a JSON object")
    unknown = sorted(set(data) - MAP_KEYS)
    if unknown:
        raise ColumnMapError(f"{source}: {unknown[0]}: unknown key (known: "
                             f"{', '.join(sorted(MAP_KEYS))})")
    if data.get("hcard_column_map") != MAP_VERSION:
        raise ColumnMapError(f"{source}: hcard_column_map: must be {MAP_VERSION} (the map "
                             "format's version)")
    columns_data = data.get("columns")
    if not isinstance(columns_data, dict) or not columns_data:
        raise ColumnMapError(f"{source}: columns: must be a non-empty object")
    if len(columns_data) > MAX_COLUMNS:
        raise ColumnMapError(f"{source}: columns: {len(columns_data)} columns, more than "
                             f"{MAX_COLUMNS}")
    columns = {name: _column(name, spec, source) for name, spec in columns_data.items()}
    seen: dict[str, str] = {}
    for spec in columns.values():
        if spec.quantity != IGNORE and spec.quantity in seen:
            raise ColumnMapError(f"{source}: columns.{spec.name}: quantity {spec.quantity!r} "
                                 f"is already that of column {seen[spec.quantity]!r}")
        seen[spec.quantity] = spec.name
    rate = _optional_number(data, "sample_rate_hz", source, positive=True)
    start = _optional_number(data, "start_s", source) or 0.0
    if rate is not None and "t" in seen:
        raise ColumnMapError(f"{source}: sample_rate_hz: the map has a time column "
                             f"({seen['t']!r}); give one time base, not both")
    if rate is None and "t" not in seen:
        raise ColumnMapError(f"{source}: no time base: map a column to quantity 't' or give "
                             "sample_rate_hz")
    derive = _derive(data.get("derive", {}), seen, source)
    labels = _labels(data.get("labels", {}), source)
    conditions = data.get("conditions", {})
    if not isinstance(conditions, dict):
        raise ColumnMapError(f"{source}: conditions: must be an object of sidecar keys")
    delimiter = data.get("delimiter")
    if delimiter is not None and delimiter not in DELIMITERS:
        raise ColumnMapError(f"{source}: delimiter: {delimiter!r} is not one of "
                             f"{', '.join(repr(d) for d in DELIMITERS)}")
    return ColumnMap(columns, rate, start, derive, labels, dict(conditions), delimiter, source)


def _column(name: str, spec: Any, source: str) -> ColumnSpec:
    where = f"{source}: columns.{name}"
    if not name or len(name) > MAX_NAME_CHARS:
        raise ColumnMapError(f"{where}: a column name has 1 to {MAX_NAME_CHARS} characters")
    if not isinstance(spec, dict):
        raise ColumnMapError(f"{where}: must be an object with a 'quantity'")
    unknown = sorted(set(spec) - COLUMN_KEYS)
    if unknown:
        raise ColumnMapError(f"{where}.{unknown[0]}: unknown key (known: "
                             f"{', '.join(sorted(COLUMN_KEYS))})")
    quantity = spec.get("quantity")
    if quantity is None:
        raise ColumnMapError(f"{where}.quantity: not set; set quantity (one of "
                             f"{', '.join(QUANTITIES)}, or 'ignore')")
    if quantity != IGNORE and quantity not in QUANTITIES:
        raise ColumnMapError(f"{where}.quantity: unknown quantity {quantity!r} (known: "
                             f"{', '.join(QUANTITIES)}, ignore)")
    gain = _number(spec, "gain", 1.0, where)
    offset = _number(spec, "offset", 0.0, where)
    if gain == 0.0:
        raise ColumnMapError(f"{where}.gain: must not be 0")
    wrap = spec.get("wrap")
    if wrap is not None and (isinstance(wrap, bool) or not isinstance(wrap, int) or wrap < 2):
        raise ColumnMapError(f"{where}.wrap: must be an integer of at least 2 (65536 for a "
                             "16-bit counter)")
    unit = spec.get("unit", "")
    if not isinstance(unit, str):
        raise ColumnMapError(f"{where}.unit: must be a string")
    if quantity in (IGNORE, "stroke"):
        if unit:
            raise ColumnMapError(f"{where}.unit: {quantity} has no unit")
        return ColumnSpec(name, quantity, "", 1.0, gain, offset, wrap)
    if unit == COUNTS:
        if quantity not in ("x", "y"):
            raise ColumnMapError(f"{where}.unit: 'counts' is a unit of x and y only")
        per_mm = _number(spec, "counts_per_mm", math.nan, where)
        if not per_mm > 0.0:
            raise ColumnMapError(f"{where}.counts_per_mm: a counter needs counts_per_mm, a "
                                 "positive number")
        return ColumnSpec(name, quantity, unit, M_PER_MM / per_mm, gain, offset, wrap)
    if "counts_per_mm" in spec:
        raise ColumnMapError(f"{where}.counts_per_mm: only with unit 'counts'")
    units = COLUMN_UNITS[quantity]
    if unit not in units:
        raise ColumnMapError(f"{where}.unit: unknown unit {unit!r} for {quantity} (known: "
                             f"{', '.join(units)}{', counts' if quantity in ('x', 'y') else ''})")
    return ColumnSpec(name, quantity, unit, units[unit], gain, offset, wrap)


def _number(spec: dict[str, Any], key: str, default: float, where: str) -> float:
    value = spec.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (
            key in spec and not math.isfinite(value)):
        raise ColumnMapError(f"{where}.{key}: must be a finite number, not {value!r}")
    return float(value)


def _optional_number(data: dict[str, Any], key: str, source: str,
                     positive: bool = False) -> float | None:
    if key not in data:
        return None
    value = _number(data, key, 0.0, source + ":")
    if positive and value <= 0.0:
        raise ColumnMapError(f"{source}: {key}: must be positive")
    return value


def _derive(data: Any, quantities: dict[str, str], source: str) -> dict[str, str]:
    if not isinstance(data, dict):
        raise ColumnMapError(f"{source}: derive: must be an object such as {{\"speed\": \"x\"}}")
    for target, origin in data.items():
        if target not in DERIVABLE:
            raise ColumnMapError(f"{source}: derive.{target}: only "
                                 f"{', '.join(DERIVABLE)} can be derived")
        if origin not in DERIVABLE[target]:
            raise ColumnMapError(f"{source}: derive.{target}: derived from one of "
                                 f"{', '.join(DERIVABLE[target])}, not {origin!r}")
        if target in quantities:
            raise ColumnMapError(f"{source}: derive.{target}: column {quantities[target]!r} "
                                 f"already records {target}; derive it only when it is absent")
        if origin not in quantities:
            raise ColumnMapError(f"{source}: derive.{target}: no column is {origin!r}")
    return dict(data)


def _labels(data: Any, source: str) -> dict[str, LabelSource]:
    if not isinstance(data, dict):
        raise ColumnMapError(f"{source}: labels: must be an object")
    labels = {}
    for key, spec in data.items():
        where = f"{source}: labels.{key}"
        if key not in LABEL_KEYS:
            raise ColumnMapError(f"{where}: unknown label (known: {', '.join(LABEL_KEYS)})")
        if isinstance(spec, str):
            spec = {"value": spec}
        if not isinstance(spec, dict) or len(spec) != 1 or not set(spec) <= {
                "value", "variable", "filename"}:
            raise ColumnMapError(f"{where}: one of {{\"value\": ...}}, {{\"variable\": ...}} "
                                 "or {\"filename\": REGEX}")
        (kind, text), = spec.items()
        if not isinstance(text, str) or not text or len(text) > MAX_NAME_CHARS:
            raise ColumnMapError(f"{where}.{kind}: a string of 1 to {MAX_NAME_CHARS} characters")
        if kind == "filename":
            try:
                pattern = re.compile(text)
            except re.error as exc:
                raise ColumnMapError(f"{where}.filename: bad regular expression ({exc})") from None
            if not pattern.groups:
                raise ColumnMapError(f"{where}.filename: the pattern needs a group (...) that "
                                     "holds the label")
        labels[key] = LabelSource(**{kind: text})
    return labels
