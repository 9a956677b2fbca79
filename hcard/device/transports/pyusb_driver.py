"""``pyusb://HOST:PORT/BUSID``: the device through pyusb, over the in-process USB/IP backend.

The driver is plain pyusb (``usb.core.find``, ``ctrl_transfer``, ``write``, ``read`` with
millisecond timeouts) on :class:`~hcard.device.transports.pyusb_backend.UsbipBackend`; pointed at
a libusb backend instead, the same calls drive the device on a real bus. With the host
``loopback`` the device is served in this process.
"""

from __future__ import annotations

import errno
import math
from collections.abc import Sequence
from typing import Any

import usb.core
import usb.util

from hcard.device import in_process
from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard.device.errors import DeviceError, DeviceStall, DeviceTimeout
from hcard.device.protocol import MAX_REPORT_BYTES, ReportKind
from hcard.device.protocol.usb_ids import IN_ENDPOINT, OUT_ENDPOINT, PID, VID
from hcard.device.transports.pyusb_backend import UsbipBackend
from hcard.device.transports.usb_descriptors import read_hid_descriptor, read_report_descriptor
from hcard.device.transports.usbip_client import (
    CLASS_INTERFACE_IN,
    CLASS_INTERFACE_OUT,
    GET_REPORT,
    HID_INTERFACE,
    SET_REPORT,
)
from hcard.device.uri import DeviceUri, parse_uri
from hcard.quantities import MS_PER_S


def _ms(seconds: float) -> int:
    """A pyusb timeout, ms: at least 1 (0 would mean "no timeout" to pyusb backends)."""
    return max(1, math.ceil(seconds * MS_PER_S))


class PyusbDriver(Driver):
    """The pyusb driver (see the module docstring)."""

    name = "pyusb"
    description = "pyusb through an in-process USB/IP backend: pyusb://HOST:PORT/BUSID"
    schemes = ("pyusb",)
    separate_connections = True

    def __init__(self, uri: DeviceUri, device: Any, backend: UsbipBackend, *,
                 timeout_s: float = DEFAULT_TIMEOUT_S,
                 server: Any = None) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.device = device
        self.backend = backend
        self.server = server

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> PyusbDriver:
        uri = parse_uri(uri) if isinstance(uri, str) else uri
        server = in_process.serve_in_process(uri) if uri.loopback else None
        backend = UsbipBackend(uri.host, uri.port, timeout_s=timeout_s,
                               transport=server.transport if server else None)
        try:
            try:
                candidates = usb.core.find(find_all=True, backend=backend)
                device = next((d for d in candidates if backend.busid_of(d) == uri.busid), None)
            except usb.core.USBError as exc:
                raise DeviceError(f"{uri}: {exc.strerror or exc}") from None
            if device is None:
                raise DeviceError(f"{uri}: no device exported as bus {uri.busid}")
            if (device.idVendor, device.idProduct) != (VID, PID):
                raise DeviceError(
                    f"{uri}: the device is {device.idVendor:04x}:{device.idProduct:04x}, "
                    f"not an hcard device ({VID:04x}:{PID:04x})"
                )
            try:
                device.set_configuration()
            except usb.core.USBError as exc:
                raise DeviceError(f"{uri}: cannot configure the device ({exc})") from None
        except BaseException:
            backend.close_all()
            if server:
                server.stop()
            raise
        return cls(uri, device, backend, timeout_s=timeout_s, server=server)

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (),
                  *, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """Same devices as the usbip driver lists, under ``pyusb://``."""
        from hcard.device.transports.usbip_client import UsbipDriver

        return [DeviceListing(listing.uri.replace("usbip://", "pyusb://", 1), cls.name,
                              listing.description)
                for listing in UsbipDriver.enumerate(hosts, timeout_s=timeout_s)]

    def _call(self, what: str, function: Any, *args: Any) -> Any:
        try:
            return function(*args)
        except usb.core.USBTimeoutError:
            raise DeviceTimeout(f"{self.uri}: {what} timed out after {self.timeout_s:g} s")\
                from None
        except usb.core.USBError as exc:
            if exc.errno == errno.EPIPE:
                raise DeviceStall(f"{self.uri}: the device STALLed the {what}") from None
            raise DeviceError(f"{self.uri}: {what} failed ({exc.strerror or exc})") from None

    def _write_output(self, report: bytes) -> None:
        self._call("output report", self.device.write, OUT_ENDPOINT, report,
                   _ms(self.timeout_s))

    def _set_feature(self, report: bytes) -> None:
        self._call(f"SET_REPORT(Feature 0x{report[0]:02X})", self.device.ctrl_transfer,
                   CLASS_INTERFACE_OUT, SET_REPORT, (ReportKind.FEATURE << 8) | report[0],
                   HID_INTERFACE, report, _ms(self.timeout_s))

    def _get_feature(self, report_id: int, size: int) -> bytes:
        data = self._call(f"GET_REPORT(Feature 0x{report_id:02X})", self.device.ctrl_transfer,
                          CLASS_INTERFACE_IN, GET_REPORT, (ReportKind.FEATURE << 8) | report_id,
                          HID_INTERFACE, size, _ms(self.timeout_s))
        return bytes(data)

    def _control_in(self, request_type: int, request: int, value: int, index: int,
                    length: int) -> bytes:
        data = self._call(f"control request 0x{request:02X} (wValue 0x{value:04X})",
                          self.device.ctrl_transfer,
                          request_type, request, value, index, length, _ms(self.timeout_s))
        return bytes(data)

    def _report_descriptor(self) -> bytes:
        return read_report_descriptor(self._control_in, HID_INTERFACE)

    def _hid_descriptor(self) -> bytes:
        return read_hid_descriptor(self._control_in, HID_INTERFACE)

    def _read_input(self, timeout_s: float) -> bytes | None:
        if timeout_s <= 0:
            # pyusb has no zero timeout (0 means none): poll the backend instead of waiting
            # a millisecond for a report that is not there.
            try:
                if not self.backend.buffered_in():
                    return None
            except DeviceError as exc:
                raise DeviceError(f"{self.uri}: {exc}") from None
            timeout_s = self.timeout_s
        try:
            data = self.device.read(IN_ENDPOINT, MAX_REPORT_BYTES, _ms(timeout_s))
        except usb.core.USBTimeoutError:
            return None
        except usb.core.USBError as exc:
            if exc.errno == errno.EPIPE:
                raise DeviceStall(f"{self.uri}: the IN endpoint STALLed") from None
            raise DeviceError(f"{self.uri}: input report read failed ({exc.strerror or exc})")\
                from None
        return bytes(data)

    def _close(self) -> None:
        try:
            usb.util.dispose_resources(self.device)
            self.backend.close_all()
        finally:
            if self.server is not None:
                self.server.stop()
