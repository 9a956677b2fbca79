"""Check ``device.safety`` (S1): measured outputs never exceed the limits in force (amplitude
in m, voltage in V, current in A).

Cards, host-set limits and streamed frames asking for more than the limits; metric: the number
of reports whose measured amplitude / voltage / current exceeds the limit in force (one report
count of quantisation allowed) or whose targets leave [0, 1] x [1, 4]; must be 0. Case
``limits-while-driven`` (PS1, PS5) lowers the limits to :data:`LOWERED_FRACTION` of those in
force while streamed frames drive the plate at its limit, and counts the reports after the
change (those echoing a FINGER sent after the SET returned) with an output above the new limit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hcard import build
from hcard.device.base import Driver
from hcard.device.play import play
from hcard.device.protocol import Capability, FaultBits, Limits, State
from hcard.quantities import NM_PER_M, UA_PER_A
from hcard.track import straight_stroke
from hcard_conformance.check_names import DEVICE_SAFETY as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, OFF_AMPLITUDE_M, STROKE_SPEED_MM_S, judged
from hcard_conformance.device_checks.host_finger import HostFinger, stroke
from hcard_conformance.realtime import (
    HostWatch,
    NotKept,
    attempts,
    collection_deferred,
    device_lag,
    reasons,
)
from hcard_conformance.result import CannotAssess, CheckResult, guarded
from hcard_conformance.streaming import lead_frames, require_fed


def _over(states: Sequence[State], driver: Driver) -> tuple[int, float]:
    """Reports with a measured output above its limit in force (one report count of
    quantisation allowed) or a target outside [0, 1] x [1, 4], and the worst output/limit."""
    limits = driver.limits()
    over = np.zeros(len(states), dtype=bool)
    worst = 0.0
    for value, limit, count in (
        (np.array([s.amplitude_m for s in states]), limits.max_amplitude_m, 1e-9),
        (np.array([s.voltage_v for s in states]), limits.max_voltage_v, 0.1),
        (np.array([s.current_a for s in states]), limits.max_current_a, 1e-8),
    ):
        over |= value > limit + count
        if limit > 0 and value.size:
            worst = max(worst, float(value.max()) / limit)
    targets = np.array([(s.target_uv, s.target_ev) for s in states]).reshape(-1, 2)
    over |= (targets[:, 0] < 0) | (targets[:, 0] > 1) | (targets[:, 1] < 1) | (targets[:, 1] > 4)
    return int(np.count_nonzero(over)), worst


def _wait_for_rest(driver: Driver, timeout_s: float = 0.5) -> None:
    """Read STATE reports until the outputs are off (a device that stays powered may still be
    ramping down from the previous session), at most ``timeout_s``."""
    end = driver.clock() + timeout_s
    while driver.clock() < end:
        states = driver.collect_until(driver.clock() + 0.005)
        if states and all(s.amplitude_m <= OFF_AMPLITUDE_M and s.voltage_v <= 1.0
                          for s in states[-3:]):
            return


SAFETY_CASES = ("card-over-limit", "host-limits", "stream-extremes", "limits-while-driven")
"""The cases of the safety check, in order."""

LOWERED_FRACTION = 0.25
"""Case ``limits-while-driven``: the limits are lowered to this fraction of those in force. The
plate, driven at the amplitude limit, is then 4 times over the new one: left to decay at its own
rate it takes ``tau ln 4`` to get under it (E-ViTa 2.2 ms, coupled stimulator 9.5 ms, two and
nine report periods), so a device that does not brake it shows in the reports after the SET."""
DRIVEN_S = 0.08
"""Streaming before the limits are lowered, s (the plate settles at its limit in ~5 ms)."""
AFTER_CHANGE_S = 0.05
"""Streaming after the limits are lowered, s, at least."""
MIN_REPORTS_AFTER = 30
"""Reports after the change the case waits for (a loaded host or transport may deliver the first
FINGER after the SET late), at most :data:`AFTER_CHANGE_TIMEOUT_S`."""
AFTER_CHANGE_TIMEOUT_S = 1.0
"""Longest streaming after the change while waiting for :data:`MIN_REPORTS_AFTER`, s."""
MIN_OVER_NEW_LIMIT = 2.0
"""The plate must be at least this many times the new amplitude limit just before the change,
or the case assesses nothing (UNASSESSED)."""
REPORT_QUANTA = (1e-9, 0.1, 1e-8)
"""One report count of amplitude (m), voltage (V) and current (A): the measurement tolerance of
the safety cases."""


@dataclass(frozen=True)
class LimitsChange:
    """The reports after lowering the limits while the plate is driven.

    Attributes:
        reports: STATE reports after the change (echoing a FINGER sent after the SET).
        over: those with a measured output above the new limit plus one report count.
        worst: largest measured output / new limit among them.
        before_m: median plate amplitude of the last 5 reports before the change, m.
        lowered: the limits set (wire counts).
        read_back: LIMITS read right after the SET.
    """

    reports: int
    over: int
    worst: float
    before_m: float
    lowered: Limits
    read_back: Limits

    @property
    def detail(self) -> str:
        """One line for the result."""
        low = self.lowered
        return (f"{self.over} of {self.reports} reports after the SET over the new limits "
                f"({low.max_amplitude_m * NM_PER_M:.0f} nm, {low.max_voltage_v:g} V, "
                f"{low.max_current_a * UA_PER_A:g} uA; read back "
                f"{'the same' if self.read_back == low else str(self.read_back)}); plate at "
                f"{self.before_m * NM_PER_M:.0f} nm before; largest output {self.worst:.3f} x its "
                f"new limit (tolerance one report count)")


def over_limits(states: Sequence[State], new: Limits) -> tuple[int, float]:
    """Reports with an output above its limit in ``new`` plus :data:`REPORT_QUANTA`, and the
    largest output / limit (also ``device.profile-upload``'s count under a host profile)."""
    over = np.zeros(len(states), dtype=bool)
    worst = 0.0
    for field, limit, quantum in zip(
            ("amplitude_m", "voltage_v", "current_a"),
            (new.max_amplitude_m, new.max_voltage_v, new.max_current_a), REPORT_QUANTA,
            strict=True):
        value = np.array([getattr(s, field) for s in states], dtype=float)
        over |= value > limit + quantum
        if limit > 0 and value.size:
            worst = max(worst, float(value.max()) / limit)
    return int(np.count_nonzero(over)), worst


def measure_limits_while_driven(driver: Driver, base: Limits) -> LimitsChange:
    """Stream UV 0 (EV 4 with EV) with the host's finger sliding so the plate runs at its
    amplitude limit, SET LIMITS to :data:`LOWERED_FRACTION` of ``base`` after :data:`DRIVEN_S`,
    send a FINGER at once and keep streaming for :data:`AFTER_CHANGE_S` (longer, up to
    :data:`AFTER_CHANGE_TIMEOUT_S`, until :data:`MIN_REPORTS_AFTER` arrived). Every report echoing
    a FINGER sent after the SET returned is after the change (session-relative: the echoes name
    this session's finger reports, never the device's uptime) and must be under the new limits
    (PS1, PS5).

    Raises:
        CannotAssess: no HOST_FINGER, the plate was not driven over the new limit, or no report
            echoed a FINGER sent after the change.
    """
    info = driver.info()
    if not info.capabilities & Capability.HOST_FINGER:
        raise CannotAssess("the device takes no FINGER reports: the reports after the change "
                           "cannot be told apart")
    rate = float(info.frame_rate_hz)
    ev = 4.0 if info.capabilities & Capability.EV else 1.0
    lead = lead_frames(int(info.stream_capacity_frames), rate)
    lowered = Limits.from_si(base.max_amplitude_m * LOWERED_FRACTION,
                             base.max_voltage_v * LOWERED_FRACTION,
                             base.max_current_a * LOWERED_FRACTION)
    finger = HostFinger(driver, stroke(info.surface_width_10um * 0.0025,
                                       info.surface_height_10um * 0.005, STROKE_SPEED_MM_S))
    watch = HostWatch(clock=driver.clock)
    driver.set_touch_source(host=True)
    driver.start()
    start = finger.start_s
    states: list[State] = []
    before: list[State] = []
    read_back: Limits | None = None
    sent, end, timeout, n_after = 0, math.inf, math.inf, 0
    while driver.clock() < timeout and (driver.clock() < end or n_after < MIN_REPORTS_AFTER):
        now = driver.clock()
        if read_back is None:
            watch.tick()  # the host's loop before the change: a late one starves the plate
        finger.feed()
        due = lead + int((now - start) * rate)
        if due > sent:
            driver.stream_frames(np.zeros(due - sent), np.full(due - sent, ev))
            sent = due
        new = driver.collect_until(driver.clock() + 0.001)
        n_after += sum(s.host_time_echo_us in finger.after_us for s in new)
        states += new
        if read_back is None and driver.clock() >= start + DRIVEN_S:
            before = list(states)
            driver.set_report(lowered)
            finger.mark()
            finger.send()  # the first FINGER after the change, as soon as the SET returned
            read_back = driver.limits()
            end = driver.clock() + AFTER_CHANGE_S
            timeout = driver.clock() + AFTER_CHANGE_TIMEOUT_S
    driver.stop()
    assert read_back is not None
    driven = float(np.median([s.amplitude_m for s in before[-5:]])) if before else 0.0
    settled = before[len(before) // 2:]
    require_fed(sum(s.stream_queued == 0 for s in settled), len(settled),
                f"the stream before the change (plate at {driven * NM_PER_M:.0f} nm)")
    if not driven >= MIN_OVER_NEW_LIMIT * lowered.max_amplitude_m:
        reason = (f"the plate was at {driven * NM_PER_M:.0f} nm before the change, not "
                  f"{MIN_OVER_NEW_LIMIT:g} x the new {lowered.max_amplitude_m * NM_PER_M:.0f} nm "
                  "limit")
        watchdog = ("the watchdog tripped (the host's finger came late)"
                    if any(s.faults & FaultBits.WATCHDOG for s in settled) else "")
        late = reasons(watch.late if driver.realtime else "", device_lag(before), watchdog)
        if late:  # the host or the device did not keep real time (spec QT3)
            raise NotKept(f"{reason}: {late}")
        raise CannotAssess(reason)
    after = [s for s in states if s.host_time_echo_us in finger.after_us]
    if not after:
        raise CannotAssess("no report echoed a FINGER sent after the change")
    over, worst = over_limits(after, lowered)
    return LimitsChange(len(after), over, worst, driven, lowered, read_back)


def measure_safety(open_driver: Callable[[], Driver]) -> Iterator[tuple[str, int, float, str]]:
    """Per case as it is measured (case, reports over a limit, the worst measured output /
    limit, a detail line): a card asking for more than the device can do, the same under host
    limits halved, streamed extreme frames, and limits lowered while the plate is driven
    (:func:`measure_limits_while_driven`)."""
    out: dict[str, tuple[int, float]] = {}
    with open_driver() as driver:
        info = driver.info()
        w, h = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
        greedy = build.card(w, h, taxtel_mm=(w / 2, h), textures=[
            build.texture(0.0, channel="uv"),
            build.texture(4.0, channel="ev") if info.capabilities & Capability.EV
            else build.texture(0.0, channel="uv")],
            texture_index=[0, 1])
    track = straight_stroke((w / 4, h / 2), (100.0, 0.0), 0.4)
    with open_driver() as driver:
        out["card-over-limit"] = _over(play(driver, greedy, track).states, driver)
    with open_driver() as driver:
        _wait_for_rest(driver)  # lowered at rest; lowering while driven is another matter
        hw = driver.limits()
        driver.set_limits(hw.max_amplitude_m / 2, hw.max_voltage_v / 2, hw.max_current_a / 2)
        try:
            out["host-limits"] = _over(play(driver, greedy, track).states, driver)
        finally:  # a device stays powered between runs: leave its limits as they were
            driver.set_limits(hw.max_amplitude_m, hw.max_voltage_v, hw.max_current_a)
    with open_driver() as driver:
        driver.send_finger(driver.clock(), w / 2, h / 2, 0.5, True)
        n = round(0.1 * info.frame_rate_hz)
        uv = np.zeros(n)
        driver.start()
        states: list[State] = []
        for k in range(0, n, 100):
            driver.stream_frames(uv[k:k + 100], np.full(100, 4.0))
            driver.send_finger(driver.clock(), w / 2, h / 2, 0.5, True)
            states += driver.collect_until(driver.clock() + 0.01)
        driver.stop()
        out["stream-extremes"] = _over(states, driver)
    for case, (n, worst) in out.items():
        yield case, n, worst, f"largest measured output {worst:.3f} x its limit in force"

    def lowered_while_driven() -> LimitsChange:
        with open_driver() as driver:
            _wait_for_rest(driver)
            base = driver.limits()
            try:
                with collection_deferred():  # a collection's pause would starve the plate
                    return measure_limits_while_driven(driver, base)
            finally:  # leave the limits as they were, as host-limits does
                driver.set_limits(base.max_amplitude_m, base.max_voltage_v, base.max_current_a)

    change = attempts(lowered_while_driven, "the limits-while-driven run")
    yield "limits-while-driven", change.over, change.worst, change.detail


def check_safety(ctx: Context) -> Iterator[CheckResult]:
    """Outputs stay within the limits in force whatever is asked (spec PS1)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def measure() -> Iterator[CheckResult]:
        for case, n_over, _worst, detail in measure_safety(open_driver):
            yield judged(CHECK, case, "n_over", n_over, 0.0, "reports", detail)

    yield from guarded(CHECK, LEVEL, SAFETY_CASES, measure)
