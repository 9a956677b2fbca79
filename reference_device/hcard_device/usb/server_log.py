"""The served device's log: one line per event, never blocking the thread that logs.

A hostile client can make a server close hundreds of connections a second, each with a line
saying why; written straight to stderr, those lines fill a pipe nobody reads and every thread
that logs then waits, the accept loop and the connections included (found in testing: the
server stopped accepting). :class:`ServerLog` hands lines to its own writer thread through a
bounded queue, lets at most :data:`LINES_PER_SECOND` through each second and counts the rest,
which it reports in one line when writing resumes.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TextIO

LINES_PER_SECOND = 20
"""Lines written per second at most; the rest are counted and reported together."""
QUEUE_LINES = 64
"""Lines waiting for the writer at most; past it they are counted, not kept."""
PREFIX = "hcard device server: "


class ServerLog:
    """A log of one line per call (``log(line)``), written to ``stream`` by a daemon thread.

    Args:
        stream: where lines go (default: the process's stderr at the time of writing).
        lines_per_second: lines written per second at most.
        clock: monotonic clock, s.
    """

    def __init__(self, stream: TextIO | None = None, *,
                 lines_per_second: int = LINES_PER_SECOND,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._stream = stream
        self.lines_per_second = lines_per_second
        self._clock = clock
        self._queue: deque[str] = deque()
        self._ready = threading.Condition()
        self._window_start = -float("inf")
        self._window_lines = 0
        self.suppressed = 0
        """Lines not written (over the rate or the queue), not yet reported."""
        self.written = 0
        self._thread: threading.Thread | None = None

    def __call__(self, line: str) -> None:
        """Log ``line`` (without waiting)."""
        with self._ready:
            now = self._clock()
            if now - self._window_start >= 1.0:
                self._window_start, self._window_lines = now, 0
            if self._window_lines >= self.lines_per_second or len(self._queue) >= QUEUE_LINES:
                self.suppressed += 1
                return
            self._window_lines += 1
            if self.suppressed:
                self._queue.append(f"({self.suppressed} more lines not logged: over "
                                   f"{self.lines_per_second} a second)")
                self.suppressed = 0
            self._queue.append(line)
            if self._thread is None:
                self._thread = threading.Thread(target=self._write, daemon=True,
                                                name="hcard-server-log")
                self._thread.start()
            self._ready.notify()

    def _write(self) -> None:
        while True:
            with self._ready:
                while not self._queue:
                    self._ready.wait()
                line = self._queue.popleft()
            stream = self._stream or sys.stderr
            try:
                print(f"{PREFIX}{line}", file=stream, flush=True)
                self.written += 1
            except (OSError, ValueError):
                pass  # a closed stream: the server goes on without its log

    def drain(self, timeout_s: float = 1.0) -> bool:
        """Wait until every queued line is written (for a clean stop); True when done."""
        deadline = self._clock() + timeout_s
        while self._clock() < deadline:
            with self._ready:
                if not self._queue:
                    return True
            time.sleep(0.005)
        return False


DEFAULT_LOG = ServerLog()
"""The log of the servers of this process (stderr)."""
