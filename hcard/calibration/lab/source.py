"""What the readers of lab files share: the interface of an opened file, the limits, and the
check that a variable is one column of numbers (spec/lab-recordings.md LR10, LR11)."""

from __future__ import annotations

import re
from typing import Protocol

import numpy as np

from hcard.calibration.lab.errors import LabRecordingError

MAX_SAMPLES = 20_000_000
"""Most samples a variable may hold (LR11): 5.5 hours at 1 kHz; 160 MB as float64."""
MAX_VARIABLES = 10_000
"""Most variables, groups and datasets a file may list (LR11)."""
MAX_DEPTH = 8
"""Deepest nesting of HDF5 groups or ``.mat`` struct fields a name may reach (LR11)."""
MAX_FILE_BYTES = 2 << 30
"""Largest ``.mat`` (v4-v7) file read, bytes (LR11): scipy reads a whole variable at once."""
MAX_TEXT_CHARS = 1 << 16
"""Longest string variable read as a label, characters (LR8)."""


class LabFile(Protocol):
    """An opened lab file: its variables by name, one at a time."""

    path: str

    def variables(self) -> dict[str, tuple[int, ...]]:
        """Every numeric or text variable by name, with its shape (at most
        :data:`MAX_VARIABLES`)."""
        ...

    def array(self, name: str) -> np.ndarray:
        """The variable ``name`` as a 1-D float64 array (LabRecordingError if it is absent,
        not numeric, not one column, or longer than :data:`MAX_SAMPLES`)."""
        ...

    def text(self, name: str) -> str:
        """The string variable ``name`` (for labels, LR8)."""
        ...

    def close(self) -> None:
        """Release the file."""
        ...


def check_shape(path: str, name: str, shape: tuple[int, ...]) -> int:
    """The sample count of a variable of ``shape``: one column or one row (every other axis
    of length 1); raises LabRecordingError for a matrix or more than :data:`MAX_SAMPLES`."""
    long_axes = [n for n in shape if n != 1]
    if len(long_axes) > 1:
        raise LabRecordingError(f"{path}: variable {name!r}: shape {shape} is not one column; "
                                "map one channel per variable, or a matrix's column K as "
                                "NAME(:,K)")
    count = int(np.prod(shape)) if shape else 1
    if count > MAX_SAMPLES:
        raise LabRecordingError(f"{path}: variable {name!r}: {count} samples, more than "
                                f"{MAX_SAMPLES}")
    return count


def as_column(path: str, name: str, value: np.ndarray) -> np.ndarray:
    """``value`` as a 1-D float64 array; LabRecordingError when it is not real numbers."""
    if value.dtype.kind not in "biuf":
        raise LabRecordingError(f"{path}: variable {name!r}: holds {value.dtype} values, not "
                                "real numbers")
    check_shape(path, name, tuple(value.shape))
    return np.asarray(value, dtype=np.float64).reshape(-1)


_COLUMN_OF = re.compile(r"^(?P<base>.+)\(:,\s*(?P<column>[1-9][0-9]{0,5})\)$")
"""A column of a matrix, MATLAB style and counted from 1: ``dataQ(:,2)`` (LR10)."""


def split_column(name: str) -> tuple[str, int | None]:
    """``name`` split into the variable and the column it selects, counted from 1
    (``"dataQ(:,2)"`` -> ``("dataQ", 2)``); ``(name, None)`` when it selects none."""
    found = _COLUMN_OF.match(name)
    if found is None:
        return name, None
    return found["base"], int(found["column"])


def matrix_column(path: str, name: str, value: np.ndarray, column: int) -> np.ndarray:
    """Column ``column`` (from 1) of the 2-D real matrix ``value`` (samples along axis 0) as
    a 1-D float64 array; LabRecordingError when ``value`` is not such a matrix or has fewer
    columns."""
    if value.dtype.kind not in "biuf":
        raise LabRecordingError(f"{path}: variable {name!r}: holds {value.dtype} values, not "
                                "real numbers")
    if value.ndim != 2:
        raise LabRecordingError(f"{path}: variable {name!r}: shape {tuple(value.shape)} is "
                                "not a matrix of samples by channels")
    if column > value.shape[1]:
        raise LabRecordingError(f"{path}: variable {name!r}: has {value.shape[1]} columns, "
                                f"not {column}")
    if value.shape[0] > MAX_SAMPLES:
        raise LabRecordingError(f"{path}: variable {name!r}: {value.shape[0]} samples, more "
                                f"than {MAX_SAMPLES}")
    return np.asarray(value[:, column - 1], dtype=np.float64)


def missing(path: str, name: str, known: dict[str, tuple[int, ...]]) -> LabRecordingError:
    """The error for a map that names ``name``, absent from the file."""
    listed = ", ".join(list(known)[:12]) + (", ..." if len(known) > 12 else "")
    return LabRecordingError(f"{path}: variable {name!r}: not in the file (it has: "
                             f"{listed or 'nothing'})")
