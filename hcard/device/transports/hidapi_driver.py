"""``hid://VID:PID`` or ``hid:///dev/hidrawN``: the production driver, through hidapi.

On Linux it uses the ``hidraw`` module of the ``hidapi`` package (hidapi's hidraw backend: the
kernel's ``/dev/hidraw*`` nodes, what ``usbip attach`` or a real USB device creates); elsewhere
the ``hid`` module (hidapi's libusb, Windows or macOS backend). Output reports are written with
``write`` (the kernel sends them on the interrupt OUT endpoint), feature reports with
``send_feature_report`` / ``get_feature_report`` (SET/GET_REPORT), input reports are read with
a timeout. The handle is opened non-blocking, so no read waits longer than asked; the feature
ioctls are bounded by the kernel's control-transfer timeout (5 s). The report descriptor is
hidapi's ``get_report_descriptor`` (the bytes the operating system read from the device: on
Linux the kernel asks for the length the HID descriptor announces); hidapi has no call for the
HID descriptor itself, nor do cython-hidapi releases before ``get_report_descriptor`` for the
report descriptor: :class:`DescriptorUnavailable` then.

Never open this driver in a process that also serves the device (``hcard device serve`` or a
``loopback`` URI): closing a hidraw node whose USB/IP server lives in the same process can
deadlock in the kernel's close path. :meth:`HidapiDriver.open` refuses to.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any

from hcard.device import in_process
from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard.device.errors import DescriptorUnavailable, DeviceError, DeviceStall
from hcard.device.protocol import MAX_REPORT_BYTES
from hcard.device.protocol.usb_ids import PID, VID
from hcard.device.uri import DeviceUri, parse_uri
from hcard.quantities import MS_PER_S


def hidapi_module() -> ModuleType:
    """The hidapi backend module: ``hidraw`` on Linux (kernel hidraw nodes), else ``hid``."""
    names = ("hidraw", "hid") if sys.platform.startswith("linux") else ("hid",)
    for name in names:
        try:
            return importlib.import_module(name)
        except ImportError:
            continue
    raise DeviceError("hidapi is not installed (pip install hidapi)")


def _error_text(handle: Any, fallback: str) -> str:
    try:
        text = handle.error()
    except Exception:  # hidapi raises ValueError on a closed handle
        text = ""
    return str(text or fallback)


class HidapiDriver(Driver):
    """The hidapi driver (see the module docstring)."""

    name = "hid"
    description = "hidapi (hidraw on Linux): hid://VID:PID or hid:///dev/hidrawN"
    schemes = ("hid",)

    def __init__(self, uri: DeviceUri, handle: Any, path: bytes, *,
                 timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.handle = handle
        self.path = path

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S,
             module: ModuleType | None = None) -> HidapiDriver:
        """Open by path or by VID:PID (the first match); ``module`` overrides the backend."""
        uri = parse_uri(uri) if isinstance(uri, str) else uri
        if in_process.serving_in_process():
            raise DeviceError(
                f"{uri}: this process serves the device; run the hidapi client in another "
                "process (closing hidraw can deadlock in the kernel otherwise)"
            )
        module = module or hidapi_module()
        if uri.path:
            if not os.path.exists(uri.path):
                raise DeviceError(f"{uri}: no such device node {uri.path} (is the device "
                                  "attached? e.g. usbip attach -r HOST -b 1-1)")
            path = uri.path.encode()
        else:
            try:
                found = module.enumerate(uri.vid, uri.pid)
            except Exception as exc:
                raise DeviceError(f"{uri}: HID enumeration failed ({exc})") from None
            if not found:
                raise DeviceError(f"{uri}: no HID device {uri.vid:04x}:{uri.pid:04x} found "
                                  "(is it plugged in or attached with usbip attach?)")
            path = found[0]["path"]
        handle = module.device()
        try:
            handle.open_path(path)
            handle.set_nonblocking(1)
        except (OSError, ValueError) as exc:
            raise DeviceError(f"{uri}: cannot open {path.decode(errors='replace')} ({exc}; "
                              "check the permissions of the device node)") from None
        return cls(uri, handle, path, timeout_s=timeout_s)

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (), *,
                  timeout_s: float = DEFAULT_TIMEOUT_S,
                  module: ModuleType | None = None) -> list[DeviceListing]:
        """hcard devices hidapi sees (our VID:PID); none when hidapi is missing."""
        try:
            module = module or hidapi_module()
            found = module.enumerate(VID, PID)
        except Exception:
            return []
        listings = []
        for entry in found:
            path = entry["path"].decode(errors="replace")
            uri = f"hid://{path}" if path.startswith("/") else f"hid://{VID:04x}:{PID:04x}"
            product = entry.get("product_string") or "hcard device"
            listings.append(DeviceListing(uri, cls.name, f"{product} at {path}"))
        return listings

    def _failure(self, what: str) -> DeviceError:
        """The error of a failed call: a STALL (EPIPE) or a device that is gone."""
        text = _error_text(self.handle, f"{what} failed")
        if self.path.startswith(b"/") and not os.path.exists(self.path):
            return DeviceError(f"{self.uri}: the device is gone ({text})")
        if "pipe" in text.lower():
            return DeviceStall(f"{self.uri}: the device refused the {what} ({text})")
        return DeviceError(f"{self.uri}: {what} failed ({text})")

    def _write_output(self, report: bytes) -> None:
        try:
            written = self.handle.write(report)
        except (OSError, ValueError):
            written = -1
        if written < 0:
            raise self._failure("output report")

    def _set_feature(self, report: bytes) -> None:
        try:
            written = self.handle.send_feature_report(report)
        except (OSError, ValueError):
            written = -1
        if written < 0:
            raise self._failure(f"SET_REPORT(Feature 0x{report[0]:02X})")

    def _get_feature(self, report_id: int, size: int) -> bytes:
        try:
            data = self.handle.get_feature_report(report_id, size)
        except (OSError, ValueError):
            raise self._failure(f"GET_REPORT(Feature 0x{report_id:02X})") from None
        return bytes(data)

    def _read_input(self, timeout_s: float) -> bytes | None:
        # read(n, 0) does not block (the handle is non-blocking); read(n, ms) waits <= ms.
        timeout_ms = math.ceil(timeout_s * MS_PER_S) if timeout_s > 0 else 0
        try:
            data = self.handle.read(MAX_REPORT_BYTES, timeout_ms)
        except (OSError, ValueError):
            raise self._failure("input report read") from None
        return bytes(data) if data else None

    def _report_descriptor(self) -> bytes:
        read = getattr(self.handle, "get_report_descriptor", None)
        if read is None:
            raise DescriptorUnavailable(
                f"{self.uri}: this hidapi has no get_report_descriptor (older cython-hidapi "
                "releases lack it; pip install -U hidapi)")
        try:
            data = read()
        except (OSError, ValueError):
            raise self._failure("report descriptor read") from None
        return bytes(data)

    def _hid_descriptor(self) -> bytes:
        raise DescriptorUnavailable(
            f"{self.uri}: hidapi reads the report descriptor the operating system holds, never "
            "the HID descriptor that announces its length")

    def _close(self) -> None:
        self.handle.close()
