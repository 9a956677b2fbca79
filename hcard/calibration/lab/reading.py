"""The one place recordings are read: the project's CSV with its sidecar, or a lab file
through a column map (spec/lab-recordings.md LR1, LR9)."""

from __future__ import annotations

import os
from pathlib import Path

from hcard.calibration.lab.assemble import measurement_of
from hcard.calibration.lab.column_map import ColumnMap
from hcard.calibration.lab.delimited import DelimitedFile
from hcard.calibration.lab.detect import file_kind
from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.hdf5_files import Hdf5File
from hcard.calibration.lab.mat_files import MatFile
from hcard.calibration.lab.source import LabFile
from hcard.calibration.measurement import Measurement, read_measurement


def open_lab_file(path: str | os.PathLike[str], delimiter: str | None = None) -> LabFile:
    """The lab file at ``path``, opened by the reader its content calls for (LR9)."""
    kind = file_kind(path)
    if kind == "mat":
        return MatFile(path)
    if kind in ("hdf5", "mat73"):
        return Hdf5File(path, matlab=kind == "mat73")
    return DelimitedFile(path, delimiter)


def read_lab_file(path: str | os.PathLike[str], column_map: ColumnMap) -> Measurement:
    """The measurement in the lab file ``path`` read through ``column_map`` (LR1)."""
    lab = open_lab_file(path, column_map.delimiter)
    try:
        return measurement_of(lab, column_map)
    finally:
        lab.close()


def read_recording(path: str | os.PathLike[str],
                   column_map: ColumnMap | None = None) -> Measurement:
    """A recording: through ``column_map`` when one is given, else the project's CSV and
    sidecar (spec/measurement-format.md); a ``.mat`` or HDF5 file without a map is an error
    that says to give one (LR1)."""
    if column_map is not None:
        return read_lab_file(path, column_map)
    if Path(path).suffix.lower() != ".csv" and Path(path).is_file() and \
            file_kind(path) != "delimited":
        raise LabRecordingError(f"{path}: a lab file ({file_kind(path)}); read it through a "
                                "column map (--map RIG.json; `hcard calibrate map FILE` "
                                "proposes one)")
    return read_measurement(path)
