"""Telling a lab file's type from its content (spec/lab-recordings.md LR9)."""

from __future__ import annotations

import os
from pathlib import Path

from hcard.calibration.lab.errors import LabRecordingError
from hcard.file_errors import reading

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
HDF5_OFFSETS = (0, 512, 1024, 2048)
"""Where an HDF5 superblock may start (0, or a user block of 512 bytes times a power of 2;
MATLAB v7.3 writes a 512-byte header first)."""
MAT_HEADER = b"MATLAB "
MAT_SUFFIXES = (".mat",)
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf", ".he5", ".nc")
LAB_SUFFIXES = (*MAT_SUFFIXES, *HDF5_SUFFIXES, ".csv", ".tsv", ".tab", ".txt")
"""Files ``hcard calibrate --map`` takes from a directory."""


def file_kind(path: str | os.PathLike[str]) -> str:
    """``"hdf5"`` (HDF5, or MATLAB v7.3), ``"mat73"`` (HDF5 with a MATLAB header), ``"mat"``
    (MATLAB v4-v7) or ``"delimited"`` (text), from the first 2056 bytes and the suffix."""
    with reading(path, LabRecordingError, "a recording"), open(path, "rb") as stream:
        head = stream.read(HDF5_OFFSETS[-1] + len(HDF5_SIGNATURE))
    hdf5 = any(head[o:o + len(HDF5_SIGNATURE)] == HDF5_SIGNATURE for o in HDF5_OFFSETS)
    if hdf5:
        return "mat73" if head.startswith(MAT_HEADER) else "hdf5"
    if head.startswith(MAT_HEADER) or Path(path).suffix.lower() in MAT_SUFFIXES:
        return "mat"
    if Path(path).suffix.lower() in HDF5_SUFFIXES:
        raise LabRecordingError(f"{path}: named as HDF5 but has no HDF5 signature")
    return "delimited"
