"""Hooks of the whole run: its own cache directory, the order of the test files, the two lanes
of a parallel run, and the helpers' asserts rewritten like a test's. The helpers themselves are
modules of :mod:`tests.helpers`, imported by name."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

# A failing assert in a helper (tests/helpers/cli.py's one-line error, realtime.py's verdicts)
# shows its values as a failing assert in a test does.
pytest.register_assert_rewrite("tests.helpers")

FIRST = ("test_guest.py", "test_served_conformance.py")
"""Test files run before the others: the QEMU guest tier emulates a whole machine in software,
and its timing bounds are the first to go on a machine that has been busy for minutes (the
real-time device tests before it); the whole suite twice against one served reference, whose
`device.latency` was not kept in three attempts in two CI runs once the PN15 tests (hostile
USB/IP clients, in-process served controls) had run before it in the same worker, and passes
alone (the cause is not yet found)."""


WALL_CLOCK_LANE = "wall-clock"
"""The xdist group of the tests marked ``wall_clock``: devices served in real time over USB/IP
and the QEMU guest. With ``-n 2 --dist loadgroup`` (the README's test command) they run one
after another on one worker, never two at once, while the other worker runs everything else
(:data:`COMPUTE_LANE`): fits, renders and in-process devices whose clock is simulated."""
COMPUTE_LANE = "compute"
"""The xdist group of every test that is not marked ``wall_clock``."""
COMPUTE_NICE = 10
"""Nice value of the worker that runs the compute lane in a parallel run: the fits and
renders beside the wall-clock lane take what CPU it leaves (a CI run with both lanes at nice 0,
BLAS on two threads, saw the served reference's host stall for 144 ms and its plays not kept)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the files of :data:`FIRST` first, keeping the order within each group, and put
    each test in its lane (:data:`WALL_CLOCK_LANE` or :data:`COMPUTE_LANE`)."""
    items.sort(key=lambda item: item.path.name not in FIRST)
    for item in items:
        lane = WALL_CLOCK_LANE if item.get_closest_marker("wall_clock") else COMPUTE_LANE
        item.add_marker(pytest.mark.xdist_group(lane))


_COMPUTE_WORKER = pytest.StashKey[bool]()


def pytest_runtest_setup(item: pytest.Item) -> None:
    """In a parallel run (``PYTEST_XDIST_WORKER`` set), the worker that takes the compute lane
    yields to the wall-clock lane: nice :data:`COMPUTE_NICE` and one BLAS/OpenMP thread, from
    its first compute test on (a group stays on one worker). A run in one process is left as
    it is: its real-time tests run alone."""
    config = item.config
    if (not os.environ.get("PYTEST_XDIST_WORKER") or config.stash.get(_COMPUTE_WORKER, False)
            or item.get_closest_marker("wall_clock")):
        return
    config.stash[_COMPUTE_WORKER] = True
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, 0, max(os.getpriority(os.PRIO_PROCESS, 0),
                                                COMPUTE_NICE))
    from threadpoolctl import threadpool_limits

    config.stash[_THREAD_LIMIT] = threadpool_limits(limits=1)


_THREAD_LIMIT = pytest.StashKey[object]()
_CACHE_DIRECTORY = pytest.StashKey[tuple[pytest.MonkeyPatch, Path]]()


def pytest_configure(config: pytest.Config) -> None:
    """Point ``XDG_CACHE_HOME`` at a fresh directory of the run's own.

    Plugin discovery remembers the entry points and contributed commands it found in the
    user's cache directory (:mod:`hcard.plugins.command_cache`): the test run, and the commands it
    starts, keep theirs in a directory of their own instead of the user's. This must precede
    collection, since test modules call ``get_registry()`` at import (a session fixture would
    come too late). Each pytest-xdist worker runs this hook as well and gets a directory of its
    own."""
    patch = pytest.MonkeyPatch()
    directory = Path(tempfile.mkdtemp(prefix="hcard-xdg-"))
    patch.setenv("XDG_CACHE_HOME", str(directory))
    config.stash[_CACHE_DIRECTORY] = (patch, directory)


def pytest_unconfigure(config: pytest.Config) -> None:
    """Restore ``XDG_CACHE_HOME`` and remove the run's cache directory."""
    patch, directory = config.stash[_CACHE_DIRECTORY]
    patch.undo()
    shutil.rmtree(directory, ignore_errors=True)


def _scheduling() -> tuple[int, int, int]:
    """The calling thread's scheduling policy, its real-time priority and the nice value."""
    return (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
            os.getpriority(os.PRIO_PROCESS, 0))


@pytest.fixture(autouse=True)
def _scheduling_given_back() -> Iterator[None]:
    """Every test leaves the process's scheduling as it found it. The processes a test
    starts inherit its main thread's: one test that kept ``SCHED_RR`` (an in-process ``hcard
    device serve`` that returned) made every later ``hcard play`` and served device of its
    worker real-time, and real-time processes of one priority take turns in 100 ms slices on
    2 cores; the tests that then failed, minutes later, were not the one at fault. This one is
    named instead, and the scheduling is put back for the next. (The compute worker's nice
    value, raised once for its whole run by :func:`pytest_runtest_setup`, is not a change
    the tests make.)"""
    before = _scheduling()
    yield
    after = _scheduling()
    if after[:2] != before[:2] or after[2] < before[2]:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
            os.setpriority(os.PRIO_PROCESS, 0, before[2])
        pytest.fail(f"the test left this process's scheduling at policy {after[0]}, priority "
                    f"{after[1]}, nice {after[2]} (it was {before[0]}, {before[1]}, nice "
                    f"{before[2]}): the processes started after it would inherit it",
                    pytrace=False)
