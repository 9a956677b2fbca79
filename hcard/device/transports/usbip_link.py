"""A USB/IP client link with real timeouts: the host side shared by the usbip and pyusb drivers.

``usbip.host.Connection`` (usbip 0.7.0) submits one URB at a time and blocks in ``recv`` without
a timeout, so a parked interrupt-IN URB or a dead server hangs the caller. :class:`UsbipLink`
keeps ``usbip.host`` for the import handshake and speaks the URB phase itself (the 48-byte
headers of ``Documentation/usb/usbip_protocol.rst``, constants from :mod:`usbip.protocol`):

* control and OUT transfers wait at most their timeout; a transfer still pending then is
  unlinked (``CMD_UNLINK``), and a server that does not even answer the unlink is declared gone;
* the interrupt-IN pipe is kept polled by a few outstanding URBs, as the kernel's usbhid does;
  completed reports are buffered (bounded: the oldest are dropped and counted) and resubmitted,
  so :meth:`read_in` returns reports as the device produced them;
* end of stream or a socket error raises :class:`DeviceError` at once.

A link is used from one thread at a time (a lock makes concurrent use safe but serial).
"""

from __future__ import annotations

import collections
import contextlib
import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, NoReturn

from usbip import host as usbip_host
from usbip import protocol

from hcard.device.errors import DeviceError, DeviceStall, DeviceTimeout
from hcard.device.transports.usbip_connect import UsbipConnector

_HEADER = 48
_OUT, _IN = 0, 1
STALL_STATUS = -32
"""URB status of a STALL (-EPIPE)."""
DEFAULT_IN_URBS = 4
"""Interrupt-IN URBs kept outstanding (the kernel's usbhid keeps one or more the same way)."""
DEFAULT_IN_BUFFER = 4096
"""Completed IN reports buffered before the oldest is dropped (4 s at 1 kHz)."""
UNLINK_GRACE_S = 0.5
"""How long a server may take to answer CMD_UNLINK before it is declared gone, s."""


@dataclass
class _Reply:
    command: int
    seqnum: int
    status: int
    actual: int
    data: bytes


class UsbipLink:
    """One device imported over USB/IP.

    Use :meth:`open`; then :meth:`control_in`, :meth:`control_out`, :meth:`interrupt_out`,
    :meth:`start_in` and :meth:`read_in`; :meth:`close` when done.

    Attributes:
        info: the import reply (``busid``, ``idVendor``, ``idProduct``, ...).
        in_dropped: IN reports dropped because :meth:`read_in` was not called in time.
    """

    def __init__(self, sock: socket.socket, info: dict, *, endpoint_description: str) -> None:
        self._sock = sock
        self.info = info
        self.description = endpoint_description
        self._devid = (int(info["busnum"]) << 16) | int(info["devnum"])
        self._seq = 0
        self._rx = bytearray()
        self._lock = threading.RLock()
        self._in_ep = 0
        self._in_length = 0
        self._in_pending: set[int] = set()
        self._in_reports: collections.deque[bytes] = collections.deque()
        self._in_capacity = DEFAULT_IN_BUFFER
        self.in_dropped = 0
        self._unlinks: set[int] = set()
        self._done: dict[int, _Reply] = {}
        self._closed = False

    # ------------------------------------------------------------------ opening

    @classmethod
    def open(
        cls,
        host: str,
        port: int,
        busid: str,
        *,
        timeout_s: float,
        nodelay: bool = True,
        transport: Any = None,
    ) -> UsbipLink:
        """Connect to ``host:port`` and import ``busid``; every step bounded by ``timeout_s``.

        ``transport`` overrides the TCP transport (e.g. one already serving an in-process
        device). Raises :class:`DeviceError` when the server is unreachable or refuses.
        """
        where = f"usbip://{host}:{port}/{busid}" if transport is None else f"usbip://{host}/{busid}"
        transport = transport or UsbipConnector(host, port, nodelay=nodelay,
                                                connect_timeout_s=timeout_s)
        try:
            sock = transport.connect()
        except OSError as exc:
            raise DeviceError(f"{where}: cannot connect ({reason_of(exc)})") from None
        connection = usbip_host.Connection(sock)
        sock.settimeout(timeout_s)
        try:
            info = connection.import_device(busid)
        except (OSError, usbip_host.USBError) as exc:
            sock.close()
            raise DeviceError(f"{where}: import of bus {busid} failed ({reason_of(exc)})") from None
        return cls(sock, info, endpoint_description=where)

    # ------------------------------------------------------------------ public transfers

    def control_in(self, request_type: int, request: int, value: int, index: int,
                   length: int, *, timeout_s: float) -> bytes:
        """An IN control transfer (device to host); returns the data stage (<= length bytes).

        Raises:
            DeviceStall: the device STALLed the request.
            DeviceTimeout, DeviceError: no answer in time, or the device is gone.
        """
        setup = struct.pack("<BBHHH", request_type, request, value, index, length)
        reply = self._transfer(_IN, 0, setup, length, b"", 0, timeout_s, "control IN")
        return reply.data[: reply.actual]

    def control_out(self, request_type: int, request: int, value: int, index: int,
                    data: bytes, *, timeout_s: float) -> int:
        """An OUT control transfer with ``data`` as its data stage; returns bytes accepted."""
        setup = struct.pack("<BBHHH", request_type, request, value, index, len(data))
        reply = self._transfer(_OUT, 0, setup, len(data), bytes(data), 0, timeout_s,
                               "control OUT")
        return reply.actual

    def interrupt_out(self, endpoint: int, data: bytes, *, timeout_s: float) -> int:
        """An interrupt OUT transfer to ``endpoint`` (address, bit 7 clear); bytes accepted."""
        reply = self._transfer(_OUT, endpoint & 0x0F, bytes(8), len(data), bytes(data), 1,
                               timeout_s, f"interrupt OUT 0x{endpoint:02X}")
        return reply.actual

    def start_in(self, endpoint: int, length: int, *, urbs: int = DEFAULT_IN_URBS,
                 capacity: int = DEFAULT_IN_BUFFER, timeout_s: float = 1.0) -> None:
        """Start polling interrupt-IN ``endpoint`` (address 0x8n) with ``urbs`` URBs."""
        with self._lock:
            self._check_open()
            if self._in_ep:
                return
            self._in_ep, self._in_length, self._in_capacity = endpoint & 0x0F, length, capacity
            deadline = time.monotonic() + timeout_s
            for _ in range(urbs):
                self._submit_in(deadline)

    def read_in(self, timeout_s: float) -> bytes | None:
        """The oldest IN report not yet read, waiting up to ``timeout_s``; None on timeout.

        Raises:
            DeviceStall: the IN endpoint STALLed.
            DeviceError: the device is gone.
        """
        with self._lock:
            self._check_open()
            if not self._in_ep:
                raise DeviceError(f"{self.description}: the IN pipe is not started")
            deadline = time.monotonic() + max(timeout_s, 0.0)
            while not self._in_reports:
                reply = self._receive(deadline)
                if reply is None:
                    return None
                self._dispatch(reply, deadline)
            return self._in_reports.popleft()

    def poll_in(self) -> int:
        """Take in whatever the server already sent, without waiting; returns the IN reports
        buffered and not yet read."""
        with self._lock:
            self._check_open()
            while self._in_ep:
                reply = self._receive(time.monotonic())
                if reply is None:
                    break
                self._dispatch(reply, time.monotonic() + 1.0)
            return len(self._in_reports)

    def close(self) -> None:
        """Unlink outstanding IN URBs (briefly waiting for the acks) and close the socket."""
        with self._lock:
            if self._closed:
                return
            try:
                deadline = time.monotonic() + 0.2
                for seqnum in sorted(self._in_pending):
                    self._send_unlink(seqnum, deadline)
                self._in_ep = 0
                while self._unlinks and time.monotonic() < deadline:
                    reply = self._receive(deadline)
                    if reply is None:
                        break
                    self._dispatch(reply, deadline)
            except (DeviceError, OSError):
                pass
            self._closed = True
            with contextlib.suppress(OSError):
                self._sock.close()

    @property
    def closed(self) -> bool:
        """True once closed (by :meth:`close` or because the device went away)."""
        return self._closed

    # ------------------------------------------------------------------ URB phase

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError(f"{self.description}: the device is closed or gone")

    def _next_seq(self) -> int:
        self._seq = (self._seq % 0xFFFF_FFFE) + 1
        return self._seq

    def _send(self, payload: bytes, deadline: float) -> None:
        try:
            self._sock.settimeout(max(deadline - time.monotonic(), 1e-3))
            self._sock.sendall(payload)
        except TimeoutError:
            self._fail("send timed out (the server does not read)")
        except OSError as exc:
            self._fail(f"connection lost ({reason_of(exc)})")

    def _submit(self, direction: int, ep: int, setup: bytes, length: int, data: bytes,
                interval: int, deadline: float) -> int:
        seqnum = self._next_seq()
        header = struct.pack(">IIIII", protocol.CMD_SUBMIT, seqnum, self._devid, direction, ep)
        header += struct.pack(">Iiiii", 0, length, 0, 0, interval) + setup
        self._send(header + (data if direction == _OUT else b""), deadline)
        return seqnum

    def _submit_in(self, deadline: float) -> None:
        seqnum = self._submit(_IN, self._in_ep, bytes(8), self._in_length, b"", 1, deadline)
        self._in_pending.add(seqnum)

    def _send_unlink(self, target: int, deadline: float) -> None:
        seqnum = self._next_seq()
        header = struct.pack(">IIIII", protocol.CMD_UNLINK, seqnum, self._devid, 0, 0)
        header += struct.pack(">Iiiii", target, 0, 0, 0, 0) + bytes(8)
        self._unlinks.add(seqnum)
        self._send(header, deadline)

    def _transfer(self, direction: int, ep: int, setup: bytes, length: int, data: bytes,
                  interval: int, timeout_s: float, what: str) -> _Reply:
        with self._lock:
            self._check_open()
            deadline = time.monotonic() + timeout_s
            seqnum = self._submit(direction, ep, setup, length, data, interval, deadline)
            reply = self._wait_for(seqnum, deadline)
            if reply is None:
                self._abandon(seqnum)
                raise DeviceTimeout(
                    f"{self.description}: {what} got no answer within {timeout_s:g} s"
                )
            if reply.status == STALL_STATUS:
                raise DeviceStall(f"{self.description}: the device STALLed the {what}")
            if reply.status != 0:
                raise DeviceError(f"{self.description}: {what} failed (status {reply.status})")
            return reply

    def _wait_for(self, seqnum: int, deadline: float) -> _Reply | None:
        while seqnum not in self._done:
            reply = self._receive(deadline)
            if reply is None:
                return None
            self._dispatch(reply, deadline)
        return self._done.pop(seqnum)

    def _abandon(self, seqnum: int) -> None:
        """Unlink a URB that timed out; a server that cannot answer that is gone."""
        grace = time.monotonic() + UNLINK_GRACE_S
        self._send_unlink(seqnum, grace)
        while self._unlinks:
            reply = self._receive(grace)
            if reply is None:
                self._fail(f"no answer to an unlink within {UNLINK_GRACE_S:g} s")
            self._dispatch(reply, grace)
        self._done.pop(seqnum, None)

    def _dispatch(self, reply: _Reply, deadline: float) -> None:
        if reply.command == protocol.RET_UNLINK:
            self._unlinks.discard(reply.seqnum)
            return
        if reply.seqnum in self._in_pending:
            self._in_pending.discard(reply.seqnum)
            if reply.status == STALL_STATUS:
                raise DeviceStall(f"{self.description}: the interrupt IN endpoint STALLed")
            if reply.status != 0:
                if not self._in_ep:
                    return  # unlinked while closing
                raise DeviceError(
                    f"{self.description}: interrupt IN failed (status {reply.status})"
                )
            if reply.actual > 0:
                if len(self._in_reports) >= self._in_capacity:
                    self._in_reports.popleft()
                    self.in_dropped += 1
                self._in_reports.append(reply.data[: reply.actual])
            if self._in_ep:
                self._submit_in(deadline)
            return
        self._done[reply.seqnum] = reply

    def _receive(self, deadline: float) -> _Reply | None:
        """The next RET_* message, or None when ``deadline`` passes first."""
        if not self._fill(_HEADER, deadline):
            return None
        command, seqnum, _devid, direction, _ep = struct.unpack_from(">IIIII", self._rx, 0)
        status, actual = struct.unpack_from(">ii", self._rx, 20)
        if command not in (protocol.RET_SUBMIT, protocol.RET_UNLINK):
            self._fail(f"unexpected USB/IP command 0x{command:08X} from the server")
        size = _HEADER
        if command == protocol.RET_SUBMIT and direction == _IN and actual > 0:
            if actual > 1 << 20:
                self._fail(f"implausible transfer length {actual} from the server")
            size += actual
            # The payload follows its header at once: wait for it even past the deadline,
            # within the grace period, so that a message is never split.
            if not self._fill(size, max(deadline, time.monotonic() + UNLINK_GRACE_S)):
                self._fail("the server stopped in the middle of a message")
        data = bytes(self._rx[_HEADER:size])
        del self._rx[:size]
        return _Reply(command, seqnum, status, max(actual, 0), data)

    def _fill(self, size: int, deadline: float) -> bool:
        """Read until ``size`` bytes are buffered; False if ``deadline`` passes first."""
        while len(self._rx) < size:
            remaining = deadline - time.monotonic()
            try:
                # A deadline already past still takes what the socket holds (non-blocking).
                self._sock.settimeout(max(remaining, 0.0))
                chunk = self._sock.recv(65536)
            except (TimeoutError, BlockingIOError):
                return False
            except OSError as exc:
                self._fail(f"connection lost ({reason_of(exc)})")
            if not chunk:
                self._fail("the server closed the connection (device gone)")
            self._rx += chunk
        return True

    def _fail(self, reason: str) -> NoReturn:
        """Close the link and raise DeviceError: the device is gone or unusable."""
        self._closed = True
        with contextlib.suppress(OSError):
            self._sock.close()
        raise DeviceError(f"{self.description}: {reason}")


def reason_of(exc: BaseException) -> str:
    """A short reason for a socket or USB/IP error (its strerror when it has one)."""
    if isinstance(exc, TimeoutError):
        return "timed out"
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
