"""The errors of lab recordings and column maps (spec/lab-recordings.md LR12): one line naming
the file, the field or variable, and the reason."""

from __future__ import annotations

from hcard.calibration.measurement import MeasurementError


class LabRecordingError(MeasurementError):
    """A lab file (``.mat``, HDF5, CSV/TSV) cannot be read through its column map."""


class ColumnMapError(MeasurementError):
    """A column map is malformed: the message names the map file and the field."""
