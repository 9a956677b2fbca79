"""A host that plays to a device in real time asks its operating system to run it ahead of
ordinary processes (spec/conformance.md QT3); and it defers its interpreter's cyclic garbage
collection to the end of the run (:func:`collection_deferred`).

Two strengths: :func:`host_priority`, a lower nice value, for a whole command or suite (it also
renders, fits and writes files for seconds at a time, which must not hold a CPU against every
other process); and :func:`real_time_priority`, round-robin real-time scheduling below the
device's own (:func:`hcard_device.usb.server.raise_priority`), for one real-time run only (a
stream, a play, a measured case): on 2 cores with two CPU burners a host at nice -10 still left
a device's stream queue empty for 123 of 966 reports, because a nice value only weighs a share
of a core that the device's real-time threads and the burners divide between them.
"""

from __future__ import annotations

import contextlib
import gc
import os
from collections.abc import Iterator

HOST_NICE = -10
"""Nice value a real-time host asks for while it plays or measures: about nine times the CPU
share of an ordinary process (each step is ~1.25x)."""


@contextlib.contextmanager
def collection_deferred() -> Iterator[None]:
    """The interpreter's cyclic garbage collection waits for the end of the block (a real-time
    run: a play, a measurement); reference counting still frees what the block drops (a play
    allocates reports, no cycles, so nothing piles up). A full collection stops every thread
    of the process; in the conformance suite's process it took 50-200 ms, in a process
    holding millions of objects (a test run, a notebook) 0.5 s, and the device keeps only 32
    STATE reports (32 ms) for the host: the reports of that pause were lost."""
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()


@contextlib.contextmanager
def host_priority() -> Iterator[str]:
    """Run the calling thread, and the threads it starts meanwhile (they inherit it), at nice
    :data:`HOST_NICE` where permitted (root or CAP_SYS_NICE; otherwise as it was, EPERM is not
    an error), and give the previous value back on exit. Yields what was granted. On a loaded
    2-core machine (two CPU burners) it took a host's median read lag of the device's reports
    from 42 ms to 9 ms, what the same host reads with no burner."""
    before = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        os.setpriority(os.PRIO_PROCESS, 0, min(before, HOST_NICE))
        granted = f"nice {min(before, HOST_NICE)}"
    except OSError:
        granted = f"nice {before} (no higher priority permitted)"
    try:
        yield granted
    finally:
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, 0, before)


_REAL_TIME_ALLOWED = [True]
"""Whether :func:`real_time_priority` may ask for ``SCHED_RR`` (see :func:`real_time_allowed`)."""


@contextlib.contextmanager
def real_time_allowed(allowed: bool) -> Iterator[None]:
    """Within the block, :func:`real_time_priority` asks for real-time scheduling only when
    ``allowed`` (else for a nice value). A host that does not keep real time anyway gains
    nothing from it and must not take it: under software emulation (a TCG guest,
    spec/conformance.md 5.2) its one CPU also runs the guest's USB/IP kernel threads, at
    ordinary priority, which a real-time thread would run ahead of."""
    before = _REAL_TIME_ALLOWED[0]
    _REAL_TIME_ALLOWED[0] = allowed
    try:
        yield
    finally:
        _REAL_TIME_ALLOWED[0] = before


HOST_RT_PRIORITY = 5
"""``SCHED_RR`` priority of a host's real-time run: ahead of every ordinary process, behind the
served device's threads (priority 10) so that a host on the same machine never delays the
device it measures."""


@contextlib.contextmanager
def real_time_priority(priority: int = HOST_RT_PRIORITY) -> Iterator[str]:
    """Run the calling thread, and the threads it starts meanwhile, at ``SCHED_RR``
    ``priority`` (default :data:`HOST_RT_PRIORITY`) where permitted (root or CAP_SYS_NICE) and
    allowed (:func:`real_time_allowed`), else as :func:`host_priority`; the previous
    scheduling on exit. Yields what was granted. For one real-time run only (seconds): the
    kernel's real-time throttling still leaves ordinary processes 5 % of each CPU, and the run
    must not compute for long."""
    try:
        if not _REAL_TIME_ALLOWED[0]:
            raise PermissionError("real-time scheduling not allowed here")
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(priority))
    except (OSError, AttributeError):  # not permitted (or not Linux): a lower nice value
        with host_priority() as granted:
            yield granted
        return
    try:
        yield f"SCHED_RR {priority}"
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, policy, param)


@contextlib.contextmanager
def real_time_host() -> Iterator[str]:
    """:func:`host_priority` and :func:`collection_deferred` together: a host playing to a
    device on the wall clock (``hcard play``). Yields what priority was granted."""
    with host_priority() as granted, collection_deferred():
        yield granted
