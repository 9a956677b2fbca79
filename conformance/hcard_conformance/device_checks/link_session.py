"""The session of the link checks (``device.upload-integrity``, ``device.report-loss``): the
host's finger (:class:`~.host_finger.HostFinger`) circling on the surface while every STATE
report is read, and the host's own pauses timed (s).
"""

from __future__ import annotations

from hcard.device.base import Driver
from hcard.device.protocol import Command, State, StateFlags
from hcard_conformance.device_checks.host_finger import HostFinger, circling

FINGER_SPEED_MM_S = 30.0
"""Speed of the host finger circling on the surface, mm/s."""
POLL_S = 0.001
"""Time the host drives and reads between two upload reports, s (one STATE period)."""
HOST_PAUSE_MAX_S = 0.02
"""A host that does not read (nor send its finger) for longer than this disturbs a session, s
(20 reports at 1 kHz, one 50 Hz touch period): its finger samples arrive late, and a device is
not asked to queue reports for a stalled host beyond that."""
TIME_MODULO = 1 << 32
"""STATE ``timestamp_us`` wraps at 2**32 us."""


class LinkSession:
    """The host's finger circling on the surface (radius a quarter of the smaller side) while a
    check works: a FINGER report every :data:`~.host_finger.FINGER_PERIOD_S` (CONTROL KEEPALIVE
    on a device without HOST_FINGER), every STATE report collected in :attr:`states`.

    Attributes:
        driver: the open driver.
        finger: the host's finger.
        states: every STATE report read so far, in arrival order.
        found: the state flags of the first report, read before changing anything (for
            :meth:`restore`).
    """

    def __init__(self, driver: Driver) -> None:
        self.driver = driver
        self.states: list[State] = []
        first = driver.read_inputs(max_count=1)
        self.found = first[0].flags if first else 0
        self.finger = HostFinger(driver, circling(driver.info(), FINGER_SPEED_MM_S))
        self._last_read = self.finger.start_s
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
        if self.finger.host_finger:
            self.driver.set_touch_source(host=True)
        if anonymous:
            self.driver.command(Command.START)
        else:
            self.driver.start()
        self.finger.feed()

    def run(self, seconds: float) -> list[State]:
        """Drive the finger and read STATE reports for ``seconds`` (s); the reports read."""
        end = self.driver.clock() + seconds
        got: list[State] = []
        while True:
            self.finger.feed()
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

    def run_until_echoed(self, seconds: float, longest_s: float, count: int = 1,
                         ) -> list[State]:
        """:meth:`run` for ``seconds`` (s), then on until ``count`` reports echo a FINGER the
        host sent since :meth:`HostFinger.mark` (``host_time_echo_us``), at most ``longest_s``
        (s) longer: a device applies a host's reports in order, so such a report shows what
        the host sent before that FINGER. On a device without HOST_FINGER, the reports of
        ``seconds`` alone."""
        got = self.run(seconds)
        if not self.finger.host_finger:
            return got
        echoes = self.finger.after_us
        deadline = self.driver.clock() + longest_s
        while sum(s.host_time_echo_us in echoes for s in got) < count \
                and self.driver.clock() < deadline:
            got += self.run(POLL_S)
        return got

    def restore(self) -> None:
        """STOP unless the device was RUNNING when found; give the touch source back to the
        internal sensor when it had it."""
        if not self.found & StateFlags.RUNNING:
            self.driver.stop()
        if self.finger.host_finger and not self.found & StateFlags.HOST_FINGER:
            self.driver.set_touch_source(host=False)
