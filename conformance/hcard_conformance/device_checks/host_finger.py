"""The host's finger on the surface while a device check works: FINGER reports along a path
(positions in mm, times in s since the finger started) at a normal force (N), each with a host
time (us) later than the one before."""

from __future__ import annotations

import math
from collections.abc import Callable

from hcard.device.base import Driver
from hcard.device.play_result import HOST_TIME_MODULO
from hcard.device.protocol import Capability, DeviceInfo
from hcard.quantities import S_PER_US, US_PER_S

FINGER_PERIOD_S = 0.01
"""FINGER reports while a check feeds the finger, s (a 100 Hz touch screen; ten per watchdog
period of the reference device, so the outputs never ramp down during an upload)."""
FINGER_FORCE_N = 0.5
"""Normal force of the host finger, N."""

FingerPath = Callable[[float], tuple[float, float]]
"""Where the finger is, (x, y) in mm, a time (s) after it started."""


def circling(info: DeviceInfo, speed_mm_s: float) -> FingerPath:
    """Round the centre of the surface of ``info`` at ``speed_mm_s`` (mm/s), radius a quarter of
    its smaller side, from the point right of the centre, counter-clockwise."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    centre_x, centre_y, radius = width / 2, height / 2, min(width, height) / 4

    def at(t_s: float) -> tuple[float, float]:
        angle = speed_mm_s * t_s / radius
        return centre_x + radius * math.cos(angle), centre_y + radius * math.sin(angle)

    return at


def stroke(x0_mm: float, y_mm: float, speed_mm_s: float) -> FingerPath:
    """Along +x from (``x0_mm``, ``y_mm``) (mm) at ``speed_mm_s`` (mm/s)."""

    def at(t_s: float) -> tuple[float, float]:
        return x0_mm + speed_mm_s * t_s, y_mm

    return at


class HostFinger:
    """The host's finger: a FINGER report in contact where ``path`` has it, at ``force_n``, when
    :meth:`send` is called and, through :meth:`feed`, every ``period_s``; a CONTROL KEEPALIVE in
    its place on a device without HOST_FINGER. Each report's host time is later than the one
    before by at least 1 us, so a STATE report's echo names one FINGER report; those sent after
    :meth:`mark` are remembered.

    Attributes:
        driver: the open driver.
        host_finger: the device takes FINGER reports (capability HOST_FINGER).
        start_s: driver-clock time the finger started, s (time 0 of ``path``).
        last_us: host time of the last FINGER report sent, us (-1: none yet).
        due_s: driver-clock time the next report is due for :meth:`feed`, s.
        after_us: host times (us, modulo 2**32 as STATE echoes them) of the FINGER reports
            sent after :meth:`mark`.
    """

    def __init__(self, driver: Driver, path: FingerPath, *, force_n: float = FINGER_FORCE_N,
                 period_s: float = FINGER_PERIOD_S) -> None:
        self.driver = driver
        self.path = path
        self.force_n = force_n
        self.period_s = period_s
        self.host_finger = bool(driver.info().capabilities & Capability.HOST_FINGER)
        self.start_s = driver.clock()
        self.last_us = -1
        self.due_s = self.start_s
        self.marked = False
        self.after_us: set[int] = set()

    def send(self) -> None:
        """Send the finger where the path has it now; the next report is due a period later."""
        now = self.driver.clock()
        self._send(now)
        self.due_s = now + self.period_s

    def feed(self) -> None:
        """Send the finger when a report is due: every period from the start, and at once, not
        once per period missed, after a longer pause."""
        now = self.driver.clock()
        if now < self.due_s:
            return
        self._send(now)
        self.due_s = max(self.due_s + self.period_s, now)

    def mark(self) -> None:
        """From now on, remember the host times of the FINGER reports sent (:attr:`after_us`),
        forgetting those sent before."""
        self.marked = True
        self.after_us = set()

    def _send(self, now_s: float) -> None:
        if not self.host_finger:
            self.driver.keepalive()
            return
        host_us = max(round(now_s * US_PER_S), self.last_us + 1)
        x_mm, y_mm = self.path(now_s - self.start_s)
        self.driver.send_finger(host_us * S_PER_US, x_mm, y_mm, self.force_n, True)
        self.last_us = host_us
        if self.marked:
            self.after_us.add(host_us % HOST_TIME_MODULO)
