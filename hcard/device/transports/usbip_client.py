"""``usbip://HOST:PORT/BUSID``: the direct USB/IP client driver.

Imports the device with ``usbip.host`` over a ``TCP_NODELAY`` transport and talks HID class
requests and interrupt transfers through :class:`~hcard.device.transports.usbip_link.UsbipLink`
(real timeouts, unlink on timeout, end of stream -> :class:`DeviceError`). With the host
``loopback`` the device is served in this process over a socket pair (no TCP, no kernel).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from usbip import host as usbip_host

from hcard.device import in_process
from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard.device.errors import DeviceError
from hcard.device.protocol import MAX_REPORT_BYTES, ReportKind
from hcard.device.protocol.usb_ids import IN_ENDPOINT, OUT_ENDPOINT, PID, VID
from hcard.device.transports.usb_descriptors import read_hid_descriptor, read_report_descriptor
from hcard.device.transports.usbip_connect import UsbipConnector
from hcard.device.transports.usbip_link import UsbipLink
from hcard.device.uri import DeviceUri, parse_uri

HID_INTERFACE = 0
"""bInterfaceNumber of the HID interface (the recipient of class requests)."""
GET_REPORT, SET_REPORT = 0x01, 0x09
CLASS_INTERFACE_OUT, CLASS_INTERFACE_IN = 0x21, 0xA1
"""bmRequestType of HID class requests to the interface, host to device and back."""
STANDARD_ENDPOINT_OUT, STANDARD_ENDPOINT_IN = 0x02, 0x82
"""bmRequestType of standard requests to an endpoint, host to device and back."""
GET_STATUS, CLEAR_FEATURE, SET_FEATURE, SET_CONFIGURATION = 0x00, 0x01, 0x03, 0x09
ENDPOINT_HALT = 0
"""Feature selector of SET_FEATURE and CLEAR_FEATURE to an endpoint (USB 2.0, 9.4)."""


def check_identity(info: dict, where: str) -> None:
    """Raise DeviceError unless an imported device has the hcard VID:PID."""
    if (info["idVendor"], info["idProduct"]) != (VID, PID):
        raise DeviceError(
            f"{where}: the device is {info['idVendor']:04x}:{info['idProduct']:04x}, "
            f"not an hcard device ({VID:04x}:{PID:04x})"
        )


class UsbipDriver(Driver):
    """The USB/IP client driver (see the module docstring)."""

    name = "usbip"
    description = "USB/IP client (usbip package): usbip://HOST:PORT/BUSID, NODELAY, timeouts"
    schemes = ("usbip",)
    separate_connections = True

    def __init__(self, uri: DeviceUri, link: UsbipLink, *, timeout_s: float = DEFAULT_TIMEOUT_S,
                 server: Any = None) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.link = link
        self.server = server

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> UsbipDriver:
        uri = parse_uri(uri) if isinstance(uri, str) else uri
        server = in_process.serve_in_process(uri) if uri.loopback else None
        try:
            link = UsbipLink.open(uri.host, uri.port, uri.busid, timeout_s=timeout_s,
                                  transport=server.transport if server else None)
            try:
                check_identity(link.info, str(uri))
                link.control_out(0x00, SET_CONFIGURATION, 1, 0, b"", timeout_s=timeout_s)
                link.start_in(IN_ENDPOINT, MAX_REPORT_BYTES, timeout_s=timeout_s)
            except BaseException:
                link.close()
                raise
        except BaseException:
            if server:
                server.stop()
            raise
        return cls(uri, link, timeout_s=timeout_s, server=server)

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (),
                  *, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """hcard devices exported by the USB/IP servers ``hosts`` (devlist request)."""
        found = []
        for host, port in hosts:
            transport = UsbipConnector(host, port, connect_timeout_s=timeout_s)
            try:
                exported = usbip_host.list_devices(transport)
            except (OSError, usbip_host.USBError):
                continue
            for info in exported:
                if (info["idVendor"], info["idProduct"]) == (VID, PID):
                    where = f"[{host}]" if ":" in host else host  # IPv6 in brackets
                    found.append(DeviceListing(
                        f"usbip://{where}:{port}/{info['busid']}", cls.name,
                        f"USB/IP export {info['busid']} ({VID:04x}:{PID:04x})",
                    ))
        return found

    # ------------------------------------------------------------------ standard requests

    def set_endpoint_halt(self, endpoint: int, halted: bool) -> None:
        """SET_FEATURE (``halted``) or CLEAR_FEATURE of ENDPOINT_HALT on ``endpoint`` (its
        address: 0x01 OUT, 0x81 IN): on a server of several connections, this connection's
        own pipe (protocol PN14).

        Raises:
            DeviceStall: the device refused the request.
        """
        self._check_open()
        self.link.control_out(STANDARD_ENDPOINT_OUT, SET_FEATURE if halted else CLEAR_FEATURE,
                              ENDPOINT_HALT, endpoint, b"", timeout_s=self.timeout_s)

    def endpoint_halted(self, endpoint: int) -> bool:
        """GET_STATUS of ``endpoint``: whether it is halted (for this connection, PN14).

        Raises:
            DeviceStall: the device refused the request.
        """
        self._check_open()
        status = self.link.control_in(STANDARD_ENDPOINT_IN, GET_STATUS, 0, endpoint, 2,
                                      timeout_s=self.timeout_s)
        return bool(status[0] & 1) if status else False

    def set_configuration(self) -> None:
        """SET_CONFIGURATION 1 (the device's one configuration): resets the halts and the IN
        queue of this connection (PN14).

        Raises:
            DeviceStall: the device refused the request.
        """
        self._check_open()
        self.link.control_out(0x00, SET_CONFIGURATION, 1, 0, b"", timeout_s=self.timeout_s)

    def _write_output(self, report: bytes) -> None:
        self.link.interrupt_out(OUT_ENDPOINT, report, timeout_s=self.timeout_s)

    def _set_feature(self, report: bytes) -> None:
        self.link.control_out(CLASS_INTERFACE_OUT, SET_REPORT,
                              (ReportKind.FEATURE << 8) | report[0], HID_INTERFACE, report,
                              timeout_s=self.timeout_s)

    def _get_feature(self, report_id: int, size: int) -> bytes:
        return self.link.control_in(CLASS_INTERFACE_IN, GET_REPORT,
                                    (ReportKind.FEATURE << 8) | report_id, HID_INTERFACE, size,
                                    timeout_s=self.timeout_s)

    def _read_input(self, timeout_s: float) -> bytes | None:
        return self.link.read_in(timeout_s)

    def _control_in(self, request_type: int, request: int, value: int, index: int,
                    length: int) -> bytes:
        return self.link.control_in(request_type, request, value, index, length,
                                    timeout_s=self.timeout_s)

    def _report_descriptor(self) -> bytes:
        return read_report_descriptor(self._control_in, HID_INTERFACE)

    def _hid_descriptor(self) -> bytes:
        return read_hid_descriptor(self._control_in, HID_INTERFACE)

    def _close(self) -> None:
        try:
            self.link.close()
        finally:
            if self.server is not None:
                self.server.stop()
