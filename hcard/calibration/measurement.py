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
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath
from typing import Any

import numpy as np

from hcard.atomic import atomic_outputs, write_atomically_together
from hcard.csv_rows import format_rows, numeric_table, read_csv_text
from hcard.errors import InputError
from hcard.json_file import read_json_file
from hcard.quantities import COLUMN_UNITS
from hcard.terminal_text import clipped

#: The SI unit suffix each quantity is written in by :func:`write_measurement`.
SI_SUFFIX = {quantity: next(s for s, scale in units.items() if scale == 1.0)
             for quantity, units in COLUMN_UNITS.items()}
#: Columns without a unit, named exactly (rules MF3, MF12): name -> integer values only.
UNITLESS: dict[str, bool] = {
    "stroke": True,
    "contact": True,
    "sequence": True,
    "texture": True,
    "faults": True,
    "flags": True,
    "target_uv": False,
    "target_ev": False,
}
#: Column quantity -> :class:`Measurement` attribute (the others go to ``Measurement.device``).
ATTRIBUTE = {
    "t": "t", "amplitude": "amplitude", "voltage": "voltage", "x": "x", "y": "y",
    "speed": "speed", "fn": "normal_force", "fl": "lateral_force", "stroke": "stroke",
    "frequency": "plate_frequency", "contact": "contact",
}
#: Device columns (rule MF12), kept by quantity name in ``Measurement.device``, in writing order.
DEVICE_COLUMNS = (
    "sequence", "f_tl", "f_tr", "f_bl", "f_br", "current", "target_uv", "target_ev", "texture",
    "faults", "flags", "echo",
)
REQUIRED = ("t", "fn", "fl")
CONTACT_THRESHOLD_N = 0.01
"""Samples whose normal force is below this are out of contact, N (rule MS2)."""
ACTUATION = ("amplitude", "voltage")
#: Sidecar keys with a checked type; other keys are kept as they are (rule MF9).
SIDECAR_STRINGS = ("device", "surface", "participant", "probe", "notes", "voltage_form")
SIDECAR_NUMBERS = ("plate_frequency_hz", "ambient_pressure_pa", "temperature_c",
                   "relative_humidity", "carrier_frequency_hz")
SIDECAR_OBJECTS = ("limits", "limits_at_start", "card", "profile", "session", "firmware")
FILE_REFERENCES = (("card", "path"), ("session", "track"))
"""Sidecar keys that name a file (rule MF13): the card played and its finger track, each
relative to the sidecar's folder and inside it."""
VOLTAGE_FORMS = ("instantaneous", "envelope")
"""Values of the sidecar key ``voltage_form``: the voltage column is the instantaneous voltage
(the default) or the peak envelope of a sinusoidal carrier at ``carrier_frequency_hz``."""


class MeasurementError(InputError):
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
        contact: True where a finger touches the surface (the device's own contact sensing,
            column ``contact``), or None (contact is then read from the normal force, MS2).
        device: the device columns of rule MF12 by quantity name (``sequence``, ``faults``,
            ``target_uv``, ``current``, ``f_tl``, ``echo``, ...), SI units, each shape (M,).
        conditions: the JSON sidecar (device, plate frequency, surface, ...).
        files: the files the sidecar names (rule MF13) by key (``"card.path"``,
            ``"session.track"``), resolved against the sidecar's folder; only those it names.
        source: the file it was read from, for messages ("" for one made in memory).
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
    contact: np.ndarray | None = None
    device: dict[str, np.ndarray] = field(default_factory=dict)
    conditions: dict[str, Any] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict, init=False)
    source: str = field(default="", compare=False)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def regressors(self) -> dict[str, np.ndarray]:
        """The named arrays present (SI units), in column order; absent optional ones omitted.

        Keys: ``t`` (s), ``amplitude`` (m), ``voltage`` (V), ``x``, ``y`` (m), ``speed`` (m/s),
        ``normal_force``, ``lateral_force`` (N), ``stroke`` (-), ``plate_frequency`` (Hz),
        ``contact`` (0 or 1).
        """
        out: dict[str, np.ndarray] = {}
        for quantity in ATTRIBUTE:
            value = getattr(self, ATTRIBUTE[quantity])
            if value is not None:
                out[ATTRIBUTE[quantity]] = value
        return out

    def column(self, quantity: str) -> np.ndarray | None:
        """A column by its quantity name (rules MF3, MF12: ``fn``, ``fl``, ``amplitude``,
        ``faults``, ``target_uv``, ...), SI units; None when the recording has none."""
        if quantity in ATTRIBUTE:
            return getattr(self, ATTRIBUTE[quantity])
        if quantity in DEVICE_COLUMNS:
            return self.device.get(quantity)
        raise KeyError(f"{quantity!r} is not a quantity of the measurement format")

    @property
    def in_contact(self) -> np.ndarray:
        """Per sample, a finger touches (rule MS2): the ``contact`` column where there is one,
        and a normal force of at least :data:`CONTACT_THRESHOLD_N`."""
        pressing = self.normal_force >= CONTACT_THRESHOLD_N
        return pressing if self.contact is None else pressing & self.contact

    @property
    def voltage_form(self) -> str:
        """``"envelope"`` when the voltage column is the peak envelope of a carrier (sidecar
        ``voltage_form``), else ``"instantaneous"``."""
        return str(self.conditions.get("voltage_form", "instantaneous"))


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The sidecar of ``path``: the CSV's file name with ``.json`` appended (rule MF8)."""
    file = Path(path)
    return file.with_name(file.name + ".json")


def _split_header(name: str, source: str, line: int) -> tuple[str, float]:
    """The quantity of a header name and its scale to SI, or raise for an unknown unit."""
    if name in UNITLESS:
        return name, 1.0
    for quantity in sorted(COLUMN_UNITS, key=len, reverse=True):
        if name.startswith(quantity + "_"):
            unit = name[len(quantity) + 1:]
            if unit not in COLUMN_UNITS[quantity]:
                accepted = ", ".join(f"{quantity}_{u}" for u in COLUMN_UNITS[quantity])
                raise MeasurementError(
                    f"{source}:{line}: column {name!r}: unknown unit {unit!r} for {quantity} "
                    f"(accepted: {accepted})"
                )
            return quantity, COLUMN_UNITS[quantity][unit]
    raise MeasurementError(
        f"{source}:{line}: column {name!r} is not a known quantity "
        f"(known: {', '.join(_known_names())})"
    )


def _known_names() -> list[str]:
    """The quantities of rules MF3 and MF12, for error messages."""
    return [*ATTRIBUTE, *DEVICE_COLUMNS]


def read_measurement(path: str | os.PathLike[str]) -> Measurement:
    """Read a recording and its sidecar (spec/measurement-format.md).

    Raises:
        MeasurementError: the file or sidecar is missing or unreadable, a required column is
            missing, a unit is unknown, a cell is not a number, a value is NaN or infinite,
            time does not increase strictly, or the sidecar is not a valid JSON object.
    """
    file = Path(path)
    text = read_csv_text(file, MeasurementError)
    side = sidecar_path(file)
    conditions = _read_sidecar(side)
    files = referenced_files(conditions, side)
    measurement = _parse(text, str(file), conditions)
    measurement.files = files
    measurement.source = str(file)
    return measurement


def referenced_files(conditions: dict[str, Any], sidecar: Path) -> dict[str, Path]:
    """The files the sidecar ``conditions`` name (:data:`FILE_REFERENCES`, rule MF13),
    resolved against the folder of the ``sidecar`` file.

    Raises:
        MeasurementError: a reference is not a string, is an absolute path, or leads out of
            the sidecar's folder (``../../etc``, or through a symbolic link), naming the key.
    """
    folder = sidecar.parent if str(sidecar.parent) else Path(".")
    home = folder.resolve()
    files: dict[str, Path] = {}
    for section, key in FILE_REFERENCES:
        holder = conditions.get(section)
        value = holder.get(key) if isinstance(holder, dict) else None
        if value is None:
            continue
        where = f"{sidecar}: {section}.{key}"
        if not isinstance(value, str) or not value:
            raise MeasurementError(f"{where}: must be a file name or null")
        if Path(value).is_absolute() or PureWindowsPath(value).is_absolute():
            raise MeasurementError(f"{where}: {clipped(value)!r} is an absolute path; a sidecar "
                                   "names its files relative to its own folder (rule MF13)")
        resolved = (folder / value).resolve()
        if not resolved.is_relative_to(home):
            raise MeasurementError(f"{where}: {clipped(value)!r} lies outside the sidecar's "
                                   f"folder {folder} (rule MF13)")
        files[f"{section}.{key}"] = resolved
    return files


def _relative_references(conditions: dict[str, Any], sidecar: Path) -> dict[str, Any]:
    """``conditions`` with each file reference (:data:`FILE_REFERENCES`), given as a path from
    the working directory, rewritten relative to the ``sidecar``'s folder; a file outside it
    becomes null (rule MF13: a reader refuses references outside the folder)."""
    folder = (sidecar.parent if str(sidecar.parent) else Path(".")).resolve()
    written = dict(conditions)
    for section, key in FILE_REFERENCES:
        holder = written.get(section)
        if not isinstance(holder, dict) or not isinstance(holder.get(key), str):
            continue
        target = Path(holder[key]).resolve()
        relative = target.relative_to(folder).as_posix() if target.is_relative_to(folder) else None
        written[section] = {**holder, key: relative}
    return written


def _read_sidecar(path: Path) -> dict[str, Any]:
    source = str(path)
    data = read_json_file(path, MeasurementError, what="a conditions sidecar",
                          named="the conditions sidecar", label="sidecar",
                          missing="the conditions sidecar")
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
    for key in SIDECAR_OBJECTS:
        if key in data and data[key] is not None and not isinstance(data[key], dict):
            raise MeasurementError(
                f"{source}: bad sidecar JSON (key {key!r} must be an object or null)"
            )
    form = data.get("voltage_form", "instantaneous")
    if form not in VOLTAGE_FORMS:
        raise MeasurementError(
            f"{source}: bad sidecar JSON (key 'voltage_form' is {form!r}; expected "
            f"{' or '.join(repr(f) for f in VOLTAGE_FORMS)})"
        )
    if form == "envelope" and not data.get("carrier_frequency_hz"):
        raise MeasurementError(
            f"{source}: bad sidecar JSON (an 'envelope' voltage needs 'carrier_frequency_hz')"
        )
    return data


def _parse(text: str, source: str, conditions: dict[str, Any]) -> Measurement:
    columns: dict[str, tuple[int, float, str]] = {}

    def check_header(names: list[str], header_line: int) -> None:
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

    _, _, table, lines = numeric_table(text, source, MeasurementError, check_header)
    if not table.shape[0]:
        raise MeasurementError(f"{source}: no samples after the header")
    values: dict[str, np.ndarray] = {}
    for quantity, (position, scale, name) in columns.items():
        raw = table[:, position]
        _check_finite(raw, lines, name, source)
        if UNITLESS.get(quantity, False):
            fractional = np.flatnonzero(raw != np.round(raw))
            if fractional.size:
                i = int(fractional[0])
                raise MeasurementError(
                    f"{source}:{lines[i]}: column {name}: {float(raw[i])!r} is not an integer"
                )
            if quantity == "contact" and np.any((raw != 0) & (raw != 1)):
                i = int(np.flatnonzero((raw != 0) & (raw != 1))[0])
                raise MeasurementError(
                    f"{source}:{lines[i]}: column contact: {float(raw[i])!r} is neither 0 nor 1"
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
    kwargs: dict[str, Any] = {ATTRIBUTE[q]: v for q, v in values.items() if q in ATTRIBUTE}
    if "contact" in kwargs:
        kwargs["contact"] = kwargs["contact"].astype(bool)
    device = {q: values[q] for q in DEVICE_COLUMNS if q in values}
    return Measurement(conditions=conditions, device=device, **kwargs)


def _check_finite(raw: np.ndarray, lines: np.ndarray, name: str, source: str) -> None:
    """Reject NaN (or empty) cells and infinities: a lone NaN and a NaN run both (rule MF6)."""
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


def _present_columns(m: Measurement) -> list[tuple[str, np.ndarray]]:
    """The columns ``m`` holds, by quantity name, in writing order: the columns of rule MF3
    first, then the device columns of rule MF12."""
    present: list[tuple[str, np.ndarray]] = [
        (q, getattr(m, ATTRIBUTE[q])) for q in ATTRIBUTE if getattr(m, ATTRIBUTE[q]) is not None
    ]
    return present + [(q, m.device[q]) for q in DEVICE_COLUMNS if q in m.device]


def _csv_header(m: Measurement) -> str:
    """The header line of ``m``'s CSV, SI unit suffixes (``t_s``, ``amplitude_m``, ...)."""
    names = [q if q in UNITLESS else f"{q}_{SI_SUFFIX[q]}" for q, _ in _present_columns(m)]
    return ",".join(names) + "\n"


def _csv_rows(m: Measurement) -> str:
    """The data lines of ``m``'s CSV, full precision (``repr``), each ending in a newline; the
    columns without a unit (rule MF3, MF12) as integers."""
    return format_rows([
        (q, np.asarray(values).astype(np.int64 if UNITLESS.get(q, False) else np.float64))
        for q, values in _present_columns(m)])


def measurement_to_csv(m: Measurement) -> str:
    """The CSV text of ``m`` in SI column units (``t_s``, ``amplitude_m``, ...), full precision;
    the columns of rule MF3 first, then the device columns of rule MF12."""
    return _csv_header(m) + _csv_rows(m)


def _sidecar_text(conditions: dict[str, Any]) -> str:
    """The sidecar's JSON text; ValueError for NaN or infinity, TypeError for a value JSON
    cannot hold."""
    return json.dumps(conditions, indent=2, sort_keys=True, allow_nan=False) + "\n"


def write_measurement(m: Measurement, path: str | os.PathLike[str]) -> None:
    """Write ``m`` as a CSV and its sidecar, together atomically; reading it back gives equal
    arrays.

    Raises ``ValueError`` (before writing anything) when the conditions hold NaN or infinity,
    and ``TypeError`` when they are not JSON-serialisable. Columns are written in SI units
    with ``repr`` precision, so the round trip is exact.
    """
    csv_bytes = measurement_to_csv(m).encode("utf-8")
    sidecar = _sidecar_text(_relative_references(m.conditions, sidecar_path(path)))
    # Both texts are built before either file is touched, and the files replace the old ones
    # together: a bad sidecar or a failed write leaves both files as they were.
    write_atomically_together([(path, csv_bytes), (sidecar_path(path), sidecar.encode("utf-8"))])


def write_measurement_blocks(blocks: Iterable[Measurement], conditions: dict[str, Any],
                             path: str | os.PathLike[str]) -> int:
    """Write a recording given as consecutive blocks of samples (each a :class:`Measurement`
    with the same columns; their own conditions are ignored) and its sidecar ``conditions``,
    the two files together atomically, holding one block in memory at a time; returns the rows
    written.

    The file is the one :func:`write_measurement` writes for the blocks joined. Raises
    ``ValueError`` (before writing anything) when the conditions hold NaN or infinity, or when
    there is no block or the blocks' columns differ (then the CSV is left as it was), and
    ``TypeError`` when the conditions are not JSON-serialisable.
    """
    sidecar = _sidecar_text(_relative_references(conditions, sidecar_path(path)))
    rows = 0
    header: str | None = None
    # the CSV and the sidecar replace the old pair together (hcard.atomic.atomic_outputs): a
    # sidecar that cannot be written no longer leaves a new CSV beside the old sidecar
    with atomic_outputs([path, sidecar_path(path)]) as (out, side):
        for block in blocks:
            block_header = _csv_header(block)
            if header is None:
                header = block_header
                out.write(header.encode("utf-8"))
            elif block_header != header:
                raise ValueError(f"a block has the columns {block_header.strip()!r}, "
                                 f"the recording {header.strip()!r}")
            out.write(_csv_rows(block).encode("utf-8"))
            rows += len(block)
        if header is None:
            raise ValueError("no samples to write")
        side.write(sidecar.encode("utf-8"))
    return rows
