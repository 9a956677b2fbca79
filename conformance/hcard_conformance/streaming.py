"""Direct streaming for the device-level dynamics checks, paced so the queue never runs dry.

A device in real time plays one frame per ``1 / frame_rate_hz`` from its stream queue
(DEVICE_INFO ``stream_capacity_frames``) and plays neutral frames when the queue is empty. A host
that sends frames only as they fall due leaves the queue empty between its sends (USB/IP, a busy
host): the device then plays bursts and gaps, and a 400 Hz sinusoid measures as 30-70 Hz. The
streamer keeps a *lead*: frames sent ahead of the device's playback, sized from the queue
(half of it, at most :data:`LEAD_S`), topped up against the clock and checked against the
``stream_queued`` the device reports.

Times in the result are session-relative: :attr:`StreamSession.t_s` counts from the first report
of the session, and analyses find the stimulus in the ``target_uv`` the device reports (the
frame it played), never in the device's uptime.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.device.base import Driver
from hcard.device.protocol import Capability, State
from hcard.device.recording import unwrapped_times
from hcard.quantities import S_PER_US, US_PER_S
from hcard_conformance.realtime import NOT_KEPT, NotKept, collection_deferred, device_lag

LEAD_S = 0.1
"""Longest lead of the streamed frames over the device's playback, s: a host that does not
run for less than this leaves no queue empty. 50 ms ran dry under two CPU burners on a 2-core
machine (6 % of the reports of a 50 Hz sine, in each of three plays); the reference queue
holds 200 ms, so half of it still leaves 100 ms of room against a device behind its clock."""
SETTLE_S = 0.05
"""Reports collected after the last streamed frame has played, s."""
FINGER_PERIOD_S = 0.01
"""Host finger reports while streaming (a 100 Hz touch screen), s."""
FINGER_FORCE_N = 0.5
"""Normal force of the host finger while streaming, N."""
FINGER_SPEED_MM_S = 60.0
"""Speed of the host finger while streaming, mm/s (the firmware's velocity compensation sees a
sliding finger; a still finger gives zero UV friction at any amplitude)."""

STARVED_FRACTION = 0.05
"""Fraction of a streaming session's reports with an empty queue beyond which a dynamics
measurement is not assessed (the reference over usbip in real time: 0-3 of ~700)."""
FED_ATTEMPTS = 3
"""Times :func:`stream_fed` plays a stimulus whose queue the host let run dry before it keeps
the attempt with the fewest empty reports. Under the starved bound a few empty reports still
corrupt a measurement: the device plays neutral frames there and the plate drops out (seen on
the reference over usbip on a busy machine: 19 empty of ~700 put a 400 Hz gain 6 dB low, the
-3 dB point at 378 Hz instead of 400)."""

@dataclass(frozen=True)
class StreamSession:
    """The STATE reports of one streaming session.

    Attributes:
        states: every report from START to STOP, in arrival order.
        t_s: their device times since the first of them, s.
        lead_frames: the lead kept, frames.
        min_queued: the smallest ``stream_queued`` reported between the first and the last
            streamed frame played (0: the queue ran dry).
        underruns: reports in that span with an empty queue.
    """

    states: list[State]
    t_s: np.ndarray
    lead_frames: int
    min_queued: int
    underruns: int

    def column(self, name: str) -> np.ndarray:
        """One STATE field of every report, as floats."""
        return np.array([getattr(s, name) for s in self.states], dtype=float)

    def require_fed(self, what: str) -> None:
        """:func:`require_fed` over this session's span (lead :attr:`lead_frames`); when the
        device flagged reports REALTIME_LAG, the reason says so: a device that fell behind its
        clock and caught up plays frames the host has not sent yet, and empties its queue with
        a host that never stalled (``bench/bench_stream_feed.py``)."""
        require_fed(self.underruns, len(self.states),
                    f"{what} (lead {self.lead_frames} frames)", device_lag(self.states))


def stream_fed(driver: Driver, uv: np.ndarray, ev: np.ndarray | None = None, *,
               what: str) -> StreamSession:
    """:func:`stream` again, up to :data:`FED_ATTEMPTS` times, while the host let the queue run
    dry; the attempt with the fewest empty reports, which must pass :func:`require_fed`. A
    device is measured on a stimulus it was given whole, not on the host's stalls."""
    best: StreamSession | None = None
    for _ in range(FED_ATTEMPTS):
        session = stream(driver, uv, ev)
        if best is None or session.underruns < best.underruns:
            best = session
        if best.underruns == 0:
            break
    assert best is not None
    best.require_fed(what)
    return best


def require_fed(empty: int, reports: int, what: str, lag: str = "") -> None:
    """Raise :class:`~hcard_conformance.realtime.NotKept` (a CannotAssess) when the stream
    queue was empty in ``empty`` of ``reports`` reports, more than :data:`STARVED_FRACTION`:
    the stream then measured the host (a software-emulated or overloaded one) or a device
    that fell behind its own clock (``lag``: :func:`device_lag` of the reports, empty when
    none was flagged), not the device's response (spec/conformance.md 5.2, QT2, QT3)."""
    if empty > STARVED_FRACTION * max(reports, 1):
        if lag:
            raise NotKept(f"{what}: the stream queue was empty in {empty} of {reports} "
                          f"reports and {lag} (a run that {NOT_KEPT})")
        raise NotKept(
            f"{what}: the host left the stream queue empty in {empty} of {reports} reports; "
            "it cannot feed the device in real time, so the measurement would be of the host "
            f"(a run that {NOT_KEPT})")


class SteadyStroke:
    """The host's finger while streaming: a stroke at :data:`FINGER_SPEED_MM_S` along x at
    :data:`FINGER_FORCE_N`, sampled every :data:`FINGER_PERIOD_S` of the host clock.

    Each sample is timed at its scheduled instant, not at the moment it is sent, and every
    position lies on the protocol's 10 um grid (FINGER ``x_10um``), so any two consecutive
    samples are exactly one period and one :data:`FINGER_PERIOD_S` x speed step apart as the
    device receives them. A host that falls behind sends the overdue samples together, each with
    its own time (the device places them by host time, PO2). The firmware's speed estimate
    (velocity compensation, Eq. 2.30) then sees one speed throughout. Timing the samples at their
    send instead, with positions rounded to the grid, made that estimate wander by 1-3 % from
    report to report, and the plate amplitude with it: on the reference over usbip on a busy
    machine the 25 Hz gain of D1 scattered by 2-3 % (standard deviation) from run to run, and by
    0.01-0.03 % with this schedule."""

    def __init__(self, start_s: float, x_mm: float, y_mm: float) -> None:
        self._start_us = round(start_s * US_PER_S)
        self._x0_counts = round(x_mm * 100)
        self._y_mm = y_mm
        self._sent = 0

    def send_due(self, driver: Driver, now_s: float) -> None:
        """Send every sample scheduled at or before ``now_s`` (host clock, s) not yet sent."""
        period_us = round(FINGER_PERIOD_S * US_PER_S)
        step_counts = round(FINGER_SPEED_MM_S * FINGER_PERIOD_S * 100)
        while (self._start_us + self._sent * period_us) * S_PER_US <= now_s:
            k = self._sent
            driver.send_finger((self._start_us + k * period_us) * S_PER_US,
                               (self._x0_counts + k * step_counts) * 0.01, self._y_mm,
                               FINGER_FORCE_N, True)
            self._sent += 1


def lead_frames(capacity_frames: int, frame_rate_hz: float) -> int:
    """The lead for a queue of ``capacity_frames``: half of it, at most :data:`LEAD_S`."""
    return max(1, min(capacity_frames // 2, round(LEAD_S * frame_rate_hz)))


def stream(driver: Driver, uv: np.ndarray, ev: np.ndarray | None = None) -> StreamSession:
    """:func:`stream_once` with the interpreter's cyclic collection deferred to its end (a
    collection's pause would leave the queue empty, spec QT3)."""
    with collection_deferred():
        return stream_once(driver, uv, ev)


def stream_once(driver: Driver, uv: np.ndarray,
                ev: np.ndarray | None = None) -> StreamSession:
    """Stream ``uv`` (and ``ev``, default neutral) frames at the device's frame rate while
    the host's finger strokes at :data:`FINGER_SPEED_MM_S` (devices with HOST_FINGER), then
    collect until the queue has played out and STOP."""
    info = driver.info()
    rate = float(info.frame_rate_hz)
    uv = np.asarray(uv, dtype=float)
    ev = np.ones_like(uv) if ev is None else np.asarray(ev, dtype=float)
    lead = lead_frames(int(info.stream_capacity_frames), rate)
    width = info.surface_width_10um * 0.01
    x0, y = width / 4, info.surface_height_10um * 0.005
    host_finger = bool(info.capabilities & Capability.HOST_FINGER)
    if host_finger:
        driver.set_touch_source(host=True)
    driver.start()
    start = driver.clock()
    finger = SteadyStroke(start, x0, y) if host_finger else None
    states: list[State] = []
    sent = 0
    n = uv.shape[0]
    while sent < n:
        now = driver.clock()
        if finger is not None:
            finger.send_due(driver, now)
        due = min(n, lead + int((now - start) * rate))
        if due > sent:
            driver.stream_frames(uv[sent:due], ev[sent:due])
            sent = due
        states += driver.collect_until(driver.clock() + 0.001)
    end = driver.clock() + lead / rate + SETTLE_S  # the lead plays out, and the plate settles
    while driver.clock() < end:
        if finger is not None:
            finger.send_due(driver, driver.clock())
        states += driver.collect_until(min(end, driver.clock() + 0.002))
    driver.stop()
    queued = np.array([s.stream_queued for s in states], dtype=int)
    # the span in which streamed frames were playing: from the first report with a queue to
    # the last one before the queue emptied for good
    filled = np.flatnonzero(queued > 0)
    if filled.size:
        span = queued[filled[0]:filled[-1] + 1]
        min_queued, underruns = int(span.min()), int(np.count_nonzero(span == 0))
    else:
        min_queued, underruns = 0, len(states)
    return StreamSession(states, unwrapped_times(states), lead, min_queued, underruns)
