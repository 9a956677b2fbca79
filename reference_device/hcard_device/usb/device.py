"""The hcard reference device as a USB-HID device on :mod:`usbip` (pinned 0.7.0).

One HID interface (class 0x03, no boot subclass) with the protocol's report descriptor
(:data:`hcard_device.protocol.REPORT_DESCRIPTOR`) and two interrupt endpoints polled every 1 ms:

* IN 0x81 (64 bytes): STATE input reports, moved from :meth:`Firmware.take_input_reports` by
  :meth:`HcardHID.pump`. The endpoint holds at most ``in_queue`` reports; when the host does
  not read, the oldest are dropped (and counted), never queued without bound: like a real
  device's FIFO, a host that comes back gets recent reports, not a backlog.
* OUT 0x01 (64 bytes): output reports, to :meth:`Firmware.handle_output`; SET_REPORT(Output) on
  EP0 goes the same way (hidraw uses it when a host stack has no OUT endpoint).

Several hosts: every USB/IP connection that imports the device gets its own IN queue
(:meth:`HcardHID.subscribe`, :class:`ConnectionView`) and every STATE report, as every process
that opens one hidraw node gets every input report; their output and feature reports all reach
the one firmware, which tells them apart only by the session tokens of protocol 1.2 (spec
section 14, rule PN10).

GET/SET_REPORT(Feature) go to :meth:`Firmware.get_feature` / :meth:`Firmware.set_feature`; a
:class:`ProtocolError` (unknown report ID, a GET-only report SET, a malformed report) answers
with a STALL, as the spec asks. GET_REPORT(Input) returns the latest STATE report.

Identity: VID 0x1209 (pid.codes, the open-hardware vendor ID) and PID 0x0001, the pid.codes
*test* PID, which anyone may use for private development and testing; a product shipping this
protocol must get its own PID. The product string names the variant (E-ViTa or coupled).
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

import usbip
from usbip.classes.device import hid
from usbip.core import Stall
from usbip.device import IN, Endpoint, In, _EPSpec

from hcard_device.protocol import REPORT_DESCRIPTOR, ProtocolError, ReportId, ReportKind

VID = 0x1209
"""pid.codes vendor ID (open-source hardware)."""
PID = 0x0001
"""pid.codes test PID: for development and testing only (see the module docstring)."""
BCD_DEVICE = 0x0100
"""Device release 1.00 (the protocol major version is in DEVICE_INFO)."""
MANUFACTURER = "hcard project"
PRODUCTS = {
    "evita": "hcard reference E-ViTa (UV)",
    "coupled": "hcard reference coupled UV+EV stimulator",
}
"""Product string of each device variant."""
SERIALS = {"evita": "HCARD-EVITA-0001", "coupled": "HCARD-COUPLED-0001"}

IN_ENDPOINT = 0x81
"""Interrupt IN endpoint address (STATE reports)."""
OUT_ENDPOINT = 0x01
"""Interrupt OUT endpoint address (output reports)."""
MAX_PACKET = 64
"""wMaxPacketSize of both interrupt endpoints, bytes (full speed; every report fits)."""
INTERVAL_MS = 1
"""bInterval of both interrupt endpoints, ms (full speed frames): 1 kHz, the STATE rate."""
DEFAULT_IN_QUEUE = 32
"""STATE reports the IN endpoint holds for the host before dropping the oldest (32 ms)."""


class FirmwareLike(Protocol):
    """What the USB layer needs of :class:`hcard_device.firmware.Firmware`."""

    def set_feature(self, data: bytes) -> None: ...

    def get_feature(self, report_id: int) -> bytes: ...

    def handle_output(self, data: bytes) -> None: ...

    def take_input_reports(self, max_count: int | None = None) -> list[bytes]: ...

    def latest_input_report(self) -> bytes: ...


class BoundedEndpoint(Endpoint):
    """An interrupt-IN endpoint that keeps at most ``capacity`` unsent reports.

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
        self._subscribers: list[BoundedEndpoint] = []
        self._subscribers_lock = threading.Lock()
        super().__init__(
            REPORT_DESCRIPTOR,
            in_ep=IN_ENDPOINT, in_mps=MAX_PACKET, in_interval=INTERVAL_MS,
            out_ep=OUT_ENDPOINT, out_mps=MAX_PACKET, out_interval=INTERVAL_MS,
            get_report=self._on_get_report, set_report=self._on_set_report,
            on_output=self._on_output,
        )

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
        with self._subscribers_lock:
            return own + sum(ep.dropped for ep in self._subscribers)

    def subscribe(self) -> BoundedEndpoint:
        """A new IN queue that gets every STATE report from now on (one per connection)."""
        endpoint = BoundedEndpoint(In(IN_ENDPOINT, "interrupt", MAX_PACKET, INTERVAL_MS),
                                   self._in_queue)
        with self._subscribers_lock:
            self._subscribers.append(endpoint)
        return endpoint

    def unsubscribe(self, endpoint: BoundedEndpoint) -> None:
        """Stop feeding ``endpoint`` (its connection ended); parked URBs are dropped."""
        with self._subscribers_lock:
            if endpoint in self._subscribers:
                self._subscribers.remove(endpoint)
        endpoint.reset()

    # ---- firmware calls ------------------------------------------------------------------

    def _refuse(self) -> Stall:
        self.stalls += 1
        return Stall()

    def _on_get_report(self, report_type: int, report_id: int, length: int) -> bytes:
        if report_type == ReportKind.FEATURE:
            try:
                with self.lock:
                    return bytes(self.firmware.get_feature(report_id))
            except ProtocolError:
                raise self._refuse() from None
        if report_type == ReportKind.INPUT and report_id == ReportId.STATE:
            with self.lock:
                return bytes(self.firmware.latest_input_report())
        raise self._refuse()

    def _on_set_report(self, report_type: int, report_id: int, payload: bytes) -> None:
        if not payload or payload[0] != report_id:
            raise self._refuse()  # the data stage starts with the report ID (HID 1.11 7.2.2)
        if report_type == ReportKind.FEATURE:
            try:
                with self.lock:
                    self.firmware.set_feature(bytes(payload))
            except ProtocolError:
                raise self._refuse() from None
            return
        if report_type == ReportKind.OUTPUT:
            self._on_output(payload)
            return
        raise self._refuse()

    def _on_output(self, payload: bytes) -> None:
        with self.lock:
            self.firmware.handle_output(bytes(payload))  # never raises (counts + fault flag)

    def pump(self) -> int:
        """Move the firmware's pending STATE reports to the IN endpoint of every connection
        (the device's own one when none subscribed); returns how many reports."""
        with self.lock:
            reports = self.firmware.take_input_reports()
        with self._subscribers_lock:
            targets = list(self._subscribers)
        for report in reports:
            if not targets:
                self.send_report(report)
            for endpoint in targets:
                endpoint.write(report)
        return len(reports)


class ConnectionView:
    """The device as one USB/IP connection sees it: IN URBs of the interrupt endpoint are
    served from the connection's own queue (:meth:`HcardHID.subscribe`); everything else
    (control requests, OUT reports, descriptors) goes to the shared device.

    Args:
        device: the :class:`usbip.USBDevice`.
        interface: its :class:`HcardHID`.
    """

    def __init__(self, device: usbip.USBDevice, interface: HcardHID) -> None:
        self._device = device
        self._interface = interface
        self.in_ep = interface.subscribe()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._device, name)

    def handle_urb(self, urb: Any, respond: Any = None) -> Any:
        """Serve an IN URB of the interrupt endpoint from this connection's queue (parked
        until a report arrives); any other URB as the device does."""
        endpoint = self.in_ep
        if urb.ep != endpoint.number or urb.direction != IN or respond is None:
            return self._device.handle_urb(urb, respond)

        def complete(data: bytes, status: int = 0) -> None:
            urb.buffer, urb.actual, urb.status = data, len(data), status
            respond(urb)

        data = endpoint.take_or_park(urb.length or endpoint.mps, complete, urb.seqnum)
        if data is None:
            return None
        urb.buffer, urb.actual, urb.status = data, len(data), 0
        return urb

    def reset_io(self) -> None:
        """A fresh import: drop this connection's stale reports and URBs (not the others')."""
        self.in_ep.reset()

    def cancel_urb(self, seqnum: int) -> None:
        """The host unlinked ``seqnum``: drop it from this connection's queue or the device."""
        if not self.in_ep.cancel(seqnum):
            self._device.cancel_urb(seqnum)

    def close(self) -> None:
        """The connection ended: stop feeding its queue."""
        self._interface.unsubscribe(self.in_ep)


def build_usb_device(
    firmware: FirmwareLike,
    variant: str,
    *,
    in_queue: int = DEFAULT_IN_QUEUE,
    lock: threading.Lock | threading.RLock | None = None,
) -> tuple[usbip.USBDevice, HcardHID]:
    """The :class:`usbip.USBDevice` of a device ``variant`` ("evita" or "coupled") and its
    HID interface; plug the device into a transport to serve it."""
    if variant not in PRODUCTS:
        raise ValueError(f"unknown device variant {variant!r}; known: {', '.join(PRODUCTS)}")
    device = usbip.USBDevice(
        VID, PID, manufacturer=MANUFACTURER, product=PRODUCTS[variant],
        serial=SERIALS[variant], bcdDevice=BCD_DEVICE,
    )
    interface = HcardHID(firmware, in_queue=in_queue, lock=lock)
    device.add(interface)
    device.connection_view = lambda: ConnectionView(device, interface)  # per connection
    return device, interface

