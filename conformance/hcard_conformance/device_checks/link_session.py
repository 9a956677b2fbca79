"""The session of the link checks (``device.upload-integrity``, ``device.report-loss``): the
host's finger circling on the surface while every STATE report is read, and the host's own
pauses timed (s).
"""

from __future__ import annotations

import math

from hcard.device.base import Driver
from hcard.device.protocol import Capability, Command, State, StateFlags

FINGER_PERIOD_S = 0.01
"""Host finger reports while a link check works, s (a 100 Hz touch screen; ten per watchdog
period of the reference device, so the outputs never ramp down during an upload)."""
FINGER_SPEED_MM_S = 30.0
"""Speed of the host finger circling on the surface, mm/s."""
FINGER_FORCE_N = 0.5
"""Normal force of the host finger, N."""
POLL_S = 0.001
"""Time the host drives and reads between two upload reports, s (one STATE period)."""
HOST_PAUSE_MAX_S = 0.02
"""A host that does not read (nor send its finger) for longer than this disturbs a session, s
(20 reports at 1 kHz, one 50 Hz touch period): its finger samples arrive late, and a device is
not asked to queue reports for a stalled host beyond that."""
TIME_MODULO = 1 << 32
"""STATE ``timestamp_us`` wraps at 2**32 us."""


class FingerSession:
    """The host's finger circling on the surface (radius a quarter of the smaller side) while a
    check works: a FINGER report every :data:`FINGER_PERIOD_S` (CONTROL KEEPALIVE on a device
    without HOST_FINGER), every STATE report collected in :attr:`states`.

    Attributes:
        driver: the open driver.
        states: every STATE report read so far, in arrival order.
        found: the state flags of the first report, read before changing anything (for
            :meth:`restore`).
    """

    def __init__(self, driver: Driver) -> None:
        info = driver.info()
        self.driver = driver
        self.host_finger = bool(info.capabilities & Capability.HOST_FINGER)
        width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
        self._centre = (width / 2, height / 2)
        self._radius = min(width, height) / 4
        self.states: list[State] = []
        first = driver.read_inputs(max_count=1)
        self.found = first[0].flags if first else 0
        self._start = driver.clock()
        self._next = self._start
        self._last_read = self._start
        self.longest_pause_s = 0.0
        """Longest driver-clock time between two reads of the host since :meth:`mark`, s (a
        host that stalls leaves the device's queue to fill and its finger samples late)."""
        self.pauses: list[tuple[float, float]] = []
        """Driver-clock intervals (start, end) in which the host did not read for longer than
        :data:`HOST_PAUSE_MAX_S`, s."""
        self.arrivals: list[float] = []
        """Driver-clock time at which each report of :attr:`states` was read, s."""

    def mark(self) -> None:
        """Start measuring :attr:`longest_pause_s` afresh, from now."""
        self._last_read = self.driver.clock()
        self.longest_pause_s = 0.0

    def begin(self, *, anonymous: bool = False) -> None:
        """Take the touch source (when the device has HOST_FINGER) and START: through
        :meth:`Driver.start` (on a protocol 1.2 device, a session this driver owns), or,
        ``anonymous``, CONTROL START with argument 0 as a protocol 1.1 host sends it: a 1.2
        device refuses every COMMIT while a session with a token is live, and accepts them in
        an anonymous one, as a 1.1 device always does."""
        check_free = getattr(self.driver, "check_free", None)
        if anonymous and check_free is not None:
            check_free()  # a session an earlier host left must end first (SessionBusy if fed)
        if self.host_finger:
            self.driver.set_touch_source(host=True)
        if anonymous:
            self.driver.command(Command.START)
        else:
            self.driver.start()
        self._feed()

    def _feed(self) -> None:
        """Send the finger sample (or KEEPALIVE) when one is due."""
        now = self.driver.clock()
        if now < self._next:
            return
        if self.host_finger:
            angle = FINGER_SPEED_MM_S * (now - self._start) / self._radius
            self.driver.send_finger(now, self._centre[0] + self._radius * math.cos(angle),
                                    self._centre[1] + self._radius * math.sin(angle),
                                    FINGER_FORCE_N, True)
        else:
            self.driver.keepalive()
        self._next = max(self._next + FINGER_PERIOD_S, now)

    def run(self, seconds: float) -> list[State]:
        """Drive the finger and read STATE reports for ``seconds`` (s); the reports read."""
        end = self.driver.clock() + seconds
        got: list[State] = []
        while True:
            self._feed()
            now = self.driver.clock()
            if now - self._last_read > HOST_PAUSE_MAX_S:
                self.pauses.append((self._last_read, now))
            self.longest_pause_s = max(self.longest_pause_s, now - self._last_read)
            self._last_read = now
            if now >= end:
                break
            batch = self.driver.collect_until(min(end, now + POLL_S))
            self.arrivals += [self.driver.clock()] * len(batch)
            got += batch
        self.states += got
        return got

    def restore(self) -> None:
        """STOP unless the device was RUNNING when found; give the touch source back to the
        internal sensor when it had it."""
        if not self.found & StateFlags.RUNNING:
            self.driver.stop()
        if self.host_finger and not self.found & StateFlags.HOST_FINGER:
            self.driver.set_touch_source(host=False)
