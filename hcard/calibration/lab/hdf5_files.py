"""HDF5 files, and MATLAB v7.3 ``.mat`` files (which are HDF5), through ``h5py``
(spec/lab-recordings.md LR9-LR11). Datasets are named by their path (``data/fn``); in a v7.3
file a struct's field may also be named as in MATLAB (``data.fn``)."""

from __future__ import annotations

import os

import h5py
import numpy as np

from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.source import (
    MAX_DEPTH,
    MAX_TEXT_CHARS,
    MAX_VARIABLES,
    as_column,
    check_shape,
    matrix_column,
    missing,
    split_column,
)


class Hdf5File:
    """An HDF5 file (or a v7.3 ``.mat`` file, ``matlab=True``) opened for reading."""

    def __init__(self, path: str | os.PathLike[str], matlab: bool = False) -> None:
        self.path = str(path)
        self.matlab = matlab
        try:
            self._file = h5py.File(self.path, "r")
        except OSError as exc:
            raise LabRecordingError(f"{self.path}: not a readable HDF5 file ({exc})") from None

    def _dataset(self, name: str) -> h5py.Dataset:
        key = name.replace(".", "/") if self.matlab else name
        parts = [p for p in key.split("/") if p]
        if not parts or len(parts) > MAX_DEPTH:
            raise LabRecordingError(f"{self.path}: variable {name!r}: a path of 1 to "
                                    f"{MAX_DEPTH} names")
        node: h5py.Group | h5py.Dataset = self._file
        for depth, part in enumerate(parts):
            if not isinstance(node, h5py.Group) or part not in node:
                raise missing(self.path, name, self.variables())
            node = node[part]
            if isinstance(node, h5py.Group) and depth == len(parts) - 1:
                raise LabRecordingError(f"{self.path}: variable {name!r}: a group (holding "
                                        f"{', '.join(list(node)[:8])}); name one of its "
                                        "datasets")
        if not isinstance(node, h5py.Dataset):
            raise missing(self.path, name, self.variables())
        return node

    def variables(self) -> dict[str, tuple[int, ...]]:
        found: dict[str, tuple[int, ...]] = {}
        self._walk(self._file, "", 1, found)
        return found

    def _walk(self, group: h5py.Group, prefix: str, depth: int,
              found: dict[str, tuple[int, ...]]) -> None:
        if depth > MAX_DEPTH:
            raise LabRecordingError(f"{self.path}: group {prefix!r}: nested more than "
                                    f"{MAX_DEPTH} deep")
        for key in group:
            if len(found) >= MAX_VARIABLES:
                raise LabRecordingError(f"{self.path}: more than {MAX_VARIABLES} datasets")
            if key.startswith("#"):  # MATLAB's #refs# and #subsystem#
                continue
            item = group.get(key)
            name = f"{prefix}{'.' if self.matlab else '/'}{key}" if prefix else key
            if isinstance(item, h5py.Group):
                self._walk(item, name, depth + 1, found)
            elif isinstance(item, h5py.Dataset):
                found[name] = tuple(item.shape)

    def _is_matlab_char(self, dataset: h5py.Dataset) -> bool:
        kind = dataset.attrs.get("MATLAB_class")
        return bool(kind is not None and np.asarray(kind).tobytes().strip(b"\0") == b"char")

    def array(self, name: str) -> np.ndarray:
        base, column = split_column(name)
        if column is not None:
            matrix = self._dataset(base)
            if matrix.dtype.kind not in "biuf" or self._is_matlab_char(matrix):
                raise LabRecordingError(f"{self.path}: variable {base!r}: not real numbers")
            if matrix.ndim != 2:
                raise LabRecordingError(f"{self.path}: variable {base!r}: shape "
                                        f"{tuple(matrix.shape)} is not a matrix of samples "
                                        "by channels")
            # MATLAB v7.3 stores an N-by-k matrix transposed, as k-by-N
            value = np.asarray(matrix[()]).T if self.matlab else np.asarray(matrix[()])
            return matrix_column(self.path, base, value, column)
        dataset = self._dataset(name)
        check_shape(self.path, name, tuple(dataset.shape))
        if dataset.dtype.kind not in "biuf" or self._is_matlab_char(dataset):
            raise LabRecordingError(f"{self.path}: variable {name!r}: holds "
                                    f"{'text' if dataset.dtype.kind in 'SUO' or self._is_matlab_char(dataset) else dataset.dtype}, "  # noqa: E501
                                    "not real numbers")
        return as_column(self.path, name, dataset[()])

    def text(self, name: str) -> str:
        dataset = self._dataset(name)
        if dataset.size > MAX_TEXT_CHARS:
            raise LabRecordingError(f"{self.path}: variable {name!r}: {dataset.size} "
                                    f"characters, more than {MAX_TEXT_CHARS}")
        value = dataset[()]
        if self._is_matlab_char(dataset):
            return "".join(chr(int(c)) for c in np.asarray(value).reshape(-1))
        if isinstance(value, bytes):
            return value.decode("utf-8", "replace")
        if isinstance(value, str):
            return value
        raise LabRecordingError(f"{self.path}: variable {name!r}: not text")

    def close(self) -> None:
        self._file.close()
