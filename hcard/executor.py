"""Run one function over many items on Dask (``dask.distributed``), or in this process
(spec/calibration.md K26).

One job: make a client from the options (a local cluster of ``workers`` processes, each with
at most ``memory_per_worker`` of memory; or the scheduler at an address; or no cluster at all),
map a top-level function over keyed items with retries, yield each outcome as it completes
with one progress line per finished task, and close what it started. A task's function must be
importable by name on the workers (a module-level function, no lambda or closure), and its
argument picklable; a task should read its own inputs (file paths, not arrays) so that a
worker's memory holds one task's data.

Failures: an exception a task raises is retried ``retries`` times (:data:`DEFAULT_RETRIES`),
then reported as that item's outcome (its key, the exception's type and message); the other
items go on. A task that wants a failure kept without retry returns it as a value.

Dask is imported only when a cluster is used: ``--workers 0`` / ``--scheduler none`` runs
the same function here, one item after another, with the same retries.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from hcard.errors import InputError

T = TypeVar("T")
R = TypeVar("R")

DEFAULT_RETRIES = 2
"""Times a task that raised is run again before its failure is reported."""

DEFAULT_MEMORY_PER_WORKER = "2GiB"
"""Memory limit of each local worker process (dask pauses a worker at 80 % of it, restarts
it at 95 %)."""

IN_PROCESS = "none"
"""The ``--scheduler`` value that runs every task in this process."""


def default_workers() -> int:
    """The local cluster's default size: ``min(4, CPUs)`` worker processes of one thread."""
    return min(4, os.cpu_count() or 1)


class ExecutorError(InputError):
    """Options that make no executor, or a scheduler that cannot be reached."""


@dataclass(frozen=True)
class ExecutorOptions:
    """Where tasks run.

    Attributes:
        scheduler: a Dask scheduler's address (``tcp://host:8786``) to use its cluster;
            :data:`IN_PROCESS` (``"none"``) to run in this process; None: a local cluster.
        workers: local cluster size (processes, one thread each); 0: in this process; None:
            :func:`default_workers`. Ignored with an address.
        memory_per_worker: memory limit of each local worker (dask's notation, e.g. ``"2GiB"``).
        retries: re-runs of a task that raised (:data:`DEFAULT_RETRIES`).
        processes: local workers are processes (True) or threads of this process (False:
            quicker to start, for tests).
    """

    scheduler: str | None = None
    workers: int | None = None
    memory_per_worker: str = DEFAULT_MEMORY_PER_WORKER
    retries: int = DEFAULT_RETRIES
    processes: bool = True

    @property
    def in_process(self) -> bool:
        """Whether the tasks run in this process, without Dask."""
        if self.scheduler is not None:
            return self.scheduler.strip().lower() == IN_PROCESS
        return self.workers == 0

    def describe(self) -> str:
        """Where the tasks run, in words."""
        if self.in_process:
            return "in this process"
        if self.scheduler is not None:
            return f"on the Dask scheduler at {self.scheduler}"
        n = default_workers() if self.workers is None else self.workers
        kind = "processes" if self.processes else "threads"
        return f"on a local Dask cluster of {n} worker {kind} ({self.memory_per_worker} each)"


IN_THIS_PROCESS = ExecutorOptions(scheduler=IN_PROCESS)
"""Options that run every task here (the library's default)."""


@dataclass(frozen=True)
class Outcome(Generic[R]):
    """One item's outcome.

    Attributes:
        key: the item's key (a participant label, a file name).
        value: the function's return value; None when it failed.
        error: ``"ExceptionType: message"`` after the last attempt failed; empty otherwise.
        attempts: times the function was run (1 + retries used), where known (a cluster
            reports only the last failure: then 0).
    """

    key: str
    value: R | None
    error: str = ""
    attempts: int = 1

    @property
    def ok(self) -> bool:
        """Whether the function returned."""
        return not self.error


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


class Executor:
    """A client of the options' executor; use as a context manager (the local cluster it
    started is closed on exit)."""

    def __init__(self, options: ExecutorOptions = IN_THIS_PROCESS) -> None:
        if options.retries < 0:
            raise ExecutorError("retries must be 0 or more")
        if options.workers is not None and options.workers < 0:
            raise ExecutorError("--workers must be 0 (in this process) or more")
        self.options = options
        self._client: Any = None
        self._cluster: Any = None
        if not options.in_process:
            self._start()

    def _start(self) -> None:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise ExecutorError(f"dask.distributed is not installed ({exc})") from exc
        options = self.options
        if options.scheduler is not None:
            try:
                self._client = Client(options.scheduler, timeout=10)
            except OSError as exc:
                raise ExecutorError(f"cannot reach the Dask scheduler at {options.scheduler}: "
                                    f"{exc}") from exc
            return
        n = default_workers() if options.workers is None else options.workers
        self._cluster = LocalCluster(
            n_workers=n, threads_per_worker=1, processes=options.processes,
            memory_limit=options.memory_per_worker, dashboard_address=None,
            silence_logs=logging.CRITICAL)
        self._client = Client(self._cluster)

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the client, and the local cluster when this executor started one."""
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def map(self, function: Callable[[T], R], items: Sequence[tuple[str, T]],
            progress: Callable[[str], None] | None = None) -> Iterator[Outcome[R]]:
        """``function(item)`` for every ``(key, item)``, yielded as each completes (in the
        given order in this process), each failure after :attr:`ExecutorOptions.retries`
        re-runs; ``progress`` gets one line per finished task
        (``"task 3/10 p002: done"`` or ``"task 3/10 p002: failed: ValueError: ..."``)."""
        say = progress or (lambda _text: None)
        total = len(items)
        outcomes = (self._here(function, items) if self._client is None
                    else self._on_cluster(function, items))
        for done, outcome in enumerate(outcomes, start=1):
            say(f"task {done}/{total} {outcome.key}: "
                + ("done" if outcome.ok else f"failed: {outcome.error}"))
            yield outcome

    def _here(self, function: Callable[[T], R], items: Sequence[tuple[str, T]]
              ) -> Iterator[Outcome[R]]:
        for key, item in items:
            yield _attempted(function, key, item, self.options.retries)

    def _on_cluster(self, function: Callable[[T], R], items: Sequence[tuple[str, T]]
                    ) -> Iterator[Outcome[R]]:
        from dask.distributed import as_completed

        client = self._client
        threads = sum(w.get("nthreads", 1)
                      for w in client.scheduler_info()["workers"].values()) or 1
        size = batch_size(len(items), threads)
        stamp = f"{getattr(function, '__name__', 'task')}-{time.time_ns()}"
        futures, batches = [], {}
        for index in range(0, len(items), size):
            batch = list(items[index:index + size])
            future = client.submit(_run_batch, function, batch, self.options.retries,
                                   key=f"{stamp}-{index}", retries=self.options.retries,
                                   pure=False)
            futures.append(future)
            batches[future.key] = batch
        for future in as_completed(futures):
            batch = batches[future.key]
            if future.status == "finished":
                yield from future.result()
            else:  # the worker itself failed (a crash, a lost connection), retries used
                error = _error_text(future.exception())
                for key, _item in batch:
                    yield Outcome(key, None, error, 0)
            future.release()


TASKS_PER_THREAD = 4
"""Batches a map submits per worker thread: enough to balance unequal items, few enough that
the scheduler's cost per task (a few milliseconds: a participant's fit takes ~20 ms) does not
outweigh the work."""


def batch_size(items: int, threads: int) -> int:
    """Items per batch for ``items`` items on ``threads`` worker threads: about
    :data:`TASKS_PER_THREAD` batches per thread, at least one item each."""
    return max(1, math.ceil(items / (threads * TASKS_PER_THREAD)))


def _attempted(function: Callable[[T], R], key: str, item: T, retries: int) -> Outcome[R]:
    """``function(item)``, run again up to ``retries`` times while it raises."""
    for attempt in range(1, retries + 2):
        try:
            value = function(item)
        except Exception as exc:
            if attempt > retries:
                return Outcome(key, None, _error_text(exc), attempt)
            continue
        return Outcome(key, value, "", attempt)
    raise AssertionError("unreachable: the last attempt returns")  # pragma: no cover


def _run_batch(function: Callable[[T], R], batch: list[tuple[str, T]],
               retries: int) -> list[Outcome[R]]:
    """A batch's items on a worker, each with its own retries (a task of the cluster)."""
    return [_attempted(function, key, item, retries) for key, item in batch]
