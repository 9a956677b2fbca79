"""MATLAB ``.mat`` files of format v4 to v7 through ``scipy.io`` (spec/lab-recordings.md LR9,
LR10). A v7.3 file is HDF5 and is read by :mod:`hcard.calibration.lab.hdf5_files`."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import scipy.io
from scipy.io.matlab import MatReadError, mat_struct

from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.source import (
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_TEXT_CHARS,
    MAX_VARIABLES,
    as_column,
    check_shape,
    matrix_column,
    missing,
    split_column,
)


class MatFile:
    """A ``.mat`` file (v4-v7): variables by name, struct fields as ``struct.field``."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)
        size = os.path.getsize(path)
        if size > MAX_FILE_BYTES:
            raise LabRecordingError(f"{self.path}: {size} bytes, more than {MAX_FILE_BYTES} "
                                    "(a .mat file)")
        try:
            listing = scipy.io.whosmat(self.path)
        except (MatReadError, ValueError, TypeError, OSError) as exc:
            raise LabRecordingError(f"{self.path}: not a readable .mat file ({exc})") from None
        if len(listing) > MAX_VARIABLES:
            raise LabRecordingError(f"{self.path}: {len(listing)} variables, more than "
                                    f"{MAX_VARIABLES}")
        self._top = {name: (tuple(shape), kind) for name, shape, kind in listing}
        self._loaded: dict[str, Any] = {}

    def _load(self, top: str, *, matrix: bool = False) -> Any:
        if top not in self._top:
            raise missing(self.path, top, self.variables())
        shape, kind = self._top[top]
        if kind not in ("struct", "char") and not matrix:
            check_shape(self.path, top, shape)
        if top not in self._loaded:
            try:
                data = scipy.io.loadmat(self.path, variable_names=[top], squeeze_me=True,
                                        struct_as_record=False, chars_as_strings=True)
            except (MatReadError, ValueError, TypeError, OSError) as exc:
                raise LabRecordingError(f"{self.path}: variable {top!r}: cannot be read "
                                        f"({exc})") from None
            self._loaded[top] = data[top]
        return self._loaded[top]

    def _value(self, name: str, *, matrix: bool = False) -> Any:
        parts = name.split(".")
        if len(parts) > MAX_DEPTH:
            raise LabRecordingError(f"{self.path}: variable {name!r}: nested {len(parts)} "
                                    f"deep, more than {MAX_DEPTH}")
        value = self._load(parts[0], matrix=matrix)
        for depth, field in enumerate(parts[1:], start=1):
            reached = ".".join(parts[:depth])
            if isinstance(value, np.ndarray) and value.dtype == object:
                raise LabRecordingError(f"{self.path}: variable {reached!r}: a struct array "
                                        f"or cell array of {value.size}; map a variable of "
                                        "one struct")
            if not isinstance(value, mat_struct):
                raise LabRecordingError(f"{self.path}: variable {reached!r}: not a struct, "
                                        f"has no field {field!r}")
            if field not in value._fieldnames:
                raise LabRecordingError(f"{self.path}: variable {reached!r}: no field "
                                        f"{field!r} (fields: {', '.join(value._fieldnames)})")
            value = getattr(value, field)
        if isinstance(value, mat_struct):
            raise LabRecordingError(f"{self.path}: variable {name!r}: a struct (fields: "
                                    f"{', '.join(value._fieldnames)}); map a field, e.g. "
                                    f"{name}.{value._fieldnames[0]}")
        return value

    def variables(self) -> dict[str, tuple[int, ...]]:
        found: dict[str, tuple[int, ...]] = {}
        for top, (shape, kind) in self._top.items():
            if kind == "struct" and shape in ((1, 1), ()):
                self._fields(top, self._load(top), 1, found)
            else:
                found[top] = shape
        return found

    def _fields(self, prefix: str, value: mat_struct, depth: int,
                found: dict[str, tuple[int, ...]]) -> None:
        for field in value._fieldnames:
            if len(found) >= MAX_VARIABLES:
                raise LabRecordingError(f"{self.path}: more than {MAX_VARIABLES} variables "
                                        "and struct fields")
            child = getattr(value, field)
            name = f"{prefix}.{field}"
            if isinstance(child, mat_struct) and depth < MAX_DEPTH - 1:
                self._fields(name, child, depth + 1, found)
            elif not isinstance(child, mat_struct):
                found[name] = tuple(np.shape(child))

    def array(self, name: str) -> np.ndarray:
        base, column = split_column(name)
        if column is not None:
            value = self._value(base, matrix=True)
            if isinstance(value, str):
                raise LabRecordingError(f"{self.path}: variable {base!r}: text, not numbers")
            return matrix_column(self.path, base, np.asarray(value), column)
        value = self._value(name)
        if isinstance(value, str):
            raise LabRecordingError(f"{self.path}: variable {name!r}: text, not numbers")
        return as_column(self.path, name, np.asarray(value))

    def text(self, name: str) -> str:
        value = self._value(name)
        if not isinstance(value, str):
            raise LabRecordingError(f"{self.path}: variable {name!r}: not text")
        return value[:MAX_TEXT_CHARS]

    def close(self) -> None:
        self._loaded.clear()
