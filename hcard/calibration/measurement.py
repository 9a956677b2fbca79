"""Tribometer recordings: a CSV of named columns in stated units plus a JSON sidecar.

The format is normative in spec/measurement-format.md. :func:`read_measurement` returns a
:class:`Measurement` holding SI arrays (s, m, V, m/s, N, Hz) and the sidecar's conditions, or
raises :class:`MeasurementError` naming the file, the line and column, and the reason. A file is
never half-read: any bad cell rejects the whole recording.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hcard.atomic import write_atomically
from hcard.csv_rows import data_rows, read_csv_text
from hcard.errors import HcardError

#: Accepted unit suffixes per quantity: suffix -> scale to the SI unit (rule M4).
UNITS: dict[str, dict[str, float]] = {
    "t": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "amplitude": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9},
    "voltage": {"v": 1.0, "kv": 1e3, "mv": 1e-3},
    "x": {"m": 1.0, "mm": 1e-3, "um": 1e-6},
    "y": {"m": 1.0, "mm": 1e-3, "um": 1e-6},
    "speed": {"m_s": 1.0, "mm_s": 1e-3, "um_s": 1e-6},
    "fn": {"n": 1.0, "mn": 1e-3},
    "fl": {"n": 1.0, "mn": 1e-3},
    "frequency": {"hz": 1.0, "khz": 1e3},
}
#: The SI unit suffix each quantity is written in by :func:`write_measurement`.
SI_SUFFIX = {
    "t": "s", "amplitude": "m", "voltage": "v", "x": "m", "y": "m", "speed": "m_s",
    "fn": "n", "fl": "n", "frequency": "hz",
}
#: Column quantity -> :class:`Measurement` attribute.
ATTRIBUTE = {
    "t": "t", "amplitude": "amplitude", "voltage": "voltage", "x": "x", "y": "y",
    "speed": "speed", "fn": "normal_force", "fl": "lateral_force", "stroke": "stroke",
    "frequency": "plate_frequency",
}
REQUIRED = ("t", "fn", "fl")
ACTUATION = ("amplitude", "voltage")
#: Sidecar keys with a checked type; other keys are kept as they are (rule M9).
SIDECAR_STRINGS = ("device", "surface", "participant", "probe", "notes")
SIDECAR_NUMBERS = ("plate_frequency_hz", "ambient_pressure_pa", "temperature_c",
                   "relative_humidity")


class MeasurementError(HcardError):
    """A measurement file or its sidecar is malformed (the message names file, line, column)."""


@dataclass
class Measurement:
    """One tribometer recording in SI units.

    Attributes:
        t: sample times, s, strictly increasing, shape (M,).
        normal_force: normal force Fn, N, shape (M,).
        lateral_force: lateral (friction) force Fl, N, shape (M,).
        amplitude: plate vibration amplitude, peak-to-peak, m, or None.
        voltage: electrovibration voltage, V, or None.
        x, y: finger position, m, or None.
        speed: finger speed along the stroke (signed), m/s, or None.
        stroke: integer stroke number per sample, or None.
        plate_frequency: plate vibration frequency, Hz, or None.
        conditions: the JSON sidecar (device, plate frequency, surface, ...).
    """

    t: np.ndarray
    normal_force: np.ndarray
    lateral_force: np.ndarray
    amplitude: np.ndarray | None = None
    voltage: np.ndarray | None = None
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    speed: np.ndarray | None = None
    stroke: np.ndarray | None = None
    plate_frequency: np.ndarray | None = None
    conditions: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def regressors(self) -> dict[str, np.ndarray]:
        """The named arrays present (SI units), in column order; absent optional ones omitted.

        Keys: ``t`` (s), ``amplitude`` (m), ``voltage`` (V), ``x``, ``y`` (m), ``speed`` (m/s),
        ``normal_force``, ``lateral_force`` (N), ``stroke`` (-), ``plate_frequency`` (Hz).
        """
        out: dict[str, np.ndarray] = {}
        for quantity in ATTRIBUTE:
            value = getattr(self, ATTRIBUTE[quantity])
            if value is not None:
                out[ATTRIBUTE[quantity]] = value
        return out


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The sidecar of ``path``: the CSV's file name with ``.json`` appended (rule M8)."""
    file = Path(path)
    return file.with_name(file.name + ".json")


def _split_header(name: str, source: str, line: int) -> tuple[str, float]:
    """The quantity of a header name and its scale to SI, or raise for an unknown unit."""
    if name == "stroke":
        return "stroke", 1.0
    for quantity in sorted(UNITS, key=len, reverse=True):
        if name.startswith(quantity + "_"):
            unit = name[len(quantity) + 1:]
            if unit not in UNITS[quantity]:
                accepted = ", ".join(f"{quantity}_{u}" for u in UNITS[quantity])
                raise MeasurementError(
                    f"{source}:{line}: column {name!r}: unknown unit {unit!r} for {quantity} "
                    f"(accepted: {accepted})"
                )
            return quantity, UNITS[quantity][unit]
    raise MeasurementError(
        f"{source}:{line}: column {name!r} is not a known quantity "
        f"(known: {', '.join(ATTRIBUTE)})"
    )


def read_measurement(path: str | os.PathLike[str]) -> Measurement:
    """Read a recording and its sidecar (spec/measurement-format.md).

    Raises:
        MeasurementError: the file or sidecar is missing or unreadable, a required column is
            missing, a unit is unknown, a cell is not a number, a value is NaN or infinite,
            time does not increase strictly, or the sidecar is not a valid JSON object.
    """
    file = Path(path)
    text = read_csv_text(file, MeasurementError)
    conditions = _read_sidecar(sidecar_path(file))
    return _parse(text, str(file), conditions)


def _read_sidecar(path: Path) -> dict[str, Any]:
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MeasurementError(f"{source}: no such file (the conditions sidecar)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MeasurementError(f"{source}: cannot read ({exc})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MeasurementError(
            f"{source}:{exc.lineno}:{exc.colno}: bad sidecar JSON ({exc.msg})"
        ) from None
    if not isinstance(data, dict):
        raise MeasurementError(f"{source}: bad sidecar JSON (the top level must be an object)")
    if not isinstance(data.get("device"), str) or not data["device"].strip():
        raise MeasurementError(f"{source}: bad sidecar JSON (key 'device' must be a non-empty "
                               "string)")
    for key in SIDECAR_STRINGS:
        if key in data and not isinstance(data[key], str):
            raise MeasurementError(f"{source}: bad sidecar JSON (key {key!r} must be a string)")
    for key in SIDECAR_NUMBERS:
        value = data.get(key)
        if key in data and value is not None and (
            isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise MeasurementError(
                f"{source}: bad sidecar JSON (key {key!r} must be a finite number or null)"
            )
    return data


def _parse(text: str, source: str, conditions: dict[str, Any]) -> Measurement:
    rows = data_rows(text)
    if not rows:
        raise MeasurementError(f"{source}: empty file (no header row)")
    header_line, header = rows[0]
    names = [cell.strip() for cell in header]
    columns: dict[str, tuple[int, float, str]] = {}
    for position, name in enumerate(names):
        quantity, scale = _split_header(name, source, header_line)
        if quantity in columns:
            raise MeasurementError(
                f"{source}:{header_line}: column {name!r} duplicates "
                f"{columns[quantity][2]!r} (both are {quantity})"
            )
        columns[quantity] = (position, scale, name)
    missing = [f"{q}_{SI_SUFFIX[q]}" for q in REQUIRED if q not in columns]
    if missing:
        raise MeasurementError(
            f"{source}:{header_line}: missing column(s) {', '.join(missing)} "
            f"(found {', '.join(names)})"
        )
    if not any(q in columns for q in ACTUATION):
        raise MeasurementError(
            f"{source}:{header_line}: missing column: an actuation column "
            "(amplitude_<unit> or voltage_<unit>) is required"
        )
    body = rows[1:]
    if not body:
        raise MeasurementError(f"{source}: no samples after the header")
    lines = np.array([number for number, _ in body])
    values: dict[str, np.ndarray] = {}
    for quantity, (position, scale, name) in columns.items():
        raw = np.empty(len(body))
        for i, (number, row) in enumerate(body):
            if len(row) != len(names):
                raise MeasurementError(
                    f"{source}:{number}: row has {len(row)} fields, the header has {len(names)}"
                )
            cell = row[position].strip()
            try:
                raw[i] = float(cell) if cell else math.nan
            except ValueError:
                raise MeasurementError(
                    f"{source}:{number}: column {name}: {cell!r} is not a number"
                ) from None
        _check_finite(raw, lines, name, source)
        if quantity == "stroke":
            if not np.all(raw == np.round(raw)):
                i = int(np.flatnonzero(raw != np.round(raw))[0])
                raise MeasurementError(
                    f"{source}:{lines[i]}: column stroke: {float(raw[i])!r} is not an integer"
                )
            values[quantity] = raw.astype(np.int64)
        else:
            values[quantity] = raw * scale if scale != 1.0 else raw
    steps = np.diff(values["t"])
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise MeasurementError(
            f"{source}:{lines[i]}: column {columns['t'][2]}: non-monotonic time, "
            f"{float(values['t'][i])!r} s follows {float(values['t'][i - 1])!r} s"
        )
    kwargs = {ATTRIBUTE[q]: v for q, v in values.items()}
    return Measurement(conditions=conditions, **kwargs)


def _check_finite(raw: np.ndarray, lines: np.ndarray, name: str, source: str) -> None:
    """Reject NaN (or empty) cells and infinities: a lone NaN and a NaN run both (rule M6)."""
    nan = np.isnan(raw)
    if nan.any():
        start = int(np.flatnonzero(nan)[0])
        end = start
        while end + 1 < nan.size and nan[end + 1]:
            end += 1
        if end > start:
            raise MeasurementError(
                f"{source}:{lines[start]}: column {name}: NaN run of {end - start + 1} samples "
                f"(lines {lines[start]}-{lines[end]})"
            )
        raise MeasurementError(f"{source}:{lines[start]}: column {name}: NaN sample")
    inf = np.flatnonzero(np.isinf(raw))
    if inf.size:
        raise MeasurementError(
            f"{source}:{lines[int(inf[0])]}: column {name}: infinite value"
        )


def measurement_to_csv(m: Measurement) -> str:
    """The CSV text of ``m`` in SI column units (``t_s``, ``amplitude_m``, ...), full precision."""
    present = [(q, getattr(m, ATTRIBUTE[q])) for q in ATTRIBUTE
               if getattr(m, ATTRIBUTE[q]) is not None]
    names = ["stroke" if q == "stroke" else f"{q}_{SI_SUFFIX[q]}" for q, _ in present]
    lines = [",".join(names)]
    for i in range(len(m)):
        lines.append(",".join(
            str(int(arr[i])) if q == "stroke" else repr(float(arr[i])) for q, arr in present
        ))
    return "\n".join(lines) + "\n"


def write_measurement(m: Measurement, path: str | os.PathLike[str]) -> None:
    """Write ``m`` as a CSV and its sidecar, each atomically; reading it back gives equal arrays.

    Raises ``ValueError`` (before writing anything) when the conditions hold NaN or infinity,
    and ``TypeError`` when they are not JSON-serialisable. Columns are written in SI units
    with ``repr`` precision, so the round trip is exact.
    """
    csv_bytes = measurement_to_csv(m).encode("utf-8")
    sidecar = json.dumps(m.conditions, indent=2, sort_keys=True, allow_nan=False) + "\n"
    # Both texts are built before either file is touched: a bad sidecar leaves both files as
    # they were.
    write_atomically(path, csv_bytes)
    write_atomically(sidecar_path(path), sidecar.encode("utf-8"))
