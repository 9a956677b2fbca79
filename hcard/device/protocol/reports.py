"""Every report of the hcard device protocol as a frozen dataclass (spec/device-protocol.md 6-9).

Fields hold integer wire values; the unit is in the field name (see :mod:`.base`). Properties
and ``from_si`` constructors convert to and from SI units and relative friction. The classes
live in :mod:`.input_report`, :mod:`.output_reports` and :mod:`.feature_reports`.
"""

from __future__ import annotations

from hcard.device.protocol.base import MAX_FINGER_FORCE_MN, POSITION_RANGE, Report
from hcard.device.protocol.feature_reports import (
    ClipReport,
    Counters,
    DeviceInfo,
    Limits,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadStatus,
)
from hcard.device.protocol.input_report import State
from hcard.device.protocol.output_reports import Control, Finger, Stream

__all__ = [
    "MAX_FINGER_FORCE_MN",
    "POSITION_RANGE",
    "REPORT_CLASSES",
    "ClipReport",
    "Control",
    "Counters",
    "DeviceInfo",
    "Finger",
    "Limits",
    "State",
    "Stream",
    "UploadBegin",
    "UploadData",
    "UploadEnd",
    "UploadStatus",
]

REPORT_CLASSES: tuple[type[Report], ...] = (
    State,
    Finger,
    Stream,
    Control,
    DeviceInfo,
    Limits,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadStatus,
    ClipReport,
    Counters,
)
"""Every report, in report-ID order."""
