"""A conforming reference device behind a late transport: one that delays one FINGER report
per contact (:class:`LateSecondSampleDriver`), or a host that reads every report late
(:class:`LateReaderDriver`).

The device itself is the reference (``sim://`` on a simulated clock); only the transport is
late: the second FINGER report of every contact, the one that gives the device its first
finger speed, reaches it :data:`LATE_S` after the host sent it (as a busy host once held one
over USB/IP). Everything else arrives at once. The device's rendering after that sample is
exact; before it, it has only the touch-down and holds it, as every renderer must.
"""

from __future__ import annotations

from collections import deque

from hcard.device.protocol import Finger, ReportId, State
from hcard.device.uri import parse_uri
from hcard_device.controls import DelayedFingerDriver
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import STEP_S, SimDriver

LATE_S = 0.009
"""Delay of the second FINGER report of each contact, s (within the D3 bound of 10 ms)."""


class LateSecondSampleDriver(DelayedFingerDriver):
    """``sim://`` (E-ViTa, or the coupled stimulator) whose transport holds the second FINGER
    report of every contact for :data:`LATE_S`."""

    def __init__(self, uri: str = "sim://") -> None:
        config = DeviceConfig.coupled() if "coupled" in uri else DeviceConfig.evita()
        super().__init__(parse_uri(uri), Firmware(DeviceSimulation(config)), timeout_s=1.0,
                         delay_s=LATE_S)
        self._in_contact = 0  # FINGER reports in contact since the last touch-down

    def start(self) -> None:
        self._in_contact = 0
        super().start()

    def _write_output(self, report: bytes) -> None:
        if report and report[0] == ReportId.FINGER:
            contact = Finger.decode(report).contact
            self._in_contact = self._in_contact + 1 if contact else 0
            if self._in_contact != 2:
                SimDriver._write_output(self, report)
                return
        super()._write_output(report)


READ_LAG_S = 0.3
"""How long after the device sent it :class:`LateReaderDriver`'s host reads a report, s (the
order of the QEMU guest's read backlog)."""


class LateReaderDriver(SimDriver):
    """``sim://`` E-ViTa behind a host that reads every STATE report :data:`READ_LAG_S` after
    the device sent it (a host whose read queue is always that far behind), while its FINGER
    reports reach the device at once."""

    def __init__(self, lag_s: float = READ_LAG_S) -> None:
        super().__init__(parse_uri("sim://"), Firmware(DeviceSimulation(DeviceConfig.evita())),
                         timeout_s=1.0)
        self.lag_s = lag_s
        self._held: deque[bytes] = deque()

    def _due(self) -> bytes | None:
        """The oldest report if the host has caught up with it, else None."""
        self._held.extend(self._pending)
        self._pending.clear()
        if self._held and State.decode(self._held[0]).timestamp_us * 1e-6 \
                <= self.clock() - self.lag_s:
            return self._held.popleft()
        return None

    def collect_until(self, t_s: float) -> list[State]:
        if t_s > self.clock():
            self.advance(t_s - self.clock())
        states = []
        while (data := self._due()) is not None:
            state = self.accept_input(data)
            if state is not None:
                states.append(state)
        return states

    def _read_input(self, timeout_s: float) -> bytes | None:
        waited = 0.0
        while (data := self._due()) is None and waited < timeout_s - 1e-12:
            step = min(STEP_S, timeout_s - waited)
            self.advance(step)
            waited += step
        return data


STALL_PERIOD_S = 0.12
"""Period of :class:`StallingReaderDriver`'s stalls, s."""
STALL_S = 0.06
"""How long each stall of :class:`StallingReaderDriver`'s host lasts, s (a QEMU guest's host
was seen to read nothing for more than 20 ms while its reports were held in the emulated
USB stack)."""


class StallingReaderDriver(LateReaderDriver):
    """``sim://`` E-ViTa behind a host that reads every report :data:`STALL_LAG_S` late and,
    for :data:`STALL_S` of every :data:`STALL_PERIOD_S` of the device's clock, reads nothing
    (the reports wait and are read together after the stall)."""

    def __init__(self) -> None:
        super().__init__(lag_s=STALL_LAG_S)

    def _due(self) -> bytes | None:
        if self.clock() % STALL_PERIOD_S < STALL_S:
            self._held.extend(self._pending)
            self._pending.clear()
            return None
        return super()._due()


STALL_LAG_S = 0.01
"""How late :class:`StallingReaderDriver`'s host reads a report outside its stalls, s."""
