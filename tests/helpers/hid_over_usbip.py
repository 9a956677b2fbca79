"""hidapi's ``device`` API carried over USB/IP, to test the hidapi driver without a kernel.

Linux turns a hidraw ``write`` into an interrupt OUT transfer, ``HIDIOCSFEATURE`` /
``HIDIOCGFEATURE`` into SET_REPORT / GET_REPORT(Feature) and delivers interrupt IN reports to
``read``; a STALL surfaces as EPIPE ("Broken pipe"), an unplugged device as ENODEV. hidapi's
``get_report_descriptor`` returns the report descriptor the kernel read when the device was
attached: the HID descriptor's ``wDescriptorLength`` bytes of GET_DESCRIPTOR(Report). This module
does the same over :class:`~hcard.device.transports.usbip_link.UsbipLink`, so that
:class:`~hcard.device.transports.hidapi_driver.HidapiDriver` runs unmodified against the real
firmware in a separate process. Paths are ``usbip://HOST:PORT/BUSID`` (bytes, as hidapi's).
The QEMU guest tier (tests/device/test_guest.py) runs the driver on a real ``/dev/hidraw``.
"""

from __future__ import annotations

import struct
from typing import Any

from hcard.device.errors import DeviceError, DeviceStall
from hcard.device.transports.usb_descriptors import read_hid_descriptor
from hcard.device.transports.usbip_link import UsbipLink

_TIMEOUT_S = 5.0  # the kernel's USB_CTRL_SET_TIMEOUT


class UsbipHidDevice:
    """One open "hidraw" handle (hidapi's ``device`` class API)."""

    def __init__(self) -> None:
        self.link: UsbipLink | None = None
        self._error = ""

    def open_path(self, path: bytes) -> None:
        host_port, _, busid = path.decode().removeprefix("usbip://").partition("/")
        host, _, port = host_port.rpartition(":")
        try:
            self.link = UsbipLink.open(host, int(port), busid, timeout_s=_TIMEOUT_S)
            self.link.control_out(0x00, 0x09, 1, 0, b"", timeout_s=_TIMEOUT_S)
            self.link.start_in(0x81, 64)
        except DeviceError as exc:
            raise OSError("open failed") from exc

    def set_nonblocking(self, value: int) -> int:
        return 0

    def _fail(self, exc: DeviceError) -> int:
        self._error = "Broken pipe" if isinstance(exc, DeviceStall) else f"No such device ({exc})"
        return -1

    def write(self, data: bytes) -> int:
        assert self.link is not None
        try:
            return self.link.interrupt_out(0x01, bytes(data), timeout_s=_TIMEOUT_S)
        except DeviceError as exc:
            return self._fail(exc)

    def send_feature_report(self, data: bytes) -> int:
        assert self.link is not None
        data = bytes(data)
        try:
            return self.link.control_out(0x21, 0x09, 0x0300 | data[0], 0, data,
                                         timeout_s=_TIMEOUT_S)
        except DeviceError as exc:
            return self._fail(exc)

    def get_feature_report(self, report_id: int, max_length: int) -> list[int]:
        assert self.link is not None
        try:
            return list(self.link.control_in(0xA1, 0x01, 0x0300 | report_id, 0, max_length,
                                              timeout_s=_TIMEOUT_S))
        except DeviceError as exc:
            self._fail(exc)
            raise OSError("read error") from exc

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        assert self.link is not None
        try:
            data = self.link.read_in(timeout_ms / 1000)
        except DeviceError as exc:
            self._fail(exc)
            raise OSError("read error") from exc
        return list(data[:max_length]) if data else []

    def get_report_descriptor(self) -> list[int]:
        """As the kernel reads it (module docstring); cython-hidapi before this call had none:
        :class:`HidOverUsbip` with ``report_descriptor=False``."""
        assert self.link is not None

        def control_in(request_type: int, request: int, value: int, index: int,
                       length: int) -> bytes:
            assert self.link is not None
            return self.link.control_in(request_type, request, value, index, length,
                                        timeout_s=_TIMEOUT_S)

        try:
            hid = read_hid_descriptor(control_in, 0)
            announced = struct.unpack_from("<H", hid, 7)[0]
            return list(control_in(0x81, 0x06, 0x2200, 0, announced))
        except DeviceError as exc:
            self._fail(exc)
            raise OSError("read error") from exc

    def error(self) -> str:
        return self._error

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


class OlderUsbipHidDevice(UsbipHidDevice):
    """The ``device`` API of a cython-hidapi release without ``get_report_descriptor``."""

    get_report_descriptor = None  # type: ignore[assignment]


class HidOverUsbip:
    """A stand-in for the ``hidraw`` module listing the devices of USB/IP servers;
    ``report_descriptor=False``: a hidapi without ``get_report_descriptor``."""

    def __init__(self, *servers: tuple[str, int], report_descriptor: bool = True) -> None:
        self.servers = servers
        self.device: type[UsbipHidDevice] = (UsbipHidDevice if report_descriptor
                                             else OlderUsbipHidDevice)

    def enumerate(self, vid: int = 0, pid: int = 0) -> list[dict[str, Any]]:
        from usbip import host as usbip_host

        from hcard_device.usb.transport import NoDelayUSBIP

        found = []
        for host, port in self.servers:
            for info in usbip_host.list_devices(NoDelayUSBIP(host, port)):
                if (vid, pid) in ((0, 0), (info["idVendor"], info["idProduct"])):
                    found.append({"path": f"usbip://{host}:{port}/{info['busid']}".encode(),
                                  "vendor_id": info["idVendor"], "product_id": info["idProduct"],
                                  "product_string": "hcard over USB/IP"})
        return found
