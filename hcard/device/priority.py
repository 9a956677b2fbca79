"""A host that plays to a device in real time asks its operating system to run it ahead of
ordinary processes (spec/conformance.md QT3): :func:`host_priority`; and it defers its
interpreter's cyclic garbage collection to the end of the run (:func:`collection_deferred`).

The device side does the same (:func:`hcard_device.usb.server.raise_priority`, round-robin
real-time scheduling); a host asks only for a lower nice value, because it also renders, fits
and writes files for seconds at a time, which must not hold a CPU against every other process.
"""

from __future__ import annotations

import contextlib
import gc
import os
from collections.abc import Iterator

HOST_NICE = -10
"""Nice value a real-time host asks for while it plays or measures: about nine times the CPU
share of an ordinary process (each step is ~1.25x)."""
REALTIME_PRIORITY = 10
"""``SCHED_RR`` priority of a process that must keep real time on its machine: the reference
device's server (:func:`hcard_device.usb.server.raise_priority`) and a client that
measures what a served device delivers
(:func:`hcard_conformance.usbip_clients.real_time_thread`). Any real-time priority runs
before every ordinary process, and 10 leaves the kernel's own real-time threads, at 50 and
above, ahead of it."""


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


@contextlib.contextmanager
def real_time_host() -> Iterator[str]:
    """:func:`host_priority` and :func:`collection_deferred` together: a host playing to a
    device on the wall clock (``hcard play``). Yields what priority was granted."""
    with host_priority() as granted, collection_deferred():
        yield granted
