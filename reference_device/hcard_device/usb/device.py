"""The hcard reference device as a USB-HID device on :mod:`usbip` (pinned 0.7.0).

One HID interface (class 0x03, no boot subclass) with the protocol's report descriptor
(:data:`hcard.device.protocol.REPORT_DESCRIPTOR`, the firmware's ``report_descriptor``; the HID
descriptor in the configuration descriptor announces its length) and two interrupt endpoints
polled every 1 ms:

* IN 0x81 (64 bytes): STATE input reports, moved from :meth:`Firmware.take_input_reports` by
  :meth:`HcardHID.pump`. The endpoint holds at most ``in_queue`` reports; when the host does
  not read, the oldest are dropped (and counted), never queued without bound: like a real
  device's FIFO, a host that comes back gets recent reports, not a backlog.
* OUT 0x01 (64 bytes): output reports, to :meth:`Firmware.handle_output`; SET_REPORT(Output) on
  EP0 goes the same way (hidraw uses it when a host stack has no OUT endpoint).

Several hosts (spec rules PN10, PN12-PN14): every USB/IP connection that imports the device
gets its own view of it (:class:`ConnectionView`): its own IN queue (:class:`InPipe`: at most
``in_queue`` reports and :attr:`ConnectionLimits.max_parked_in_urbs` parked URBs), every STATE
report, its own endpoint halts and configuration value; its output and feature reports reach the
one firmware tagged with the connection (``origin``), so that the firmware refuses the
state-changing reports of every connection but the one that began the live session (PN13).

GET/SET_REPORT(Feature) go to :meth:`Firmware.get_feature` / :meth:`Firmware.set_feature`; a
:class:`ProtocolError` (unknown report ID, a GET-only report SET, a malformed report, a report
refused to another connection) answers with a STALL, as the spec asks. GET_REPORT(Input) returns
the latest STATE report.

Identity: VID 0x1209 (pid.codes, the open-hardware vendor ID) and PID 0x0001, the pid.codes
*test* PID, which anyone may use for private development and testing; a product shipping this
protocol must get its own PID. The product string names the variant (E-ViTa or coupled).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Protocol

import usbip
from usbip.classes.device import hid
from usbip.core import CLASS, ENDPOINT, FEATURE_ENDPOINT_HALT, OUT, STANDARD, Setup, Stall, Urb
from usbip.device import IN, Endpoint, _EPSpec

from hcard.device.protocol import ProtocolError, ReportId, ReportKind
from hcard.device.protocol.usb_ids import IN_ENDPOINT, OUT_ENDPOINT, PID, VID
from hcard_device.usb.connection import (
    DEFAULT_LIMITS,
    Connection,
    ConnectionClosed,
    ConnectionLimits,
    ret_submit_in,
)

BCD_DEVICE = 0x0100
"""Device release 1.00 (the protocol major version is in DEVICE_INFO)."""
MANUFACTURER = "hcard project"
PRODUCTS = {
    "evita": "hcard reference E-ViTa (UV)",
    "coupled": "hcard reference coupled UV+EV stimulator",
}
"""Product string of each device variant."""
SERIALS = {"evita": "HCARD-EVITA-0001", "coupled": "HCARD-COUPLED-0001"}

MAX_PACKET = 64
"""wMaxPacketSize of both interrupt endpoints, bytes (full speed; every report fits)."""
INTERVAL_MS = 1
"""bInterval of both interrupt endpoints, ms (full speed frames): 1 kHz, the STATE rate."""
DEFAULT_IN_QUEUE = 32
"""STATE reports the IN endpoint holds for the host before dropping the oldest (32 ms)."""
STALL_STATUS = -32
"""URB status of a STALL (-EPIPE)."""
NO_DEVICE_STATUS = -19
"""URB status of a transfer to an endpoint the device does not have (-ENODEV, as usbip)."""

_GET_STATUS, _CLEAR_FEATURE, _SET_FEATURE = 0x00, 0x01, 0x03
_GET_CONFIGURATION, _SET_CONFIGURATION = 0x08, 0x09
_CLASS_INTERFACE_OUT, _CLASS_INTERFACE_IN = 0x21, 0xA1
_UPLOAD_END_SET = (_CLASS_INTERFACE_OUT, hid.SET_REPORT,
                   (int(ReportKind.FEATURE) << 8) | int(ReportId.UPLOAD_END))


class FirmwareLike(Protocol):
    """What the USB layer needs of :class:`hcard_device.firmware.Firmware`. ``origin``: the
    connection a request came from (None: unknown, e.g. in-process callers).
    ``report_descriptor``: the HID report descriptor the interface declares (PD1)."""

    report_descriptor: bytes

    def set_feature(self, data: bytes, origin: object | None = None) -> None: ...

    def get_feature(self, report_id: int, origin: object | None = None) -> bytes: ...

    def handle_output(self, data: bytes, origin: object | None = None) -> None: ...

    def take_input_reports(self, max_count: int | None = None) -> list[bytes]: ...

    def latest_input_report(self) -> bytes: ...


class BoundedEndpoint(Endpoint):
    """An interrupt-IN endpoint that keeps at most ``capacity`` unsent reports (the device's
    own IN endpoint, served when no connection views the device).

    Writing past the capacity drops the oldest queued report and counts it in
    :attr:`dropped`; a write with an IN URB parked completes that URB at once.
    """

    def __init__(self, spec: _EPSpec, capacity: int) -> None:
        super().__init__(spec)
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.dropped = 0

    def write(self, data: bytes) -> None:
        with self._cv:
            while len(self._q) >= self.capacity:
                self._q.popleft()
                self.dropped += 1
        super().write(data)

    @property
    def queued(self) -> int:
        """Reports waiting for an IN URB."""
        with self._cv:
            return len(self._q)


class InPipe:
    """The interrupt-IN endpoint as one connection sees it: its own queue of at most
    ``capacity`` STATE reports (the oldest dropped and counted, rule PT5) and at most
    ``max_parked`` IN URBs waiting for a report (one more closes the connection).

    A report that arrives while URBs are parked completes the oldest at once: its RET_SUBMIT is
    queued on the connection under the pipe's lock (so an unlink that finds no URB answers
    after it), and written without waiting (:meth:`Connection.send`).
    """

    def __init__(self, connection: Connection, *, capacity: int = DEFAULT_IN_QUEUE,
                 max_parked: int = DEFAULT_LIMITS.max_parked_in_urbs,
                 endpoint: int = IN_ENDPOINT) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.connection = connection
        self.capacity = capacity
        self.max_parked = max_parked
        self.number = endpoint & 0x0F
        self.dropped = 0
        self.halted = False
        self._reports: deque[bytes] = deque()
        self._parked: deque[tuple[int, int, int]] = deque()  # (seqnum, devid, length)
        self._lock = threading.Lock()

    @property
    def queued(self) -> int:
        """Reports waiting for an IN URB."""
        return len(self._reports)

    @property
    def parked(self) -> int:
        """IN URBs waiting for a report."""
        return len(self._parked)

    def deliver(self, reports: list[bytes]) -> None:
        """New STATE reports (the pump): complete parked URBs with them, queue the rest."""
        with self._lock:
            parked = self._parked
            answers = []
            start = 0
            if parked and not self.halted:
                number = self.number
                while parked and start < len(reports):
                    seqnum, devid, length = parked.popleft()
                    report = reports[start]
                    answers.append(ret_submit_in(seqnum, devid, number, report[:length]))
                    start += 1
            queue = self._reports
            for report in reports[start:] if start else reports:
                if len(queue) >= self.capacity:
                    queue.popleft()
                    self.dropped += 1
                queue.append(report)
            if answers:
                self.connection.send(b"".join(answers))
                return
        self.connection.flush()

    def take_or_park(self, urb: Urb) -> Urb | None:
        """An IN URB: answered now with the oldest queued report (or a STALL while halted),
        else parked (None).

        Raises:
            ConnectionClosed: ``max_parked`` URBs are parked already.
        """
        with self._lock:
            if self.halted:
                urb.buffer, urb.actual, urb.status = b"", 0, STALL_STATUS
                return urb
            if self._reports:
                data = self._reports.popleft()[: urb.length or MAX_PACKET]
                urb.buffer, urb.actual, urb.status = data, len(data), 0
                return urb
            if len(self._parked) >= self.max_parked:
                raise ConnectionClosed(
                    f"more than {self.max_parked} interrupt-IN URBs parked")
            self._parked.append((urb.seqnum, urb.devid, urb.length or MAX_PACKET))
            return None

    def cancel(self, seqnum: int) -> bool:
        """Drop the parked URB ``seqnum`` (the host unlinked it); True when it was parked."""
        with self._lock:
            for index, entry in enumerate(self._parked):
                if entry[0] == seqnum:
                    del self._parked[index]
                    return True
        return False

    def halt(self) -> None:
        """SET_FEATURE(ENDPOINT_HALT) from this connection: its parked URBs STALL now, and so
        does every IN URB it sends until it clears the halt. Queued reports stay."""
        with self._lock:
            self.halted = True
            parked, self._parked = self._parked, deque()
            answers = [ret_submit_in(seqnum, devid, self.number, b"", STALL_STATUS)
                       for seqnum, devid, _length in parked]
            if answers:
                self.connection.send(b"".join(answers))

    def clear_halt(self) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT) from this connection."""
        with self._lock:
            self.halted = False

    def reset(self) -> None:
        """SET_CONFIGURATION from this connection: drop its queued reports and its halt
        (parked URBs stay: they take the next reports)."""
        with self._lock:
            self._reports.clear()
            self.halted = False


class HcardHID(hid.HID):
    """The HID interface of the hcard device, wired to a firmware.

    Args:
        firmware: the :class:`~hcard_device.firmware.Firmware` (or anything shaped like it).
        in_queue: reports the IN endpoint holds before dropping the oldest.
        lock: serialises every firmware call made from USB threads (the pump and the USB/IP
            connection threads); default: the firmware's own ``lock`` (which its real-time
            loop holds while it advances), else a new one.
    """

    def __init__(self, firmware: FirmwareLike, *, in_queue: int = DEFAULT_IN_QUEUE,
                 lock: threading.Lock | threading.RLock | None = None) -> None:
        self._in_queue = in_queue
        self.firmware = firmware
        self.lock = lock or getattr(firmware, "lock", None) or threading.RLock()
        self.stalls = 0
        """Requests answered with a STALL (refused by the firmware or not allowed)."""
        self._pipes: tuple[InPipe, ...] = ()  # replaced, never changed: the pump reads it
        self._dropped_by_gone = 0  # reports dropped at the pipes of connections that ended
        self._pipes_lock = threading.Lock()
        super().__init__(
            firmware.report_descriptor,
            in_ep=IN_ENDPOINT, in_mps=MAX_PACKET, in_interval=INTERVAL_MS,
            out_ep=OUT_ENDPOINT, out_mps=MAX_PACKET, out_interval=INTERVAL_MS,
            get_report=self._on_get_report, set_report=self._on_set_report,
            on_output=self._on_output,
        )

    @property
    def in_queue(self) -> int:
        """Reports each IN queue holds before dropping the oldest."""
        return self._in_queue

    def _add_endpoint(self, spec: _EPSpec) -> Endpoint:
        if spec.addr & 0x80:  # the IN endpoint: bounded
            ep: Endpoint = BoundedEndpoint(spec, self._in_queue)
            self._endpoints[(ep.number, ep.dir)] = ep
            return ep
        return super()._add_endpoint(spec)

    @property
    def in_dropped(self) -> int:
        """STATE reports dropped at the IN endpoints because a host did not read them."""
        own = self.in_ep.dropped if isinstance(self.in_ep, BoundedEndpoint) else 0
        return own + self._dropped_by_gone + sum(pipe.dropped for pipe in self._pipes)

    @property
    def pipes(self) -> tuple[InPipe, ...]:
        """The IN queues of the connections served now."""
        return self._pipes

    def subscribe(self, pipe: InPipe) -> None:
        """Feed ``pipe`` every STATE report from now on (one per connection)."""
        with self._pipes_lock:
            self._pipes = (*self._pipes, pipe)

    def unsubscribe(self, pipe: InPipe) -> None:
        """Stop feeding ``pipe`` (its connection ended)."""
        with self._pipes_lock:
            if pipe in self._pipes:
                self._pipes = tuple(p for p in self._pipes if p is not pipe)
                self._dropped_by_gone += pipe.dropped

    # ---- firmware calls ------------------------------------------------------------------

    def refuse(self) -> Stall:
        """A STALL to raise for a request the device refuses (counted in :attr:`stalls`)."""
        self.stalls += 1
        return Stall()

    def get_report(self, report_type: int, report_id: int, origin: object | None = None) -> bytes:
        """GET_REPORT: a feature report from the firmware, or the latest STATE report.

        Raises:
            Stall: the firmware refused the request (PE1), or it is not a GET the device has.
        """
        if report_type == ReportKind.FEATURE:
            try:
                with self.lock:
                    return bytes(self.firmware.get_feature(report_id, origin=origin))
            except ProtocolError:
                raise self.refuse() from None
        if report_type == ReportKind.INPUT and report_id == ReportId.STATE:
            with self.lock:
                return bytes(self.firmware.latest_input_report())
        raise self.refuse()

    def set_report(self, report_type: int, report_id: int, payload: bytes,
                   origin: object | None = None) -> None:
        """SET_REPORT: a feature report (STALL when refused) or an output report.

        The firmware takes its own lock (a COMMIT releases it while the card is checked, rule
        PU12), so it is not taken here.

        Raises:
            Stall: the data stage does not start with the report ID (HID 1.11 7.2.2), the
                firmware refused the feature report (PE1, PN13), or the report type is Input.
        """
        if not payload or payload[0] != report_id:
            raise self.refuse()
        if report_type == ReportKind.FEATURE:
            try:
                self.firmware.set_feature(bytes(payload), origin=origin)
            except ProtocolError:
                raise self.refuse() from None
            return
        if report_type == ReportKind.OUTPUT:
            self.output(payload, origin)
            return
        raise self.refuse()

    def output(self, payload: bytes, origin: object | None = None) -> None:
        """An output report (interrupt OUT or SET_REPORT(Output)); never refused here (the
        firmware counts and flags what it refuses, PE2)."""
        with self.lock:
            self.firmware.handle_output(bytes(payload), origin=origin)

    def _on_get_report(self, report_type: int, report_id: int, length: int) -> bytes:
        return self.get_report(report_type, report_id)

    def _on_set_report(self, report_type: int, report_id: int, payload: bytes) -> None:
        self.set_report(report_type, report_id, payload)

    def _on_output(self, payload: bytes) -> None:
        self.output(payload)

    def pump(self) -> int:
        """Move the firmware's pending STATE reports to the IN queue of every connection
        (the device's own IN endpoint when none views it); returns how many reports. What a
        connection's socket did not take yet is written on the way (never waiting)."""
        with self.lock:
            reports = self.firmware.take_input_reports()
        pipes = self._pipes
        if not pipes:
            for report in reports:
                self.send_report(report)
            return len(reports)
        for pipe in pipes:
            if reports:
                pipe.deliver(reports)
            else:
                pipe.connection.flush()
        return len(reports)


class ConnectionView:
    """The device as one USB/IP connection sees it (rules PN10, PN12-PN14).

    * interrupt IN: the connection's own :class:`InPipe`;
    * interrupt OUT and SET/GET_REPORT: to the firmware with the connection as ``origin``;
    * SET/CLEAR_FEATURE(ENDPOINT_HALT), GET_STATUS(endpoint): the connection's own halt of its
      own pipes (PN14), never the other connections';
    * SET/GET_CONFIGURATION: the connection's own value; SET_CONFIGURATION resets only its IN
      queue and its halts;
    * everything else (descriptors, the HID idle rate and protocol, which change nothing the
      device does) as the shared device answers it.

    Args:
        device: the :class:`usbip.USBDevice`.
        interface: its :class:`HcardHID`.
        connection: the connection served.
    """

    def __init__(self, device: usbip.USBDevice, interface: HcardHID,
                 connection: Connection) -> None:
        self._device = device
        self._interface = interface
        self.connection = connection
        self.origin = connection.number
        self.in_pipe = InPipe(connection, capacity=interface.in_queue,
                              max_parked=connection.limits.max_parked_in_urbs)
        self.out_halted = False
        self.configuration = 0
        interface.subscribe(self.in_pipe)

    def is_slow(self, urb: Urb) -> bool:
        """An UPLOAD_END SET: it may run the card check (rule PU12), for seconds."""
        setup = urb.setup
        return (urb.ep == 0 and len(setup) == 8 and setup[0] == _UPLOAD_END_SET[0]
                and setup[1] == _UPLOAD_END_SET[1]
                and setup[2] | setup[3] << 8 == _UPLOAD_END_SET[2])

    def submit(self, urb: Urb, connection: Connection) -> Urb | None:
        """Serve ``urb``; None when it was parked (the pump answers it)."""
        if urb.ep == 0:
            return self._control(urb)
        if urb.ep == self.in_pipe.number and urb.direction == IN:
            return self.in_pipe.take_or_park(urb)
        if urb.ep == OUT_ENDPOINT and urb.direction == OUT:
            if self.out_halted:
                urb.actual, urb.status = 0, STALL_STATUS
                return urb
            self._interface.output(urb.buffer, self.origin)
            urb.actual, urb.status = len(urb.buffer), 0
            return urb
        urb.buffer, urb.actual, urb.status = b"", 0, NO_DEVICE_STATUS
        return urb

    def unlink(self, seqnum: int) -> bool:
        """Drop the parked IN URB ``seqnum``; True when it was parked."""
        return self.in_pipe.cancel(seqnum)

    def close(self) -> None:
        """The connection ended: stop feeding its IN queue."""
        self._interface.unsubscribe(self.in_pipe)

    # ---- control transfers ---------------------------------------------------------------

    def _control(self, urb: Urb) -> Urb:
        setup = Setup.parse(urb.setup)
        try:
            data = self._request(setup, urb)
        except Stall:
            urb.buffer, urb.actual, urb.status = b"", 0, STALL_STATUS
            return urb
        if setup.direction == IN:
            data = data[: setup.wLength]
            urb.buffer, urb.actual = data, len(data)
        else:
            urb.actual = setup.wLength
        urb.status = 0
        return urb

    def _request(self, setup: Setup, urb: Urb) -> bytes:
        """The data stage of a control request's answer (b"" for OUT requests)."""
        if setup.type == STANDARD:
            request = setup.bRequest
            if setup.recipient == ENDPOINT and request in (_GET_STATUS, _CLEAR_FEATURE,
                                                           _SET_FEATURE):
                return self._endpoint_request(setup)
            if request == _SET_CONFIGURATION:
                self.configuration = setup.wValue & 0xFF
                self.in_pipe.reset()
                self.out_halted = False
                return b""
            if request == _GET_CONFIGURATION:
                return bytes([self.configuration])
            return self._shared(urb)
        if setup.type == CLASS and setup.bRequest in (hid.GET_REPORT, hid.SET_REPORT):
            # whatever the recipient and direction bits say: no report reaches the firmware
            # without its connection (rule PN13)
            if setup.bmRequestType == _CLASS_INTERFACE_IN and setup.bRequest == hid.GET_REPORT:
                return self._interface.get_report(setup.wValue >> 8, setup.wValue & 0xFF,
                                                  self.origin)
            if setup.bmRequestType == _CLASS_INTERFACE_OUT and setup.bRequest == hid.SET_REPORT:
                self._interface.set_report(setup.wValue >> 8, setup.wValue & 0xFF,
                                           bytes(urb.buffer), self.origin)
                return b""
            raise self._interface.refuse()
        return self._shared(urb)

    def _endpoint_request(self, setup: Setup) -> bytes:
        """GET_STATUS, SET_FEATURE, CLEAR_FEATURE of an endpoint: this connection's halts."""
        address = setup.wIndex & 0xFF
        if address == IN_ENDPOINT:
            halted = self.in_pipe.halted
        elif address == OUT_ENDPOINT:
            halted = self.out_halted
        else:
            halted = False  # EP0 cannot be halted; unknown endpoints read as running
        if setup.bRequest == _GET_STATUS:
            return b"\x01\x00" if halted else b"\x00\x00"
        if setup.wValue == FEATURE_ENDPOINT_HALT:
            halt = setup.bRequest == _SET_FEATURE
            if address == IN_ENDPOINT:
                self.in_pipe.halt() if halt else self.in_pipe.clear_halt()
            elif address == OUT_ENDPOINT:
                self.out_halted = halt
        return b""

    def _shared(self, urb: Urb) -> bytes:
        """A request the shared device answers the same to every connection."""
        answer = self._device.handle_urb(urb, None)
        if answer.status:
            raise Stall
        return bytes(answer.buffer[: answer.actual]) if urb.direction == IN else b""


def build_usb_device(
    firmware: FirmwareLike,
    variant: str,
    *,
    in_queue: int = DEFAULT_IN_QUEUE,
    lock: threading.Lock | threading.RLock | None = None,
) -> tuple[usbip.USBDevice, HcardHID]:
    """The :class:`usbip.USBDevice` of a device ``variant`` ("evita" or "coupled") and its
    HID interface; plug the device into a transport to serve it. The device's
    ``connection_view(device, connection)`` makes each connection's :class:`ConnectionView`."""
    if variant not in PRODUCTS:
        raise ValueError(f"unknown device variant {variant!r}; known: {', '.join(PRODUCTS)}")
    device = usbip.USBDevice(
        VID, PID, manufacturer=MANUFACTURER, product=PRODUCTS[variant],
        serial=SERIALS[variant], bcdDevice=BCD_DEVICE,
    )
    interface = HcardHID(firmware, in_queue=in_queue, lock=lock)
    device.add(interface)

    def connection_view(_device: Any, connection: Connection) -> ConnectionView:
        return ConnectionView(device, interface, connection)

    device.connection_view = connection_view
    return device, interface


__all__ = ["BoundedEndpoint", "ConnectionLimits", "ConnectionView", "HcardHID", "InPipe",
           "build_usb_device"]
