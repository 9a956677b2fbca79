"""Placing the host's finger samples on the device clock.

A FINGER report carries the host's time of its sample (``host_time_us``, wrapping at 2^32 us).
Reports reach the device after a transport delay that varies: on a busy host they arrive late and
in bursts, several in the same millisecond. Timing the samples by their arrival would make the
renderer see a finger that stands still and then jumps (an estimated velocity of mm per us, dead-
reckoned for up to 100 ms), so the device times each sample at ``host time + offset``, where the
offset is the smallest ``arrival - host time`` seen since the host's clock was last anchored: the
report that travelled fastest fixes how far the two clocks are apart, and the others keep the
spacing the host gave them.

A host whose times do not advance (one that sends 0, say: the field is free for any value) gets
its samples timed by their arrival, as in protocol 1.0. The offset is kept across sessions (a
short first burst of a session is then placed right too) and may grow by
:data:`DRIFT_ALLOWANCE` of the host time that passes, so two clocks that drift apart (ppm) are
followed both ways; a jump of the host's clock by more than :data:`REANCHOR_GAP_S` (a restarted
host) anchors it afresh.
"""

from __future__ import annotations

from hcard_device.sim.finger import HOST_TIME_WRAP_S

REANCHOR_GAP_S = 600.0
"""A step of the host's time (s) after which the clock offset is anchored again."""
DRIFT_ALLOWANCE = 50e-6
"""How fast the offset may grow, s per s of host time (50 ppm: two crystal clocks of +-25 ppm)."""


class HostClock:
    """Maps host sample times (s, wrapping at 2^32 us) onto the device clock (s)."""

    def __init__(self) -> None:
        self._host_s: float | None = None  # the last host time, unwrapped, s
        self._offset_s = 0.0  # device time - host time, s
        self._timed_by_host = False

    def reset(self) -> None:
        """Forget the anchor (the next sample anchors it)."""
        self._host_s = None
        self._timed_by_host = False

    @property
    def last_host_s(self) -> float | None:
        """The unwrapped host time of the sample :meth:`device_time` placed last, s, on a
        time line that only moves forward (wraps of the u32 counter unrolled); None when that
        sample was timed by its arrival (its host time did not advance) or none was placed."""
        return self._host_s if self._timed_by_host else None

    def device_time(self, arrival_s: float, host_time_s: float) -> float:
        """The device time (s) of a sample taken at ``host_time_s`` that arrived at
        ``arrival_s`` (device clock): never later than its arrival."""
        if self._host_s is None:
            host = host_time_s
            self._offset_s = arrival_s - host
        else:
            step = (host_time_s - self._host_s) % HOST_TIME_WRAP_S
            if step == 0.0:
                self._timed_by_host = False
                return arrival_s
            host = self._host_s + step
            if step > REANCHOR_GAP_S:
                self._offset_s = arrival_s - host
            else:
                relaxed = self._offset_s + DRIFT_ALLOWANCE * step
                self._offset_s = min(relaxed, arrival_s - host)
        self._host_s = host
        self._timed_by_host = True
        return host + self._offset_s
