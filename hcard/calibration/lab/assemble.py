"""A lab file read through its column map, as the :class:`Measurement` the project's own CSV
reader gives (spec/lab-recordings.md LR4-LR8, LR12)."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from hcard.calibration.lab.column_map import ColumnMap, ColumnSpec
from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.source import LabFile
from hcard.calibration.measurement import (
    ACTUATION,
    ATTRIBUTE,
    SIDECAR_NUMBERS,
    Measurement,
)


def unwrap_counts(raw: np.ndarray, wrap: int) -> np.ndarray:
    """A wrapping counter's counts made continuous (LR5): each step ``d`` between
    consecutive samples becomes ``d - wrap * round(d / wrap)`` (round half to even, so a step
    of exactly ``wrap / 2`` stays as it is), and the first sample keeps its count."""
    steps = np.diff(raw)
    steps = steps - wrap * np.round(steps / wrap)
    return np.concatenate(([raw[0]], raw[0] + np.cumsum(steps))) if raw.size else raw


def to_si(raw: np.ndarray, spec: ColumnSpec) -> np.ndarray:
    """``(U(raw) - offset) * gain * unit_factor`` (LR4), ``U`` the unwrapping of LR5 when the
    column wraps, else the identity."""
    counts = unwrap_counts(raw, spec.wrap) if spec.wrap is not None else raw
    return (counts - spec.offset) * spec.gain * spec.unit_factor


def _where(lab: LabFile, spec: ColumnSpec, index: int) -> str:
    line = getattr(lab, "line", None)
    return f"{lab.path}:{line(index)}" if line else f"{lab.path}: sample {index}"


def measurement_of(lab: LabFile, column_map: ColumnMap) -> Measurement:
    """The measurement in ``lab`` as ``column_map`` says, in SI units, its conditions the map's
    ``conditions`` and labels.

    Raises:
        LabRecordingError: a mapped variable is absent or not one column of numbers, the
            columns differ in length, a value is NaN or infinite, time does not increase, a
            required quantity is unmapped, a counter leaves its range, or a label cannot be
            found.
    """
    by_quantity = column_map.by_quantity()
    missing = [q for q in ("fn", "fl") if q not in by_quantity]
    if missing or not any(q in by_quantity for q in ACTUATION):
        need = ", ".join(missing) or "amplitude or voltage"
        raise LabRecordingError(f"{lab.path}: map {column_map.source}: no column is {need} "
                                "(rule MF5 needs fn, fl and amplitude or voltage)")
    values: dict[str, np.ndarray] = {}
    length: tuple[str, int] | None = None
    for quantity, spec in by_quantity.items():
        raw = lab.array(spec.name)
        if length is None:
            length = (spec.name, raw.size)
        elif raw.size != length[1]:
            raise LabRecordingError(f"{lab.path}: variable {spec.name!r}: {raw.size} samples, "
                                    f"{length[0]!r} has {length[1]}")
        _check_finite(lab, spec, raw)
        if spec.wrap is not None:
            outside = np.flatnonzero((raw < 0) | (raw >= spec.wrap) | (raw != np.round(raw)))
            if outside.size:
                i = int(outside[0])
                raise LabRecordingError(f"{_where(lab, spec, i)}: variable {spec.name!r}: "
                                        f"count {raw[i]!r} is not an integer in 0..{spec.wrap - 1}")
        values[quantity] = to_si(raw, spec)
    assert length is not None
    if length[1] == 0:
        raise LabRecordingError(f"{lab.path}: variable {length[0]!r}: no samples")
    if "t" not in values:
        assert column_map.sample_rate_hz is not None
        values["t"] = column_map.start_s + np.arange(length[1]) / column_map.sample_rate_hz
    _check_time(lab, by_quantity.get("t"), values["t"])
    if "stroke" in values:
        stroke = values["stroke"]
        fractional = np.flatnonzero(stroke != np.round(stroke))
        if fractional.size:
            i = int(fractional[0])
            raise LabRecordingError(f"{_where(lab, by_quantity['stroke'], i)}: variable "
                                    f"{by_quantity['stroke'].name!r}: stroke {stroke[i]!r} is "
                                    "not an integer")
        values["stroke"] = stroke.astype(np.int64)
    for target, origin in column_map.derive.items():
        values[target] = np.gradient(values[origin], values["t"]) if length[1] > 1 else \
            np.zeros(1)
    conditions = _conditions(lab, column_map)
    kwargs: dict[str, Any] = {ATTRIBUTE[q]: v for q, v in values.items()}
    measurement = Measurement(conditions=conditions, **kwargs)
    measurement.source = lab.path
    return measurement


def _check_finite(lab: LabFile, spec: ColumnSpec, raw: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(raw))
    if bad.size:
        i = int(bad[0])
        what = "NaN" if np.isnan(raw[i]) else "infinite value"
        run = f" ({bad.size} such samples)" if bad.size > 1 else ""
        raise LabRecordingError(f"{_where(lab, spec, i)}: variable {spec.name!r}: {what}"
                                f"{run}")


def _check_time(lab: LabFile, spec: ColumnSpec | None, t: np.ndarray) -> None:
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size and spec is not None:
        i = int(bad[0]) + 1
        raise LabRecordingError(f"{_where(lab, spec, i)}: variable {spec.name!r}: time not "
                                f"increasing, {float(t[i])!r} s follows {float(t[i - 1])!r} s")


def _conditions(lab: LabFile, column_map: ColumnMap) -> dict[str, Any]:
    conditions = dict(column_map.conditions)
    for key, label in column_map.labels.items():
        if label.value is not None:
            conditions[key] = label.value
        elif label.variable is not None:
            conditions[key] = lab.text(label.variable).strip()
        else:
            assert label.filename is not None
            match = re.search(label.filename, Path(lab.path).name)
            if match is None:
                raise LabRecordingError(f"{lab.path}: labels.{key}: the file name does not "
                                        f"match {label.filename!r}")
            groups = match.groupdict()
            conditions[key] = groups["value"] if "value" in groups else match.group(1)
    device = conditions.get("device")
    if not isinstance(device, str) or not device.strip():
        raise LabRecordingError(f"{lab.path}: map {column_map.source}: no device: set "
                                "labels.device or conditions.device (rule MF9)")
    for key in SIDECAR_NUMBERS:
        value = conditions.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                  or not math.isfinite(value)):
            raise LabRecordingError(f"{lab.path}: map {column_map.source}: conditions.{key}: "
                                    "must be a finite number or null")
    return conditions
