"""Tier-2 helper: the reference device served by a separate process on 127.0.0.1.

:func:`served_device` starts ``python -m hcard_device.usb.server --port 0`` (or ``hcard device
serve``), waits (bounded) for its ``serving ... at usbip://127.0.0.1:PORT/1-1`` line, yields a
:class:`ServedDevice`, and always kills the process on exit.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

START_TIMEOUT_S = 20.0
"""Longest wait for the server's ready line, s (imports numpy, scipy and the physics)."""
_READY = re.compile(r"at (usbip://(127\.0\.0\.1):(\d+)/(\S+))")


@dataclass
class ServedDevice:
    """A device server process and where it listens."""

    process: subprocess.Popen[bytes]
    uri: str
    host: str
    port: int
    banner: str

    def terminate(self, sig: int = signal.SIGTERM, timeout_s: float = 5.0) -> tuple[int, str]:
        """Send ``sig`` and wait for the exit; returns (exit status, rest of stdout)."""
        self.process.send_signal(sig)
        out, _err = self.process.communicate(timeout=timeout_s)
        return self.process.returncode, out.decode(errors="replace")

    def kill(self) -> None:
        """SIGKILL, as a crashing or unplugged device would vanish."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(5)


def _read_line(fd: int, deadline: float) -> str:
    data = b""
    while b"\n" not in data:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError(f"no ready line within {START_TIMEOUT_S} s (got {data!r})")
        ready, _, _ = select.select([fd], [], [], remaining)
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                raise RuntimeError(f"the server exited before it was ready (got {data!r})")
            data += chunk
    return data.split(b"\n", 1)[0].decode(errors="replace")


@contextlib.contextmanager
def served_device(variant: str = "evita", *, cli: bool = False,
                  extra: Sequence[str] = ()) -> Iterator[ServedDevice]:
    """Serve a device in a subprocess on a free port of 127.0.0.1 (``cli``: through
    ``hcard device serve``; ``extra``: more options, e.g. ``--effect air-layer``); the process is
    killed when the block ends, whatever happens."""
    if cli:
        command = [sys.executable, "-c", "from hcard.cli.main import cli; cli()", "device",
                   "serve", "--port", "0", "--device", variant, *extra]
    else:
        command = [sys.executable, "-m", "hcard_device.usb.server", "--port", "0",
                   "--device", variant, *extra]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout is not None
        try:
            line = _read_line(process.stdout.fileno(), time.monotonic() + START_TIMEOUT_S)
        except (TimeoutError, RuntimeError) as exc:
            process.kill()
            _out, err = process.communicate(timeout=5)
            raise RuntimeError(f"{exc}; stderr: {err.decode(errors='replace')[-2000:]}") from None
        match = _READY.search(line)
        if not match:
            raise RuntimeError(f"unexpected ready line {line!r}")
        yield ServedDevice(process, match[1], match[2], int(match[3]), line)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5)
        for stream in (process.stdout, process.stderr):
            if stream is not None:
                stream.close()
