"""Real-time runs in the tests: repeated while the machine could not keep them, never hidden.

A test that judges a device served in real time (``tests/helpers/served_device.py``, ``usbip://``)
judges a run of the device and of the test's own process together. On a loaded machine either
may fall behind; the run then measures the lateness (spec/conformance.md QT3; the device says so
itself from protocol 1.4, PI4). Such a run is measured again, at most
:data:`~hcard_conformance.realtime.ATTEMPTS` times in all (3). When no attempt was kept the test
FAILS, saying that the machine could not keep real time and why each attempt was not kept: a
real-time verdict that depends on an idle machine is a defect, and a test that skipped it would
hide one. A run that was kept is judged as usual, so a faulty device still fails.

* :func:`in_real_time` runs a test's own real-time measurement, which raises
  :class:`~hcard_conformance.realtime.NotKept` when its run was not kept: a block under
  :func:`kept_run` does so when an assertion fails in a run the host or the device did not
  keep;
* :func:`assert_conforms` judges a conformance report, whose cases are already measured again by
  the suite (QT3): an UNASSESSED case whose every run was not kept fails the test with the
  machine's reason, any other non-PASS with the device's.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TypeVar

import pytest

from hcard.device.protocol import State
from hcard_conformance.realtime import (
    ATTEMPTS,
    HostWatch,
    NotKept,
    device_lag,
    host_priority,
    not_kept_results,
    reasons,
)
from hcard_conformance.result import CheckResult

__all__ = ["MACHINE", "HostWatch", "NotKept", "assert_conforms", "in_real_time", "kept_run"]

T = TypeVar("T")
MACHINE = "the machine could not keep real time"
"""How a test that failed for lack of real time begins its message."""


def in_real_time(run: Callable[[], T], what: str, attempts: int = ATTEMPTS) -> T:
    """``run()`` again while it raises NotKept, at most ``attempts`` times, each at the host
    priority the conformance suite asks for (:func:`host_priority`); the first kept run's
    value. When none was kept the test fails with :data:`MACHINE` and every reason."""
    why: list[str] = []
    for attempt in range(1, attempts + 1):
        try:
            with host_priority():  # a real-time host asks to be one, as the suite does (QT3)
                return run()
        except NotKept as exc:
            why.append(f"attempt {attempt}: {exc}")
    pytest.fail(f"{MACHINE} for {what} in {attempts} attempts: {'; '.join(why)}",
                pytrace=False)


@contextlib.contextmanager
def kept_run(states: Sequence[State] = ()) -> Iterator[HostWatch]:
    """The block is one real-time run, watched (:class:`HostWatch`): an assertion that fails
    in it (``assert``, ``pytest.raises``, ``pytest.fail``) becomes NotKept when the host did
    not run for longer than the watch's bound or the device flagged a report of ``states``
    REALTIME_LAG (PI4; the block may fill the list as it reads); in a run that was kept it
    stands, and the test fails with the device's verdict."""
    with HostWatch() as watch:
        try:
            yield watch
        except (AssertionError, pytest.fail.Exception) as exc:
            late = reasons(watch.late, device_lag(list(states)))
            if late:
                raise NotKept(f"{late}; the run found: {exc}") from exc
            raise


def assert_conforms(results: Iterable[CheckResult]) -> None:
    """Every case of a conformance run passed. An UNASSESSED case that the suite could not
    measure in real time in any of its runs (QT3) fails the test with :data:`MACHINE`; a case
    that failed otherwise fails it with the device's verdict (both listed)."""
    bad = [r for r in results if not r.passed]
    if not bad:
        return
    machine = not_kept_results(bad)
    device = [(r.check, r.case, r.status, r.detail) for r in bad if r not in machine]
    if device:
        pytest.fail(f"cases that did not pass: {device}"
                    + (f"; and {MACHINE} for {[(r.check, r.case) for r in machine]}"
                       if machine else ""), pytrace=False)
    pytest.fail(f"{MACHINE} for {len(machine)} cases: "
                + "; ".join(f"{r.check} {r.case}: {r.detail}" for r in machine), pytrace=False)
