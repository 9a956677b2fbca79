"""The device's event counters, one set for the firmware and the simulation it drives.

The COUNTERS feature report (spec/device-protocol.md section 8.4) is built from them; the
firmware counts the host's reports, the simulation the streamed frames and invalid values.
CLEAR_COUNTERS zeroes all of them at once.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from hcard.device.protocol import Counters

_U16 = 0xFFFF
_U32 = 0xFFFF_FFFF


@dataclass
class DeviceCounters:
    """Counts since power-up or the last :meth:`clear` (totals, not wrapped: the COUNTERS
    report wraps them to its field widths).

    Attributes:
        input_reports: STATE reports produced.
        input_dropped: STATE reports dropped because the input queue was full.
        output_reports: output reports accepted.
        rejected_requests: malformed or refused output and feature requests.
        stream_frames_dropped: streamed frames dropped because the stream queue was full.
        stream_gaps: STREAM reports whose stream_seq was not the previous one plus 1.
        watchdog_trips: times the watchdog expired.
        latched_faults: OR of every fault bit reported.
        late_reports: STATE reports produced with fault REALTIME_LAG (rule PI4).
        stream_underruns: frames played neutral because the stream queue ran dry (not in the
            report).
        invalid_requests: commands to the simulation that carried invalid values (not in the
            report).
    """

    input_reports: int = 0
    input_dropped: int = 0
    output_reports: int = 0
    rejected_requests: int = 0
    stream_frames_dropped: int = 0
    stream_gaps: int = 0
    watchdog_trips: int = 0
    latched_faults: int = 0
    late_reports: int = 0
    stream_underruns: int = 0
    invalid_requests: int = 0

    def clear(self) -> None:
        """Zero every counter (CLEAR_COUNTERS)."""
        for field in dataclasses.fields(self):
            setattr(self, field.name, 0)

    def report(self) -> Counters:
        """The COUNTERS report of these counts, each wrapped to its field's width."""
        return Counters(
            input_reports=self.input_reports & _U32,
            input_dropped=self.input_dropped & _U32,
            output_reports=self.output_reports & _U32,
            rejected_requests=self.rejected_requests & _U32,
            stream_frames_dropped=self.stream_frames_dropped & _U32,
            stream_gaps=self.stream_gaps & _U32,
            watchdog_trips=self.watchdog_trips & _U32,
            latched_faults=self.latched_faults & _U16,
            late_reports=self.late_reports & _U32,
        )
