"""USB/IP clients of a served device, well-behaved and hostile: the bounded-connections cases
of ``device.session-ownership`` (rule PN15, :mod:`hcard_conformance.device_checks.connections`)
judge an implementation with them, and the reference server's own isolation tests
(tests/device/test_server_isolation.py) and bench/bench_server_isolation.py use them too.

Each client speaks the URB phase of the kernel's ``Documentation/usb/usbip_protocol.rst`` on a
raw socket (the import handshake through :func:`usbip.protocol.client_import`), so that it can
do what no driver does: stop reading its socket, park URBs by the hundred thousand, declare a
2 GiB transfer, hold a connection idle. A hostile client runs on its own thread until stopped,
reconnecting when the server closes it (so it keeps misbehaving for the whole measurement),
and counts what it did.

:func:`measure_delivery` is the well-behaved client: the hcard driver's link
(:class:`~hcard.device.transports.usbip_link.UsbipLink`, 4 interrupt-IN URBs outstanding, as a
host's usbhid keeps one or more) reading STATE reports for a while, and what it received.
"""

from __future__ import annotations

import abc
import contextlib
import functools
import itertools
import json
import os
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from usbip import protocol

from hcard.device.priority import REALTIME_PRIORITY
from hcard.device.protocol import (
    INPUT_RATE_HZ,
    FaultBits,
    Finger,
    UploadAction,
    UploadEnd,
    UploadStatus,
    decode_input,
    upload_reports,
)
from hcard.device.transports.usbip_link import UsbipLink

_SUBMIT = struct.Struct(">IIIIIIiiii8s")
_IN, _OUT = 1, 0
DEVID = (1 << 16) | 2  # bus 1, device 2: the served device's busnum/devnum
IN_EP, OUT_EP = 1, 1
REPORT_BYTES = 64


def submit_header(seqnum: int, direction: int, ep: int, length: int,
                  setup: bytes = bytes(8)) -> bytes:
    """A CMD_SUBMIT header (48 bytes)."""
    return _SUBMIT.pack(protocol.CMD_SUBMIT, seqnum, DEVID, direction, ep, 0, length, 0, 0,
                        1 if ep else 0, setup)


@functools.cache
def in_urbs(first: int, count: int) -> bytes:
    """``count`` interrupt-IN URBs numbered from ``first``, back to back."""
    return b"".join(submit_header(n, _IN, IN_EP, REPORT_BYTES)
                    for n in range(first, first + count))


@functools.cache
def descriptor_gets(first: int, count: int) -> bytes:
    """``count`` GET_DESCRIPTOR(Report) control URBs numbered from ``first`` (the largest
    answer the device gives: 48 + 111 bytes)."""
    setup = struct.pack("<BBHHH", 0x81, 0x06, 0x2200, 0, 128)
    return b"".join(submit_header(n, _IN, 0, 128, setup) for n in range(first, first + count))


@functools.cache
def finger_outs(first: int, count: int) -> bytes:
    """``count`` interrupt-OUT URBs carrying a FINGER report, numbered from ``first``."""
    report = Finger.from_si(0.1, 10.0, 10.0, 0.5, True).encode()
    return b"".join(submit_header(n, _OUT, OUT_EP, len(report)) + report
                    for n in range(first, first + count))


def import_device(host: str, port: int, timeout_s: float = 5.0,
                  receive_buffer: int | None = None) -> socket.socket:
    """A raw socket that imported bus 1-1 (blocking, ``TCP_NODELAY``; ``receive_buffer``:
    its SO_RCVBUF, set before connecting, bytes).

    Raises:
        OSError: refused, or closed before the import completed (a full server).
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if receive_buffer is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
    sock.settimeout(timeout_s)
    try:
        sock.connect((host, port))
    except OSError:
        sock.close()
        raise
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        protocol.client_import(sock, b"1-1")
    except Exception as exc:
        sock.close()
        raise OSError(f"import refused ({exc})") from None
    return sock


@dataclass
class Delivery:
    """What a well-behaved client received over ``seconds``.

    Attributes:
        seconds: wall time of the measurement, s.
        received: distinct STATE reports received.
        max_arrival_gap_ms: longest wall time between two reports received, ms.
        max_stamp_gap_us: largest step of ``timestamp_us`` between consecutive reports, us
            (1000 when none is missing).
        lost: reports missing (sequence gaps).
        lagged: reports the device flagged REALTIME_LAG (it produced them late on its own
            clock, rule PI4).
    """

    seconds: float
    received: int
    max_arrival_gap_ms: float
    max_stamp_gap_us: int
    lost: int
    lagged: int = 0
    arrivals: list[float] = field(default_factory=list, repr=False)
    stamps_us: list[int] = field(default_factory=list, repr=False)
    real_time: bool = False
    """Whether the client read at the device's real-time priority (:func:`real_time_thread`)."""

    @property
    def fraction(self) -> float:
        """STATE reports received per second over the 1000 the device produces per second."""
        return self.received / self.seconds / INPUT_RATE_HZ


@contextlib.contextmanager
def real_time_thread() -> Iterator[bool]:
    """Run the calling thread at ``SCHED_RR`` with the served device's own priority where
    permitted (root or CAP_SYS_NICE), and as it was afterwards. Yields whether it was granted:
    a client that reads at that priority receives what the device delivers, not what the
    machine's other processes leave its thread (on 2 shared cores, 10-20 ms gaps at an
    ordinary priority with nothing else happening)."""
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REALTIME_PRIORITY))
    except OSError:
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setscheduler(0, policy, param)


def measure_delivery(host: str, port: int, seconds: float, *, settle_s: float = 0.3,
                     beside: Callable[[], contextlib.AbstractContextManager[object]] | None = None,
                     beside_settle_s: float | None = None,
                     during: Callable[[], object] | None = None,
                     real_time: bool = False) -> Delivery:
    """The well-behaved client: import the device with the hcard link, read STATE reports for
    ``settle_s`` (dropped), enter ``beside()`` (misbehaving clients, started after this one
    holds its connection) and read ``beside_settle_s`` more (default ``settle_s``; the
    misbehaviour takes effect), then read for ``seconds`` (and, with ``during``, for as long
    as ``during()`` runs on another thread) and return what arrived. ``real_time``: read at
    the device's real-time priority (:func:`real_time_thread`), where permitted
    (:attr:`Delivery.real_time` says whether it was)."""
    with real_time_thread() if real_time else contextlib.nullcontext(False) as granted:
        delivery = _measure_delivery(host, port, seconds, settle_s, beside, beside_settle_s,
                                     during)
    delivery.real_time = bool(granted)
    return delivery


def _measure_delivery(host: str, port: int, seconds: float, settle_s: float,
                      beside: Callable[[], contextlib.AbstractContextManager[object]] | None,
                      beside_settle_s: float | None,
                      during: Callable[[], object] | None) -> Delivery:
    link = UsbipLink.open(host, port, "1-1", timeout_s=5.0)
    try:
        link.control_out(0x00, 0x09, 1, 0, b"", timeout_s=5.0)  # SET_CONFIGURATION 1
        link.start_in(0x81, REPORT_BYTES)
        with contextlib.ExitStack() as stack:
            _read_for(link, settle_s)
            if beside is not None:
                stack.enter_context(beside())
                _read_for(link, settle_s if beside_settle_s is None else beside_settle_s)
            worker = None
            if during is not None:
                worker = threading.Thread(target=during, daemon=True)
            arrivals: list[float] = []
            stamps: list[int] = []
            sequences: list[int] = []
            lagged = 0
            t0 = time.monotonic()
            if worker is not None:
                worker.start()
            while time.monotonic() - t0 < seconds or (worker is not None and worker.is_alive()):
                report = link.read_in(0.05)
                if report:
                    state = decode_input(report)
                    arrivals.append(time.monotonic())
                    stamps.append(state.timestamp_us)
                    sequences.append(state.sequence)
                    lagged += bool(state.faults & FaultBits.REALTIME_LAG)
            elapsed = time.monotonic() - t0
    finally:
        link.close()
    gaps = [b - a for a, b in itertools.pairwise([t0, *arrivals])]
    stamp_steps = [(b - a) % (1 << 32) for a, b in itertools.pairwise(stamps)]
    lost = sum((b - a - 1) % (1 << 16) for a, b in itertools.pairwise(sequences))
    return Delivery(elapsed, len(set(sequences)), max(gaps, default=elapsed) * 1e3,
                    max(stamp_steps, default=0), lost, lagged, arrivals, stamps)


def _read_for(link: UsbipLink, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            link.read_in(0.05)
        except Exception:  # a device gone shows in the measurement that follows
            return


@dataclass
class CommitOutcome:
    """A COMMIT measured by :func:`measure_commit`.

    Attributes:
        during: what the observer received while the COMMIT's control transfer was pending.
        baseline: what it received over as long, with no commit.
        commit_s: how long the COMMIT's control transfer took, s.
        status: UPLOAD_STATUS after it.
    """

    during: Delivery
    baseline: Delivery
    commit_s: float
    status: UploadStatus


def set_report_urb(seqnum: int, report: bytes) -> bytes:
    """A SET_REPORT(Feature) control URB carrying ``report`` (header and data stage)."""
    setup = struct.pack("<BBHHH", 0x21, 0x09, 0x0300 | report[0], 0, len(report))
    return submit_header(seqnum, _OUT, 0, len(report), setup) + report


def get_report_urb(seqnum: int, report_id: int, length: int = 64) -> bytes:
    """A GET_REPORT(Feature) control URB for ``report_id``."""
    setup = struct.pack("<BBHHH", 0xA1, 0x01, 0x0300 | report_id, 0, length)
    return submit_header(seqnum, _IN, 0, length, setup)


def read_answer(sock: socket.socket) -> tuple[int, int, bytes]:
    """The next RET_SUBMIT on ``sock``: (seqnum, status, data)."""
    header = _read_exactly(sock, 48)
    _command, seqnum, _devid, direction, _ep = struct.unpack_from(">IIIII", header)
    status, actual = struct.unpack_from(">ii", header, 20)
    data = _read_exactly(sock, actual) if direction == _IN and actual > 0 else b""
    return seqnum, status, data


def _read_exactly(sock: socket.socket, size: int) -> bytes:
    out = bytearray()
    while len(out) < size:
        chunk = sock.recv(size - len(out))
        if not chunk:
            raise OSError("the server closed the connection")
        out += chunk
    return bytes(out)


def staged_upload(host: str, port: int, data: bytes) -> socket.socket:
    """A raw connection that sent the UPLOAD_BEGIN and UPLOAD_DATA reports of ``data``
    (pipelined, 256 transfers in flight: ~1 s for 2 MiB instead of the 10 s one transfer at a
    time takes), each answered without a STALL, ready for the COMMIT (:func:`timed_commit`).

    Raises:
        OSError: a transfer STALLed or the connection closed.
    """
    sock = import_device(host, port, timeout_s=60.0)
    reports = upload_reports(data, UploadAction.COMMIT)[:-1]
    window = 256
    for start in range(0, len(reports), window):
        chunk = reports[start:start + window]
        sock.sendall(b"".join(set_report_urb(start + i + 1, report)
                              for i, report in enumerate(chunk)))
        for _ in chunk:
            seqnum, status, _ = read_answer(sock)
            if status:
                raise OSError(f"upload transfer {seqnum} answered with status {status}")
    return sock


def timed_commit(sock: socket.socket) -> tuple[float, UploadStatus]:
    """Send UPLOAD_END COMMIT on a :func:`staged_upload` connection; (how long the control
    transfer took, s; UPLOAD_STATUS after it)."""
    t0 = time.monotonic()
    sock.sendall(set_report_urb(1 << 30, UploadEnd(UploadAction.COMMIT).encode()))
    read_answer(sock)
    took = time.monotonic() - t0
    sock.sendall(get_report_urb((1 << 30) + 1, 0x25))
    _seqnum, _status, answer = read_answer(sock)
    return took, UploadStatus.decode(answer)


def measure_commit(host: str, port: int, data: bytes, *, min_seconds: float = 1.0,
                   real_time: bool = False) -> CommitOutcome:
    """Upload ``data`` on one connection (:func:`staged_upload`), then COMMIT it while an
    observer (:func:`measure_delivery`, another connection) reads STATE reports; then measure
    the observer alone over as long (at least ``min_seconds``)."""
    timing: dict[str, object] = {}

    @contextlib.contextmanager
    def staged() -> Iterator[None]:
        sock = staged_upload(host, port, data)
        timing["sock"] = sock
        try:
            yield
        finally:
            sock.close()

    def commit() -> None:
        sock = timing["sock"]
        assert isinstance(sock, socket.socket)
        timing["commit_s"], timing["status"] = timed_commit(sock)

    during = measure_delivery(host, port, 0.0, beside=staged, during=commit, real_time=real_time)
    commit_s = timing["commit_s"]
    status = timing["status"]
    assert isinstance(commit_s, float) and isinstance(status, UploadStatus)
    baseline = measure_delivery(host, port, max(commit_s, min_seconds), real_time=real_time)
    return CommitOutcome(during, baseline, commit_s, status)


class Hostile(abc.ABC):
    """A hostile client on its own thread until :meth:`stop` (see the module docstring).

    Attributes:
        connections: connections it opened (each reconnect counts).
        refused: connections the server refused or closed during the import.
        urbs: URBs it submitted.
    """

    name = "hostile"

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.connections = 0
        self.refused = 0
        self.urbs = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=self.name)
        self._socks: list[socket.socket] = []
        self._lock = threading.Lock()

    def __enter__(self) -> Hostile:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        """Stop misbehaving and close every socket."""
        self._stop.set()
        with self._lock:
            socks, self._socks = self._socks, []
        for sock in socks:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()
        self._thread.join(10.0)

    receive_buffer: int | None = None

    def _connect(self) -> socket.socket | None:
        try:
            sock = import_device(self.host, self.port, receive_buffer=self.receive_buffer)
        except OSError:
            self.refused += 1
            self._stop.wait(0.01)
            return None
        self.connections += 1
        with self._lock:
            self._socks.append(sock)
        return sock

    def _forget(self, sock: socket.socket) -> None:
        with self._lock:
            if sock in self._socks:
                self._socks.remove(sock)
        with contextlib.suppress(OSError):
            sock.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            sock = self._connect()
            if sock is None:
                continue
            try:
                self.misbehave(sock)
            except OSError:
                pass  # the server closed it: reconnect and go on
            finally:
                self._forget(sock)

    @abc.abstractmethod
    def misbehave(self, sock: socket.socket) -> None:
        """What the client does with one connection until the server closes it."""


class NonReader(Hostile):
    """Parks interrupt-IN URBs and never reads its socket, while it asks for the report
    descriptor (answered at once) until the answers fill its socket and the server's (4 MiB on
    Linux loopback): the review's client that stops reading its IN endpoint, made to fill the
    buffers in seconds instead of the half minute its parked URBs alone take at 1000 reports a
    second. On a server that parks without bound, URBs stay parked when the buffers are full,
    and completing one then writes to a socket that takes nothing more."""

    name = "non-reading client"
    receive_buffer = 4096
    PARKED = 20_000

    def misbehave(self, sock: socket.socket) -> None:
        sock.settimeout(1.0)
        sock.sendall(in_urbs(1, self.PARKED))
        self.urbs += self.PARKED
        batch = descriptor_gets(self.PARKED + 1, 256)
        while not self._stop.is_set():
            try:
                sock.sendall(batch)
            except TimeoutError:
                continue  # the server stopped reading us: keep the connection as it is
            self.urbs += 256


class ParkedUrbFlood(Hostile):
    """Submits interrupt-IN URBs as fast as it can (far more than the 1000 reports a second
    that could complete them: they park), reading what comes back."""

    name = "parked-URB flood"

    def misbehave(self, sock: socket.socket) -> None:
        batch = in_urbs(1, 512)
        while not self._stop.is_set():
            sock.settimeout(1.0)
            sock.sendall(batch)
            self.urbs += 512
            sock.settimeout(0.0)
            with contextlib.suppress(BlockingIOError):
                while sock.recv(1 << 16):
                    pass
                raise OSError("closed by the server")


class GiantOutUrb(Hostile):
    """Declares one OUT URB of 2 GiB and feeds it as fast as the socket takes it."""

    name = "2 GiB OUT URB"
    DECLARED = (1 << 31) - 1

    def misbehave(self, sock: socket.socket) -> None:
        sock.sendall(submit_header(1, _OUT, OUT_EP, self.DECLARED))
        self.urbs += 1
        chunk = bytes(1 << 16)
        sock.settimeout(1.0)
        fed = 0
        while not self._stop.is_set() and fed < self.DECLARED:
            sock.sendall(chunk)
            fed += len(chunk)


class OutReportFlood(Hostile):
    """Floods interrupt OUT URBs carrying FINGER reports (pipelined 64 at a time), reading
    the answers."""

    name = "OUT-report flood"

    def misbehave(self, sock: socket.socket) -> None:
        batch = finger_outs(1, 64)
        sock.settimeout(2.0)
        answer = 48 * 64
        while not self._stop.is_set():
            sock.sendall(batch)
            self.urbs += 64
            got = 0
            while got < answer:
                data = sock.recv(answer - got)
                if not data:
                    raise OSError("closed by the server")
                got += len(data)


class IdleImporters:
    """``count`` connections that import the device and then do nothing (held open until
    :meth:`stop`); the server may refuse some (counted)."""

    name = "idle importers"

    def __init__(self, host: str, port: int, count: int = 300) -> None:
        self.host, self.port, self.count = host, port, count
        self.held: list[socket.socket] = []
        self.refused = 0

    def __enter__(self) -> IdleImporters:
        for _ in range(self.count):
            try:
                self.held.append(import_device(self.host, self.port, timeout_s=2.0))
            except OSError:
                self.refused += 1
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        """Close every connection held."""
        for sock in self.held:
            sock.close()
        self.held = []


HOSTILE_KINDS: dict[str, Callable[[str, int], Hostile | IdleImporters]] = {
    "non-reader": NonReader,
    "parked-urb-flood": ParkedUrbFlood,
    "giant-out-urb": GiantOutUrb,
    "out-report-flood": OutReportFlood,
    "idle-importers": IdleImporters,
}
"""Each kind of misbehaving client, by name."""


@contextlib.contextmanager
def hostile_process(kind: str, host: str, port: int,
                    ready_timeout_s: float = 30.0) -> Iterator[dict[str, int]]:
    """Run the misbehaving client ``kind`` in a process of its own (so that its work does not
    slow the measuring client's process) until the block ends; yields a dict filled, after
    the block, with what it did (``connections``, ``refused``, ``urbs``, ``held``)."""
    process = subprocess.Popen(
        [sys.executable, "-m", __name__, kind, host, str(port)], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True)
    stats: dict[str, int] = {}
    try:
        assert process.stdout is not None and process.stdin is not None
        ready, _, _ = select.select([process.stdout], [], [], ready_timeout_s)
        if not ready or process.stdout.readline().strip() != "started":
            raise RuntimeError(f"the {kind} client did not start")
        yield stats
        process.stdin.close()
        out = process.stdout.read()
        process.wait(30)
        stats.update(json.loads(out or "{}"))
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5)


HOSTILE_NICENESS = 10
"""CPU niceness of a hostile client's process. A client elsewhere on the network costs the
device's machine nothing but what the server spends on it; on the one machine of a test (two
cores here) its own CPU use would slow the server as any busy process does, which is what the
scheduler decides, not the server: nicer than the server, it still runs flat out whenever a
core is free."""


def _main(kind: str, host: str, port: int) -> None:
    """The process of :func:`hostile_process`: misbehave until stdin closes, at the ordinary
    policy (a host measuring in real time starts it from a ``SCHED_RR`` thread, whose policy
    a child inherits: a flooding client must not run ahead of the device) and
    :data:`HOSTILE_NICENESS`."""
    with contextlib.suppress(OSError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    os.nice(HOSTILE_NICENESS)
    client = HOSTILE_KINDS[kind](host, port)
    with client:
        print("started", flush=True)
        sys.stdin.read()
    stats = {name: getattr(client, name) for name in ("connections", "refused", "urbs")
             if hasattr(client, name)}
    if isinstance(client, IdleImporters):
        stats["held"] = client.count - client.refused
    print(json.dumps(stats), flush=True)


if __name__ == "__main__":
    _main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
