"""One USB/IP connection of the served device, with bounded memory, that never blocks the device.

usbip 0.7.0's ``protocol.serve_connection`` trusts the client: it reads whatever transfer length
a URB header declares, parks every IN URB it is sent, and answers with a blocking ``sendall``
under a per-connection lock, from whichever thread completes the URB. The pump (on the firmware
thread) completes the parked IN URBs of every connection, so one client that stops reading its
socket blocked the STATE stream of all of them. :class:`Connection` serves the URB phase itself (the
48-byte headers of the kernel's ``Documentation/usb/usbip_protocol.rst``, the handshake through
:func:`usbip.protocol.serve_handshake`) with every resource bounded by
:class:`ConnectionLimits`:

* a URB whose transfer length is negative, or above :attr:`ConnectionLimits.max_out_bytes`
  (OUT data, which is read into memory) or :attr:`ConnectionLimits.max_in_bytes` (IN), closes
  the connection before any of its payload is read;
* answers go into the connection's own outgoing buffer and are written with non-blocking
  sends by whichever thread produced them (the pump flushes what the socket did not take every
  cycle): no thread ever waits for a client. When more than
  :attr:`ConnectionLimits.max_pending_bytes` wait because the client does not read, the
  connection is closed;
* IN URBs parked waiting for a report are bounded per connection by the device's view
  (:class:`~hcard_device.usb.device.InPipe`), and so are the control transfers waiting behind
  a slow one (:attr:`ConnectionLimits.max_queued_controls`);
* the import handshake must arrive within :attr:`ConnectionLimits.handshake_timeout_s`;
* interrupt-OUT URBs complete at most at the bus's rate, one per full-speed frame
  (:attr:`ConnectionLimits.out_reports_per_s`, after a burst of
  :attr:`ConnectionLimits.out_report_burst`): a client that submits them faster waits, as it
  would on a USB bus (its reader thread sleeps, so its socket fills and its own sends block),
  and its reports cost the device no more than a host streaming at full rate.

Every close says why on the server's log (one line). Requests the device's view calls slow
(an UPLOAD_END that runs the card check, spec rule PU12) run on a helper thread, so the
connection's IN stream and its unlinks keep flowing while the control transfer's status stage
is held; the other control transfers of the connection wait behind it, in order.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from usbip import protocol
from usbip.core import IN, OUT, Urb

from hcard.errors import HcardError

HEADER_BYTES = 48
"""Size of every USB/IP URB-phase header (20-byte basic + 28-byte union), bytes."""
_BASIC = struct.Struct(">IIIII")  # command, seqnum, devid, direction, ep
_SUBMIT = struct.Struct(">Iiiii")  # transfer_flags, transfer_buffer_length, start, packets, int.
_RET_SUBMIT = struct.Struct(">IIIIIiiiii8x")  # basic + status, actual, start, packets, errors
_RET_UNLINK = struct.Struct(">IIIIIi24x")  # basic + status
UNLINKED_STATUS = -104
"""RET_UNLINK status of a URB the server unlinked before completing it (-ECONNRESET, as the
kernel's usbip stub answers); 0 when it had completed already."""


@dataclass(frozen=True)
class ConnectionLimits:
    """The bounds of one served connection (spec/device-protocol.md section 13).

    Attributes:
        max_out_bytes: largest OUT transfer accepted, bytes (a full-speed HID report is 64;
            a larger URB closes the connection before its payload is read).
        max_in_bytes: largest IN transfer a URB may ask for, bytes (wLength of a control
            transfer is at most 65535; nothing is allocated for it).
        max_parked_in_urbs: interrupt-IN URBs one connection may keep waiting for a report
            (the kernel's usbhid keeps 1, the hcard link 4); one more closes the connection.
        max_pending_bytes: answers waiting for a client that does not read its socket (beyond
            what the kernel's socket buffer took), bytes; past it the connection is closed.
        max_queued_controls: control transfers waiting behind a slow one (an UPLOAD_END
            running the card check); one more closes the connection.
        handshake_timeout_s: longest wait for the OP_REQ_IMPORT (or OP_REQ_DEVLIST), s.
        out_reports_per_s: interrupt-OUT URBs completed per second at most, 1/s (a
            full-speed interrupt endpoint of bInterval 1 ms carries one 64-byte report a
            frame; a host streaming frames sends ~770/s: 667 STREAM and 100 FINGER).
        out_report_burst: interrupt-OUT URBs completed at once before that rate applies (a
            host's first STREAM reports come in a burst that fills the device's queue).
    """

    max_out_bytes: int = 4096
    max_in_bytes: int = 0xFFFF
    max_parked_in_urbs: int = 64
    max_pending_bytes: int = 64 * 1024
    max_queued_controls: int = 4
    handshake_timeout_s: float = 2.0
    out_reports_per_s: float = 1000.0
    out_report_burst: int = 64


class ReportPacer:
    """A token bucket: how long an interrupt-OUT URB must wait to keep a connection within
    ``rate`` URBs a second after a burst of ``burst``.

    Args:
        rate: URBs per second, 1/s.
        burst: URBs that may pass at once, after an idle spell.
        clock: monotonic time, s.
    """

    def __init__(self, rate: float, burst: int,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not rate > 0 or burst < 1:
            raise ValueError(f"a pacer needs a rate > 0 and a burst >= 1 ({rate}, {burst})")
        self.rate, self.burst, self._clock = rate, burst, clock
        self._tokens = float(burst)
        self._last = clock()

    def take(self) -> float:
        """Take the next URB's turn; the time to wait before it completes, s (0: at once)."""
        now = self._clock()
        self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate) - 1.0
        self._last = now
        return -self._tokens / self.rate if self._tokens < 0 else 0.0


DEFAULT_LIMITS = ConnectionLimits()
"""The bounds every connection of the reference device's server gets."""


class ConnectionClosed(HcardError):
    """Raised inside a connection's threads to end it; its message is the logged reason."""


class DeviceView(Protocol):
    """What a connection needs of the device as that connection sees it
    (:class:`~hcard_device.usb.device.ConnectionView`)."""

    def submit(self, urb: Urb, connection: Connection) -> Urb | None:
        """Serve ``urb``; the URB to answer now, or None when it was parked (answered later
        through :meth:`Connection.answer`)."""
        ...

    def is_slow(self, urb: Urb) -> bool:
        """``urb`` may take long (it then runs off the connection's reader thread)."""
        ...

    def unlink(self, seqnum: int) -> bool:
        """Drop the parked URB ``seqnum``; True when one was parked."""
        ...

    def close(self) -> None:
        """The connection ended: release what the view holds."""
        ...


def ret_submit(urb: Urb) -> bytes:
    """The RET_SUBMIT of a completed URB (header, then the data of an IN transfer)."""
    header = _RET_SUBMIT.pack(protocol.RET_SUBMIT, urb.seqnum, urb.devid, urb.direction, urb.ep,
                              urb.status, urb.actual, 0, 0, 0)
    if urb.direction == IN and urb.actual > 0:
        return header + bytes(urb.buffer[: urb.actual])
    return header


def ret_submit_in(seqnum: int, devid: int, ep: int, data: bytes, status: int = 0) -> bytes:
    """The RET_SUBMIT of an interrupt-IN URB completed with ``data`` (the pump's fast path)."""
    return _RET_SUBMIT.pack(protocol.RET_SUBMIT, seqnum, devid, IN, ep, status, len(data), 0, 0,
                            0) + data


class Connection:
    """One client of the served device (see the module docstring).

    Args:
        sock: the accepted (or socket-pair) socket; the connection owns and closes it.
        number: the connection's number on its server (1, 2, ...): the origin the firmware
            attributes sessions to (spec rule PN12).
        peer: the client's address as text, for the log.
        limits: the bounds.
        log: writes one line to the server's log.
    """

    def __init__(self, sock: socket.socket, number: int, peer: str, *,
                 limits: ConnectionLimits = DEFAULT_LIMITS,
                 log: Callable[[str], None] = print) -> None:
        self.sock = sock
        self.number = number
        self.peer = peer
        self.limits = limits
        self._log = log
        self._out = bytearray()
        self._out_lock = threading.Lock()
        self._controls: deque[Urb] | None = None  # not None while a slow control runs
        self._control_lock = threading.Lock()
        self._cancelled: set[int] = set()
        self._closed = threading.Event()
        self._out_pacer = ReportPacer(limits.out_reports_per_s, limits.out_report_burst)
        self.close_reason = ""
        self.view: DeviceView | None = None

    def __repr__(self) -> str:
        return f"connection {self.number} ({self.peer})"

    # ------------------------------------------------------------------ serving

    def serve(self, devices: list[Any], make_view: Callable[[Any, Connection], DeviceView]) -> None:
        """Serve the connection until it ends (on the calling thread): the handshake, then
        URBs; closes the socket and the view, and logs why it ended when it was not the client
        leaving in the ordinary way."""
        reason = ""
        try:
            self.sock.settimeout(self.limits.handshake_timeout_s)
            try:
                device = protocol.serve_handshake(self.sock, devices)
            except TimeoutError:
                raise ConnectionClosed(
                    f"no import request within {self.limits.handshake_timeout_s:g} s") from None
            if device is None:
                return  # a device list was asked for, or an unknown bus: usbip answered it
            self.sock.settimeout(None)
            self.view = make_view(device, self)
            self._serve_urbs(self.view)
        except ConnectionClosed as exc:
            reason = str(exc)
        except OSError as exc:
            if not self._closed.is_set():
                reason = f"socket error ({exc.strerror or exc})"
        finally:
            self._finish(reason)

    def _serve_urbs(self, view: DeviceView) -> None:
        reader = self.sock.makefile("rb", buffering=HEADER_BYTES * 64)
        try:
            while True:
                header = reader.read(HEADER_BYTES)
                if len(header) < HEADER_BYTES:
                    if self._closed.is_set():
                        raise ConnectionClosed(self.close_reason)
                    return  # the client closed the connection
                self._handle(header, reader, view)
        finally:
            reader.close()

    def _handle(self, header: bytes, reader: Any, view: DeviceView) -> None:
        command, seqnum, devid, direction, ep = _BASIC.unpack_from(header)
        flags, length, _start, _packets, interval = _SUBMIT.unpack_from(header, 20)
        if command == protocol.CMD_UNLINK:
            self._unlink(seqnum, devid, direction, ep, flags, view)
            return
        if command != protocol.CMD_SUBMIT:
            raise ConnectionClosed(f"unknown USB/IP command 0x{command:08X}")
        if direction not in (IN, OUT) or not 0 <= ep <= 15:
            raise ConnectionClosed(f"URB {seqnum}: direction {direction}, endpoint {ep}")
        bound = self.limits.max_out_bytes if direction == OUT else self.limits.max_in_bytes
        if not 0 <= length <= bound:
            raise ConnectionClosed(
                f"URB {seqnum} declares a transfer of {length} bytes "
                f"({'OUT' if direction == OUT else 'IN'} transfers: 0..{bound})")
        data = b""
        if direction == OUT and length:
            data = reader.read(length)
            if len(data) < length:
                raise ConnectionClosed(f"the client closed in the middle of URB {seqnum}")
        # The device has no isochronous endpoint: number_of_packets is ignored, as usbip's
        # read_cmd does for non-isochronous transfers.
        urb = Urb(command, seqnum, devid, direction, ep, flags, length, interval,
                  bytes(header[40:48]), data)
        if ep == 0 and self._defer_control(urb, view):
            return
        if ep and direction == OUT:
            wait_s = self._out_pacer.take()
            if wait_s and self._closed.wait(wait_s):
                raise ConnectionClosed(self.close_reason)
        answer = view.submit(urb, self)
        if answer is not None:
            self.answer(answer)

    # ------------------------------------------------------------------ slow control transfers

    def _defer_control(self, urb: Urb, view: DeviceView) -> bool:
        """Queue ``urb`` behind a slow control transfer, or start it on a helper thread when it
        is slow itself; False when it is served at once on the reader thread."""
        with self._control_lock:
            if self._controls is not None:
                if len(self._controls) >= self.limits.max_queued_controls:
                    raise ConnectionClosed(
                        f"more than {self.limits.max_queued_controls} control transfers wait "
                        "behind a slow one")
                self._controls.append(urb)
                return True
            if not view.is_slow(urb):
                return False
            self._controls = deque([urb])
        threading.Thread(target=self._run_controls, args=(view,), daemon=True,
                         name=f"usbip-control-{self.number}").start()
        return True

    def _run_controls(self, view: DeviceView) -> None:
        """Serve the queued control transfers in order (the first one slow), then hand control
        transfers back to the reader thread."""
        while True:
            with self._control_lock:
                assert self._controls is not None
                if not self._controls:
                    self._controls = None
                    return
                urb = self._controls[0]
            try:
                answer = view.submit(urb, self)
            except Exception as exc:  # never leave the queue stuck: the connection ends
                self.close(f"control transfer {urb.seqnum} failed ({exc!r})")
                answer = None
            with self._control_lock:
                assert self._controls is not None
                self._controls.popleft()
                cancelled = urb.seqnum in self._cancelled
                self._cancelled.discard(urb.seqnum)
            if answer is not None and not cancelled:
                self.answer(answer)

    def _unlink(self, seqnum: int, devid: int, direction: int, ep: int, target: int,
                view: DeviceView) -> None:
        """CMD_UNLINK of URB ``target``: drop it if parked or queued (a running slow control
        transfer finishes, but its answer is not sent), then answer RET_UNLINK."""
        unlinked = view.unlink(target)
        if not unlinked:
            with self._control_lock:
                if self._controls is not None:
                    for index, queued in enumerate(self._controls):
                        if queued.seqnum == target:
                            if index == 0:
                                self._cancelled.add(target)
                            else:
                                del self._controls[index]
                            unlinked = True
                            break
        status = UNLINKED_STATUS if unlinked else 0
        self.send(_RET_UNLINK.pack(protocol.RET_UNLINK, seqnum, devid, direction, ep, status))

    # ------------------------------------------------------------------ answers

    def answer(self, urb: Urb) -> None:
        """Send the RET_SUBMIT of a completed URB."""
        self.send(ret_submit(urb))

    def send(self, data: bytes) -> None:
        """Queue ``data`` for the client and write what the socket takes now, without waiting;
        closes the connection when more than ``max_pending_bytes`` would be waiting."""
        with self._out_lock:
            if self._closed.is_set():
                return
            self._out += data
            self._flush_locked()

    def flush(self) -> None:
        """Write what waits for the client, as far as the socket takes it now."""
        if self._out:
            with self._out_lock:
                if not self._closed.is_set():
                    self._flush_locked()

    def _flush_locked(self) -> None:
        out = self._out
        while out:
            try:
                sent = self.sock.send(out, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self._close_locked(f"socket error while sending ({exc.strerror or exc})")
                return
            del out[:sent]
        if len(out) > self.limits.max_pending_bytes:
            self._close_locked(
                f"the client does not read: {len(out)} bytes of answers wait (bound "
                f"{self.limits.max_pending_bytes})")

    @property
    def pending_bytes(self) -> int:
        """Bytes of answers waiting for the client to read them."""
        return len(self._out)

    # ------------------------------------------------------------------ closing

    @property
    def closed(self) -> bool:
        """True once the connection was closed (by either side)."""
        return self._closed.is_set()

    def close(self, reason: str) -> None:
        """Close the connection from any thread; ``reason`` goes to the log. The reader
        thread wakes (its socket is shut down) and releases the connection's resources."""
        with self._out_lock:
            self._close_locked(reason)

    def _close_locked(self, reason: str) -> None:
        if self._closed.is_set():
            return
        self.close_reason = reason
        self._closed.set()
        self._out = bytearray()
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)

    def _finish(self, reason: str) -> None:
        with self._out_lock:
            already = self._closed.is_set()
            reason = self.close_reason if already and self.close_reason else reason
            self._closed.set()
            self._out = bytearray()
        if self.view is not None:
            self.view.close()
        with contextlib.suppress(OSError):
            self.sock.close()
        if reason:
            self._log(f"closed {self}: {reason}")
