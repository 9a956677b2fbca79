"""Runs a device or its host could not keep in real time (spec/conformance.md QT3).

A device-level measurement is made by two machines at once: the device, which must produce a
STATE report per millisecond of its clock, and the host, which must send its finger samples and
read the reports on time. When either falls behind, a real-time measurement (latency, report
loss, a session kept alive while a second host acts, a stream that keeps the plate driven)
measures the lateness, not the device. Such a run is **not kept**: it is measured again, at most
:data:`ATTEMPTS` times in all, and when no attempt was kept the case is UNASSESSED with the
reason of each attempt, never a FAIL of the device. What the device did wrong regardless of
timing (a START not refused, a card replaced, a report misnumbered) is judged on any run.

What tells a run was not kept:

* the device's own account (protocol 1.4, rule PI4): fault REALTIME_LAG in a report of the run
  (:func:`device_lag`), or COUNTERS ``late_reports`` moving over it;
* the host's own clock (:class:`HostWatch`): the host process was not running for longer than
  a stated bound (its thread slept or waited for the CPU past it), so its FINGER samples left
  late and it read the reports late; a host loop also notes the gaps between its own
  iterations (:meth:`HostWatch.tick`).

A real-time host also asks to be one (:func:`host_priority`): while it measures a device in
real time, it runs ahead of the ordinary processes of its computer where the OS permits.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import TypeVar

import numpy as np

from hcard.device.priority import collection_deferred, host_priority
from hcard.device.protocol import FaultBits, State
from hcard.quantities import MS_PER_S
from hcard_conformance.result import CannotAssess, CheckResult, unassessed

__all__ = ["ATTEMPTS", "HOST_LATE_S", "NOT_KEPT", "HostWatch", "NotKept", "attempted_case",
           "attempts", "collection_deferred", "device_lag", "host_priority", "not_kept_results",
           "reasons"]

ATTEMPTS = 3
"""Runs of a measurement at most, while none was kept in real time (spec QT3)."""
HOST_LATE_S = 0.02
"""Longest time the host may not run (its loop not iterating, or its watch thread oversleeping)
in a run that is kept, s: 20 reports at 1 kHz, one 50 Hz touch period (the bound of the host's
own pauses in the report-loss check, spec 4.7)."""
WATCH_PERIOD_S = 0.005
"""Sleep of the :class:`HostWatch` thread between two looks at the host's clock, s: a quarter of
:data:`HOST_LATE_S` (each wake-up takes the interpreter lock from the host's reader; at 1 ms
the watch cost a host under software emulation most of its reports)."""
NOT_KEPT = "could not be kept in real time"
"""Words every reason of a run not kept contains (the tests look for them)."""

T = TypeVar("T")


class NotKept(CannotAssess):
    """Raised by a measurement whose run the device or the host did not keep in real time (the
    reason is the message); :func:`attempts` measures again."""


def device_lag(states: Sequence[State]) -> str:
    """Why the device did not keep real time over ``states`` (rule PI4): the reports flagged
    REALTIME_LAG; empty when none was."""
    late = sum(1 for s in states if s.faults & FaultBits.REALTIME_LAG)
    if not late:
        return ""
    return (f"the device flagged {late} of {len(states)} reports REALTIME_LAG (it produced them "
            "late on its real-time clock, device protocol PI4)")


CLOCK_RATE_TOLERANCE = 0.01
"""A device clock whose rate differs from the host's by more than this fraction is named in
the diagnosis of gaps between reports (:func:`clock_mismatch`)."""
_U16, _U32 = 1 << 16, 1 << 32


def clock_rate(states: Sequence[State]) -> float | None:
    """The device clock's rate against the host's over ``states``: the slope of the echoed
    samples' placements on the device clock (report timestamp less echo age, PI3) against their
    host times (``host_time_echo_us``), by least squares over the distinct echoes; None when
    fewer than three samples were echoed with an age. 1.0: the clocks agree; 0.9: the device's
    runs 10 % slow."""
    placed: dict[int, int] = {}
    for s in states:
        if s.host_time_echo_us and s.echo_age_s is not None:
            placed.setdefault(s.host_time_echo_us, s.timestamp_us - s.echo_age_us)
    if len(placed) < 3:
        return None
    host = np.unwrap(np.array(list(placed), dtype=float), period=_U32)
    device = np.unwrap(np.array(list(placed.values()), dtype=float), period=_U32)
    if np.ptp(host) <= 0:
        return None
    return float(np.polyfit(host - host[0], device - device[0], 1)[0])


def sequence_gaps(states: Sequence[State]) -> int:
    """STATE reports missing from ``states`` by their sequence numbers (wrapping u16)."""
    steps = np.mod(np.diff(np.array([s.sequence for s in states], dtype=np.int64)), _U16)
    return int(np.sum(steps[(steps > 1) & (steps < _U16 // 2)] - 1))


def clock_mismatch(states: Sequence[State]) -> str:
    """Why reports leave gaps on the host's time line though none was lost: the device's clock
    runs at another rate than the host's (more than :data:`CLOCK_RATE_TOLERANCE`) and the
    sequence numbers show no report missing; empty otherwise."""
    rate = clock_rate(states)
    if rate is None or abs(rate - 1.0) <= CLOCK_RATE_TOLERANCE or sequence_gaps(states):
        return ""
    pace = f"{abs(rate - 1.0):.1%} {'slow' if rate < 1.0 else 'fast'}"
    return (f"no report was lost (their sequence numbers run without a gap): the device's clock "
            f"runs {pace} against the host's (placements of the echoed samples, PI3, against "
            "their host times), so its reports' times on the host clock leave gaps")


class HostWatch:
    """How late the host process ran while a measurement lasted, on the host's own clock.

    Used as a context manager, a daemon thread sleeps :data:`WATCH_PERIOD_S` again and again and
    notes how much longer than that each sleep took (the process waited for a CPU, or for the
    interpreter lock behind a thread that computed); a host loop may also call :meth:`tick` at
    every iteration, which notes the time since its previous call. While it watches, the
    interpreter's cyclic garbage collection waits for the end of the run (reference counting
    still frees what a run drops): a full collection of a suite's process stops every thread
    for 50-200 ms, and the device's reports are lost meanwhile (the served conformance test on
    a loaded machine saw the host stop for up to 201 ms during plays, losing 7-26 % of a
    render's reports).

    Args:
        bound_s: longest lateness of a kept run, s.
        clock: the host's clock, s.
    """

    def __init__(self, bound_s: float = HOST_LATE_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.bound_s = bound_s
        self.clock = clock
        self.longest_s = 0.0
        """Longest lateness seen, s."""
        self.late_count = 0
        """Times the lateness exceeded :attr:`bound_s`."""
        self._last_tick: float | None = None
        self._deferred = collection_deferred()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def note(self, late_s: float) -> None:
        """Record one lateness of ``late_s`` s."""
        with self._lock:
            self.longest_s = max(self.longest_s, late_s)
            self.late_count += late_s > self.bound_s

    def tick(self) -> None:
        """A host loop's iteration: note the time since the previous one."""
        now = self.clock()
        if self._last_tick is not None:
            self.note(now - self._last_tick)
        self._last_tick = now

    def _watch(self) -> None:
        while not self._stop.is_set():
            before = time.monotonic()
            time.sleep(WATCH_PERIOD_S)
            self.note(time.monotonic() - before - WATCH_PERIOD_S)

    def __enter__(self) -> HostWatch:
        self._deferred.__enter__()
        self._thread = threading.Thread(target=self._watch, name="host-watch", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self._deferred.__exit__(None, None, None)

    @property
    def late(self) -> str:
        """Why the host did not keep real time (empty when it did)."""
        if self.longest_s <= self.bound_s:
            return ""
        return (f"the host did not run for up to {self.longest_s * MS_PER_S:.0f} ms "
                f"({self.late_count} times over {self.bound_s * MS_PER_S:.0f} ms)")


def reasons(*found: str) -> str:
    """The non-empty reasons of ``found``, joined."""
    return "; ".join(r for r in found if r)


def attempts(measure: Callable[[], T], what: str, count: int = ATTEMPTS) -> T:
    """``measure()`` again while it raises :class:`NotKept`, at most ``count`` runs, each at
    the host's real-time priority (:func:`host_priority`); the first kept run's value. When
    none was kept, raises :class:`CannotAssess` naming ``what`` and the reason of every
    attempt (spec QT3)."""
    why: list[str] = []
    for attempt in range(1, count + 1):
        try:
            with host_priority():
                return measure()
        except NotKept as exc:
            why.append(f"attempt {attempt}: {exc}")
    raise CannotAssess(f"{what} {NOT_KEPT} in {count} attempts ({'; '.join(why)})")


def attempted_case(check: str, level: str, case: str,
                   measure: Callable[[], CheckResult]) -> CheckResult:
    """One case's result by :func:`attempts`: UNASSESSED with the reasons when no run was
    kept (the other cases of a check go on)."""
    try:
        return attempts(measure, f"the run of {case}")
    except CannotAssess as exc:
        return unassessed(check, level, case, str(exc))


def not_kept_results(results: Iterable[CheckResult]) -> list[CheckResult]:
    """The UNASSESSED results whose reason is a run not kept in real time."""
    return [r for r in results if r.status == "UNASSESSED" and NOT_KEPT in r.detail]
