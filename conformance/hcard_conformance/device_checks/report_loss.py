"""Check ``device.report-loss`` (spec/conformance.md 4.7, rules L1-L3; protocol PT5, section
6, 8.4): the STATE stream a host records is complete, or its losses are counted.

CONTROL CLEAR_COUNTERS, then :data:`LOSS_SESSION_S` of driven play reading every STATE
report, then COUNTERS. ``sequence-gaps``: duplicated, reordered, or misnumbered reports (a
step of ``sequence`` that differs from the step of ``timestamp_us``), must be 0;
``loss-fraction``: sequence numbers missing while the host was reading (gaps across the
host's own pauses of more than :data:`HOST_PAUSE_MAX_S` are excused) over those expected,
at most the timing class's ``host_report_loss`` (:data:`MAX_LOSS_FRACTION` for a
real-time host); ``drops-counted``: the gaps the host saw against COUNTERS
``input_dropped`` (:func:`count_error`), within :func:`drop_count_limit`. A session that
the host or a device off real time disturbed is measured again
(:func:`measure_loss_sessions`). The check zeroes the device's counters (CLEAR_COUNTERS)
and leaves them counting.

The check is session-relative: it needs neither a fresh device nor its uptime, so it passes
twice in a row against one device that stays powered.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from itertools import pairwise

from hcard.device.base import Driver
from hcard.device.errors import SessionLost
from hcard.device.protocol import Counters, FaultBits, State
from hcard.quantities import MS_PER_S, S_PER_US, US_PER_S
from hcard_conformance.check_names import DEVICE_REPORT_LOSS as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.device_checks.link_session import (
    HOST_PAUSE_MAX_S,
    TIME_MODULO,
    LinkSession,
)
from hcard_conformance.realtime import NOT_KEPT, NotKept, collection_deferred
from hcard_conformance.result import CannotAssess, CheckResult, guarded, measured, unassessed
from hcard_conformance.timing import REAL_TIME, timing_class

LOSS_SESSION_S = 3.0
"""Driven play over which STATE reports are counted, s (3 000 reports at 1 kHz: one lost
report is 0.033 %, a third of :data:`MAX_LOSS_FRACTION`)."""
WARM_UP_S = 0.1
"""Play before CLEAR_COUNTERS, s (the reports of an earlier session are read and set aside)."""
TAIL_S = 0.05
"""Reports read after GET COUNTERS, s: those the device produced before answering it."""
MAX_LOSS_FRACTION = REAL_TIME.host_report_loss
"""L2 threshold of a real-time host (timing class ``real-time``; another class states its own
``host_report_loss``): at most 0.1 % of STATE reports lost, about one a second at 1 kHz. A
full-speed interrupt pipe polled every 1 ms (PT1) delivers every report when the device queues
as PT5 asks and the host reads; one lost report a second leaves the 1 kHz record of a session
dense enough for the 10 ms touch period and the 2 ms rise-time resolution of the device checks,
and keeps the host's latency and fault tracking (faults are ORed into the next report, PI1)
intact."""
DROP_COUNT_SLACK = 2
"""L3 threshold, plus the host's own loss allowance (:func:`drop_count_limit`): the gaps the
host saw and COUNTERS ``input_dropped`` may differ by this many reports: the CLEAR_COUNTERS at
the start and the GET COUNTERS at the end each fall between two reports, so one report at either
end may be counted on one side only."""
LOSS_CASES = ("sequence-gaps", "loss-fraction", "drops-counted")
"""The cases of ``device.report-loss``, in order."""
LOSS_ATTEMPTS = 3
"""Sessions measured at most: one that lost reports while disturbed (the host stalled, or the
device fell behind real time) is measured again (:func:`measure_loss_sessions`)."""
MIN_RATE_RATIO = 0.95
"""A session in which the device's clock (STATE ``timestamp_us``) advanced less than this
fraction of the host's is disturbed: the device did not run in real time."""
_SEQUENCE_MODULO = 1 << 16


@dataclass(frozen=True)
class SequenceStats:
    """Sequence numbers of the STATE reports of a session, as the host received them.

    Attributes:
        received: reports received.
        expected: sequence numbers from the first to the highest received (wrap-around
            unwrapped): the reports the device produced in that span.
        lost: sequence numbers of that span never received.
        duplicates: reports whose sequence number was already received.
        reordered: reports received after a higher sequence number.
        misnumbered: consecutive reports whose sequence step differs from their time step
            (``timestamp_us`` difference in report periods): a device that numbers only the
            reports it sends hides its losses (PT5).
        longest_gap: most consecutive sequence numbers missing.
        excused: of ``lost``, those missing between two reports the host read on either side
            of one of its own pauses (it did not read: a device drops, counted, what the host
            does not take, PT5).
    """

    received: int
    expected: int
    lost: int
    duplicates: int
    reordered: int
    misnumbered: int
    longest_gap: int
    excused: int = 0

    @property
    def unexcused(self) -> int:
        """Reports lost while the host was reading: ``lost - excused``."""
        return max(self.lost - self.excused, 0)

    @property
    def loss_fraction(self) -> float:
        """Reports lost while the host was reading over those expected, ``unexcused /
        expected`` (NaN without reports)."""
        return self.unexcused / self.expected if self.expected else math.nan


def sequence_stats(sequences: Sequence[int], timestamps_us: Sequence[int] | None = None,
                   period_us: float = 1000.0, arrivals_s: Sequence[float] | None = None,
                   pauses: Sequence[tuple[float, float]] = ()) -> SequenceStats:
    """Loss, duplicates, reordering and misnumbering of u16 ``sequences`` in arrival order
    (each unwrapped relative to the previous one: steps of less than 2^15 forward, otherwise
    backward). ``timestamps_us`` (u32, wrapping) and the report period ``period_us`` (us)
    give the time steps that the sequence steps are compared with; ``arrivals_s`` (the host
    clock when each report was read, s) and the host's ``pauses`` ((start, end), s) tell the
    gaps the host's pauses excuse."""
    if not sequences:
        return SequenceStats(0, 0, 0, 0, 0, 0, 0)
    unwrapped = [int(sequences[0])]
    for previous, current in pairwise(sequences):
        step = (int(current) - int(previous)) % _SEQUENCE_MODULO
        unwrapped.append(unwrapped[-1] + (step if step < _SEQUENCE_MODULO // 2
                                          else step - _SEQUENCE_MODULO))
    seen: set[int] = set()
    highest = unwrapped[0]
    duplicates = reordered = 0
    for value in unwrapped:
        if value in seen:
            duplicates += 1
            continue
        if value < highest:
            reordered += 1
        seen.add(value)
        highest = max(highest, value)
    ordered = sorted(seen)
    expected = ordered[-1] - ordered[0] + 1
    longest = max((b - a - 1 for a, b in pairwise(ordered)), default=0)
    misnumbered = 0
    if timestamps_us is not None:
        for k in range(1, len(unwrapped)):
            dt = (int(timestamps_us[k]) - int(timestamps_us[k - 1])) % TIME_MODULO
            if dt >= TIME_MODULO // 2:
                dt -= TIME_MODULO
            if round(dt / period_us) != unwrapped[k] - unwrapped[k - 1]:
                misnumbered += 1
    excused = 0
    if arrivals_s is not None and pauses:
        excused = excused_gaps(unwrapped, arrivals_s, pauses)
    return SequenceStats(len(unwrapped), expected, expected - len(ordered), duplicates,
                         reordered, misnumbered, longest, min(excused, expected - len(ordered)))


def excused_gaps(unwrapped: Sequence[int], arrivals_s: Sequence[float],
                 pauses: Sequence[tuple[float, float]]) -> int:
    """Sequence numbers missing in forward steps between two consecutive reports (arrival
    order) read on either side of, or during, a host pause: its interval overlaps the two
    reads (``arrivals_s``, s)."""
    excused = 0
    for k in range(1, len(unwrapped)):
        step = unwrapped[k] - unwrapped[k - 1]
        if step > 1 and any(start < arrivals_s[k] and end > arrivals_s[k - 1]
                            for start, end in pauses):
            excused += step - 1
    return excused


@dataclass(frozen=True)
class LossSession:
    """A report-loss session.

    Attributes:
        stats: the sequence statistics of the reports read after CLEAR_COUNTERS.
        counters: COUNTERS at the end of the session.
        dropped_field: ``dropped_reports`` of the last report read (u16, since the clear).
        flagged: reports read with fault INPUT_DROPPED.
        duration_s: driver time from CLEAR_COUNTERS to the last report read, s.
        rate_ratio: device time (``timestamp_us``) over host time in the session: 1 for a
            device that keeps real time.
        longest_pause_s: the host's longest time between two reads, s.
        late_s: spread of the reports' delay from the device's clock to the host's read
            (the latest less the earliest), s: reports that reached the host in a burst, late.
        attempt: which session this was (1 = the first, :data:`LOSS_ATTEMPTS` at most).
        device_late: reports read with fault REALTIME_LAG, or COUNTERS ``late_reports`` if
            more (the device fell behind its real-time clock, device protocol PI4).
    """

    stats: SequenceStats
    counters: Counters
    dropped_field: int
    flagged: int
    duration_s: float
    rate_ratio: float
    longest_pause_s: float
    late_s: float = 0.0
    attempt: int = 1
    device_late: int = 0

    @property
    def disturbed(self) -> str:
        """Why the session says little about the link (empty when it does not): the host
        paused longer than :data:`HOST_PAUSE_MAX_S`, or the device's clock advanced less than
        :data:`MIN_RATE_RATIO` of the host's (it did not run in real time: a simulated device
        on a loaded machine)."""
        reasons = []
        if self.longest_pause_s > HOST_PAUSE_MAX_S:
            reasons.append(
                f"the host paused {self.longest_pause_s * MS_PER_S:.0f} ms between reads")
        if self.late_s > HOST_PAUSE_MAX_S:
            reasons.append(f"reports reached the host up to {self.late_s * MS_PER_S:.0f} ms late")
        if self.rate_ratio < MIN_RATE_RATIO:
            reasons.append(f"the device's clock ran at {self.rate_ratio:.0%} of the host's")
        if self.device_late:
            reasons.append(f"the device produced {self.device_late} reports late on its "
                           "real-time clock (REALTIME_LAG, device protocol PI4)")
        return " and ".join(reasons)

    @property
    def lost_while_reading(self) -> bool:
        """Reports were lost while the host read (gaps its own pauses do not excuse)."""
        return self.stats.unexcused > 0

    def conditions(self) -> str:
        """The session's conditions, for a result's detail."""
        text = (f"session {self.attempt}: host paused at most "
                f"{self.longest_pause_s * MS_PER_S:.1f} ms, delay spread "
                f"{self.late_s * MS_PER_S:.1f} ms, device clock at "
                f"{self.rate_ratio:.1%} of the host's")
        if self.disturbed:
            text += f" (disturbed: {self.disturbed})"
        return text


def measure_report_loss(driver: Driver, session_s: float = LOSS_SESSION_S) -> LossSession:
    """Warm up, CLEAR_COUNTERS, play ``session_s`` (s) reading every STATE report, GET
    COUNTERS, read :data:`TAIL_S` more, restore the touch source and RUNNING."""
    info = driver.info()
    session = LinkSession(driver)
    session.begin()
    try:
        session.run(WARM_UP_S)
        driver.clear_counters()
        session.mark()
        first = len(session.states)
        start = driver.clock()
        with collection_deferred():  # a collection's pause would lose reports (QT3)
            session.run(session_s)
        counters = driver.counters()
        session.run(TAIL_S)
        duration = driver.clock() - start
        states, arrivals = session.states[first:], session.arrivals[first:]
        pauses = [p for p in session.pauses if p[1] > start]
    finally:
        session.restore()
    if not states:
        raise CannotAssess(f"no STATE report in {session_s:g} s of play")
    rate = max(info.input_rate_hz, 1)
    stats = sequence_stats([s.sequence for s in states], [s.timestamp_us for s in states],
                           US_PER_S / rate, arrivals, pauses)
    flagged = sum(bool(s.faults & FaultBits.INPUT_DROPPED) for s in states)
    device_late = max(sum(bool(s.faults & FaultBits.REALTIME_LAG) for s in states),
                      counters.late_reports)
    return LossSession(stats, counters, states[-1].dropped_reports, flagged, duration,
                       device_span_s(states) / duration, session.longest_pause_s,
                       delay_spread_s(states, arrivals), device_late=device_late)


def delay_spread_s(states: Sequence[State], arrivals_s: Sequence[float]) -> float:
    """The latest less the earliest delay from a report's device time (``timestamp_us``,
    unwrapped) to its read on the host's clock (``arrivals_s``), s: 0 when every report
    travelled as fast as the fastest; large after a burst (a device that fell behind and
    caught up, or a host that paused)."""
    if not states:
        return 0.0
    device_s, delays = 0.0, [arrivals_s[0]]
    for k in range(1, len(states)):
        ticks = (states[k].timestamp_us - states[k - 1].timestamp_us) % TIME_MODULO
        device_s += ticks * S_PER_US
        delays.append(arrivals_s[k] - device_s)
    return max(delays) - min(delays)


def device_span_s(states: Sequence[State]) -> float:
    """Device time from the first to the last of ``states`` (``timestamp_us``, unwrapped
    across the u32 wrap step by step), s."""
    total = 0
    for previous, current in pairwise(states):
        total += (current.timestamp_us - previous.timestamp_us) % TIME_MODULO
    return total * S_PER_US


def measure_loss_sessions(driver: Driver, attempts: int = LOSS_ATTEMPTS) -> LossSession:
    """The session the cases judge: the first that was not disturbed
    (:attr:`LossSession.disturbed`) or lost nothing while the host was reading (no gap but
    those its own pauses excuse, no anomaly); when every one of ``attempts`` was disturbed and
    lost reports, the one that lost fewest: its loss cases are then not assessed (a run not
    kept in real time, spec QT3, :func:`loss_not_kept`), its anomalies are judged."""
    sessions: list[LossSession] = []
    lost: list[str] = []
    for attempt in range(1, attempts + 1):
        try:
            m = replace(measure_report_loss(driver), attempt=attempt)
        except SessionLost as exc:
            # the host went silent for watchdog_ms (PN7 ended its session): a session not
            # kept (spec QT3); a driver that is not real-time never goes silent
            if not driver.realtime:
                raise
            lost.append(f"session {attempt}: {exc}")
            continue
        s = m.stats
        if not m.disturbed or s.unexcused + s.duplicates + s.reordered + s.misnumbered == 0:
            return m
        sessions.append(m)
    if not sessions:
        raise NotKept(f"every session {NOT_KEPT}: {'; '.join(lost)}")
    return min(sessions, key=lambda m: m.stats.unexcused)


def loss_not_kept(m: LossSession, sessions: int) -> str:
    """Why the loss cases (L2, L3) of the judged session ``m`` are not assessed: it lost
    reports while the host read, and it was disturbed (the host paused, reports came in a
    burst, or the device fell behind its real-time clock), as every one of the ``sessions``
    measured was (spec QT3: the loss measured the lateness, not the device; empty when the
    session is judged). Duplicated, reordered or misnumbered reports (L1) owe nothing to
    lateness and are judged whatever the session's conditions."""
    if not m.disturbed or not m.lost_while_reading:
        return ""
    return (f"every one of {sessions} sessions lost reports while disturbed, so the run "
            f"{NOT_KEPT} ({m.conditions()}; {m.stats.unexcused} lost while the host read)")


def count_error(stats: SequenceStats, counted: int) -> int:
    """L3 metric, reports: the drops COUNTERS claims beyond the reports missing
    (``counted - lost``), or the reports missing while the host was reading that it does not
    count (``unexcused - counted``), whichever is larger, at least 0. Gaps at the host's own
    pauses may be the device's counted drops (PT5) or losses behind the device (the host's
    buffers), which no device can count."""
    return max(counted - stats.lost, stats.unexcused - counted, 0)


def drop_count_limit(expected: int, host_loss: float) -> int:
    """L3 threshold for a session of ``expected`` reports, reports: :data:`DROP_COUNT_SLACK`
    plus the reports the host itself may lose (``host_loss``, the timing class's
    ``host_report_loss``): those the device delivered and the host failed to read, which no
    device counts."""
    return DROP_COUNT_SLACK + math.floor(host_loss * expected)


def check_report_loss(ctx: Context) -> Iterator[CheckResult]:
    """Sequence gaps, loss fraction and COUNTERS agreement of the STATE stream (L1-L3)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    timing = timing_class(ctx)

    def measure() -> Iterator[CheckResult]:
        sessions = LOSS_ATTEMPTS if timing.keeps_real_time else 1
        with open_driver() as driver:
            m = measure_loss_sessions(driver, sessions)
        s = m.stats
        not_kept = loss_not_kept(m, sessions) if timing.keeps_real_time else ""
        yield measured(CHECK, LEVEL, "sequence-gaps", "n_anomalies",
                       s.duplicates + s.reordered + s.misnumbered, 0.0, unit="reports",
                       detail=f"{s.duplicates} duplicated, {s.reordered} reordered, "
                       f"{s.misnumbered} misnumbered (sequence step != timestamp step) of "
                       f"{s.received} reports; {m.conditions()}")
        if not_kept:
            yield unassessed(CHECK, LEVEL, "loss-fraction", not_kept)
            yield unassessed(CHECK, LEVEL, "drops-counted", not_kept)
            return
        yield measured(CHECK, LEVEL, "loss-fraction", "loss_fraction",
                       s.loss_fraction * 100, timing.host_report_loss * 100, unit="%",
                       detail=f"{s.unexcused} of {s.expected} reports lost while the host "
                       f"read ({s.lost} missing, {s.excused} at its own pauses; longest gap "
                       f"{s.longest_gap}) over {m.duration_s:.2f} s; {m.conditions()}; timing "
                       f"class {timing.name}")
        counted = m.counters.input_dropped
        yield measured(CHECK, LEVEL, "drops-counted", "count_error",
                       count_error(s, counted),
                       drop_count_limit(s.expected, timing.host_report_loss), unit="reports",
                       detail=f"host saw {s.lost} missing ({s.excused} at its own pauses), "
                       f"COUNTERS input_dropped {counted} "
                       f"(STATE dropped_reports {m.dropped_field}, {m.flagged} reports flagged "
                       f"INPUT_DROPPED, input_reports {m.counters.input_reports}); "
                       f"{m.conditions()}")

    yield from guarded(CHECK, LEVEL, LOSS_CASES, measure)
