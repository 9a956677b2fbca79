"""Check ``device.latency`` (D3): the time from a FINGER report to the plate's change, s, and
how late the host read the device's reports.

Median, over :data:`LATENCY_TRIALS` moves of the host finger across a texture boundary, of the
time from sending the FINGER report to the measured plate amplitude crossing half way to its new
settled value; threshold from the timing class (real time: 10 ms: half the 20 ms period of a
50 Hz touch screen, so a change is felt before the next touch sample).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hcard import build
from hcard.device.base import Driver
from hcard.device.protocol import Finger, State
from hcard.quantities import MS_PER_S, S_PER_US
from hcard_conformance.check_names import DEVICE_LATENCY as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, READ_CATCH_UP_S, judged
from hcard_conformance.realtime import NotKept, attempts, collection_deferred, device_lag
from hcard_conformance.result import CannotAssess, CheckResult, guarded
from hcard_conformance.timing import timing_class

LATENCY_TRIALS = 10
"""Moves of the host finger across the boundary in one latency run."""
LATENCY_LATE_S = 0.005
"""Largest lateness of the host in a kept latency trial timed when the host read its reports
(a device before protocol 1.3; spec QT3), s: its loop not iterating, or a FINGER report's send
call taking longer. Half the 10 ms D3 bound, as PI4's own margin. A trial in which the device
flagged a report REALTIME_LAG (device protocol PI4) is never kept."""
READ_WINDOW_S = 0.1
"""Window of the host's reads of which a real-time run keeps the freshest (smallest read lag)
for ``host-read-lag``, s: a host that falls behind reads a backlog, oldest first, and catches
up within a few ms once it runs; over 100 ms it reads at least one report as fresh as the
delivery makes it, unless it did not run for the whole window."""
MIN_READ_LAGS = 10
"""Windows a real-time run needs for its ``host-read-lag``."""


def freshest_reads(reads: Sequence[tuple[float, float]],
                   window_s: float = READ_WINDOW_S) -> list[float]:
    """The smallest read lag (s) of each ``window_s`` of the host's clock that holds reads:
    ``reads`` are (host clock of the read, read lag), s. The host's backlog (its own lateness)
    is left out; what stays is the device's and the transport's delivery (spec QT3)."""
    best: dict[int, float] = {}
    for at, lag in reads:
        key = math.floor(at / window_s)
        best[key] = min(best.get(key, math.inf), lag)
    return [best[key] for key in sorted(best)]
MIN_KEPT_TRIALS = LATENCY_TRIALS // 2
"""Kept trials a latency run needs, else it is measured again (the median of fewer says more
about which trials were kept than about the device)."""


@dataclass(frozen=True)
class LatencyRun:
    """What :func:`measure_latency` saw.

    Attributes:
        latencies_s: per trial, the time from the first FINGER report on the new texture to
            the first report past half the amplitude change, s (NaN: never crossed).
        read_lag_s: per report, how long after its own time on the host clock (PI3: echoed
            sample's host time + echo age) the host read it, s: the host's read backlog
            (with the fastest one-way transit); for a real-time host the freshest read of
            each :data:`READ_WINDOW_S` (:func:`freshest_reads`: the delivery, the host's own
            lateness left out, spec QT3). Empty when the device does not date its reports
            (protocol before 1.3).
        kept: per trial, whether the host and the device kept real time in it (spec QT3).
        not_kept: why each trial that was not kept was not (one line each).
        host_late_s: the host's longest lateness over the run (loop gaps, sends), s.
        dated_reports: reports read that the device dated (PI3), on time or not.
    """

    latencies_s: list[float]
    read_lag_s: list[float]
    kept: list[bool]
    not_kept: list[str]
    host_late_s: float = 0.0
    dated_reports: int = 0

    @property
    def kept_latencies_s(self) -> list[float]:
        """The latencies of the kept trials, s."""
        return [lat for lat, ok in zip(self.latencies_s, self.kept, strict=True) if ok]


def measure_latency(driver: Driver, trials: int = LATENCY_TRIALS, *,
                    dated: bool = False) -> LatencyRun:
    """Latencies from a FINGER report moving onto a UV 0.4 taxtel to the measured plate
    amplitude crossing half its settled value (method of bench/bench_device_latency.py).

    A real-time host times the crossing report by its own time on the host clock (PI3: echoed
    sample + echo age) plus the run's smallest read lag (the fastest delivery of a report to
    the host, with the fastest one-way transit the device's clock offset took out, PO2): that
    is the time from the send to the report's frame plus the fastest delivery, the transport
    included and the host's own lateness in reading left out. A trial is kept unless a report
    of it carries REALTIME_LAG (spec QT3). A device before protocol 1.3 is timed when the host
    read the report, and a trial is kept only when also the host's loop never went
    :data:`LATENCY_LATE_S` without iterating and no send took longer. With ``dated`` (a host
    that cannot read in real time, timing class ``software-emulation``) a report is timed at
    its own time on the host clock alone and every trial is kept. Each position is held until
    the host has read the reports of the whole hold, however late it reads them."""
    info = driver.info()
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    card = build.card(width, height, taxtel_mm=(width / 2, height), textures=[
        build.texture(1.0, channel="uv"), build.texture(0.4, channel="uv")],
        texture_index=[0, 1])
    left, right, y = width / 4, 3 * width / 4, height / 2
    driver.upload_card(card)
    driver.set_touch_source(host=True)
    driver.start()
    read_lag: list[float] = []

    @dataclass
    class Hold:
        """The reports of one hold: (state, time since the first send by read, by own time),
        the host's longest lateness in sending (from the time a FINGER carries to the end of
        its send) and in its loop (between two iterations), s."""

        seen: list[tuple[State, float, float | None]]
        send_late_s: float
        loop_late_s: float

    reads: list[tuple[float, float]] = []  # (host clock of the read, read lag), s

    def hold(x: float, seconds: float, poll_s: float = 0.0005) -> Hold:
        """Send the finger at ``x`` (twice: zero velocity) every 10 ms until the host has read
        the reports of ``seconds`` after the first send (at most :data:`READ_CATCH_UP_S`
        more); the reports that echo a sample of this hold (the device applied it: those
        still echoing an earlier one, read late, belong to an earlier position)."""
        seen: list[tuple[State, float, float | None]] = []
        start = driver.clock()
        start_us = Finger.from_si(start, 0.0, 0.0, 0.0, False).host_time_us
        sent: set[int] = set()
        next_send = start
        covered = -math.inf  # time since the first send that the reports read reach, s
        send_late, loop_late, last = 0.0, 0.0, start
        while True:
            now = driver.clock()
            loop_late, last = max(loop_late, now - last), now
            if now >= next_send:
                t = start if next_send == start else now
                driver.send_finger(t, x, y, 0.5, True)
                driver.send_finger(t, x, y, 0.5, True)
                sent.add(Finger.from_si(t, 0.0, 0.0, 0.0, False).host_time_us)
                next_send += 0.01
                send_late = max(send_late, driver.clock() - t)  # from the time they carry
            for state in driver.collect_until(driver.clock() + poll_s):
                now_read = driver.clock()
                read = now_read - start
                own = _host_time_since(state, start_us)
                if own is not None:
                    read_lag.append(read - own)
                    reads.append((now_read, read - own))
                if state.host_time_echo_us in sent:
                    seen.append((state, read, own))
                    covered = max(covered, own if dated and own is not None else read)
            if covered >= seconds or now >= start + seconds + READ_CATCH_UP_S:
                return Hold(seen, send_late, loop_late)

    holds: list[Hold] = []
    with collection_deferred():  # a collection's pause is host lateness (spec QT3)
        hold(left, 0.05)
        for _ in range(trials):
            holds.append(hold(right, 0.06))
            hold(left, 0.04)
    driver.stop()
    floor = min(read_lag, default=math.nan)
    latencies: list[float] = []
    kept: list[bool] = []
    why: list[str] = []
    for k, h in enumerate(holds):
        own_times = all(own is not None for _, _, own in h.seen)
        if own_times and (dated or math.isfinite(floor)):
            # by the device's account (PI3), plus the fastest delivery when timed as read
            shift = 0.0 if dated else floor
            timed = [(s, own + shift) for s, _, own in h.seen if own is not None]
            if dated:  # reports past the hold were read early; their own times are not lag
                timed = [(s, t) for s, t in timed if t <= 0.06]
        else:
            timed = [(s, read) for s, read, _ in h.seen]
        seen = sorted((pair for pair in timed if pair[1] >= 0.0), key=lambda pair: pair[1])
        settled = float(np.mean([s.amplitude_m for s, _ in seen[-10:]])) if seen else math.nan
        latencies.append(next((dt for s, dt in seen if s.amplitude_m >= settled / 2), math.nan))
        # timed by own time, the host's lateness in reading is left out (and a FINGER is
        # written to the link at once: lateness there would need the process preempted
        # between reading the clock and writing, a rare event the median absorbs); timed by
        # read, every gap of the host's loop counts
        late_s = 0.0 if own_times else max(h.send_late_s, h.loop_late_s)
        problems = [] if dated else [p for p in (
            f"the host ran {late_s * MS_PER_S:.0f} ms late" if late_s > LATENCY_LATE_S else "",
            device_lag([s for s, _, _ in h.seen])) if p]
        kept.append(not problems)
        if problems:
            why.append(f"trial {k + 1}: {'; '.join(problems)}")
    return LatencyRun(latencies, read_lag if dated else freshest_reads(reads), kept, why,
                      max((max(h.loop_late_s, h.send_late_s) for h in holds), default=0.0),
                      len(read_lag))


def _host_time_since(state: State, start_us: int) -> float | None:
    """The report's time on the host clock (PI3: echoed sample's host time + echo age) less
    the host time ``start_us``, s (modulo the 32-bit host time; within +-35 min); None when
    the device does not say (no echo yet, or protocol before 1.3)."""
    age = state.echo_age_s
    if age is None or state.host_time_echo_us == 0:
        return None
    modulo = 1 << 32
    since_us = (state.host_time_echo_us - start_us + modulo // 2) % modulo - modulo // 2
    return since_us * S_PER_US + age


LATENCY_CASES = ("boundary-move", "host-read-lag")
"""The cases of ``device.latency``, in order (the second reads the first's run)."""


def check_latency(ctx: Context) -> Iterator[CheckResult]:
    """End-to-end latency from a host finger update to the plate's change, and (case
    ``host-read-lag``) how late the host read the device's reports."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver
    timing = timing_class(ctx)
    runs: list[LatencyRun] = []

    def latency_run() -> LatencyRun:
        """One run, kept when at least :data:`MIN_KEPT_TRIALS` of its trials were (QT3)."""
        with open_driver() as driver:
            run = measure_latency(driver, dated=not timing.keeps_real_time)
        if len(run.kept_latencies_s) < MIN_KEPT_TRIALS:
            raise NotKept(f"{len(run.kept_latencies_s)} of {len(run.latencies_s)} trials kept "
                          f"(at least {MIN_KEPT_TRIALS} needed): {'; '.join(run.not_kept)}")
        if timing.keeps_real_time and run.dated_reports and len(run.read_lag_s) < MIN_READ_LAGS:
            raise NotKept(f"the host read reports in {len(run.read_lag_s)} windows of "
                          f"{READ_WINDOW_S * MS_PER_S:.0f} ms (at least {MIN_READ_LAGS} needed "
                          f"for host-read-lag; it did not run for up to "
                          f"{run.host_late_s * MS_PER_S:.0f} ms)")
        return run

    def measure() -> Iterator[CheckResult]:
        run = attempts(latency_run, "the latency run")
        runs.append(run)
        lat = run.kept_latencies_s
        timed = ("reports timed on the host clock by the device (PI3), without the host's "
                 "read backlog or the fastest transit" if not timing.keeps_real_time
                 else "reports timed by their own time on the host clock (PI3) plus the "
                 "fastest delivery (the host's lateness in reading left out)")
        left_out = (f"; {len(run.latencies_s) - len(lat)} trials not kept in real time and "
                    f"left out ({run.not_kept[0]}{', ...' if len(run.not_kept) > 1 else ''})"
                    if len(lat) < len(run.latencies_s) else "")
        yield judged(CHECK, LATENCY_CASES[0], "median_latency",
                      float(np.median(lat)) * MS_PER_S, timing.latency_s * MS_PER_S, "ms",
                      f"{len(lat)} moves, max {np.nanmax(lat) * MS_PER_S:.1f} ms; {timed}"
                      f"{left_out}; {timing.why}")

    def read_lag() -> Iterator[CheckResult]:
        if not runs:
            raise CannotAssess("the latency run did not complete")
        if not runs[0].read_lag_s:
            raise CannotAssess("the device does not date its reports (echo age, protocol 1.3 "
                               "PI3)")
        lags = np.asarray(runs[0].read_lag_s)
        yield judged(CHECK, LATENCY_CASES[1], "median_read_lag",
                      float(np.median(lags)) * MS_PER_S, timing.read_lag_s * MS_PER_S, "ms",
                      f"{lags.size} {'windows' if timing.keeps_real_time else 'reports'}, "
                      "90th percentile "
                      f"{np.percentile(lags, 90) * MS_PER_S:.1f}"
                      f" ms (read time less the report's own time on the host clock, PI3"
                      f"{'; the freshest read of each 100 ms' if timing.keeps_real_time else ''}"
                      f"); {timing.why}")

    yield from guarded(CHECK, LEVEL, LATENCY_CASES[:1], measure)
    yield from guarded(CHECK, LEVEL, LATENCY_CASES[1:], read_lag)
