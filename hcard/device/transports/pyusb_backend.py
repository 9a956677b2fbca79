"""A pyusb backend (:class:`usb.backend.IBackend`) that reaches devices over USB/IP, in process.

``usb.core.find(backend=UsbipBackend(host, port))`` lists the devices a USB/IP server exports;
descriptors are read from the device with GET_DESCRIPTOR, and transfers go through a
:class:`~hcard.device.transports.usbip_link.UsbipLink`, so pyusb's timeouts are real: a read with
no data raises :class:`usb.core.USBTimeoutError` after its timeout, a STALL raises
:class:`usb.core.USBError` with ``errno`` EPIPE, and a vanished device ENODEV.
"""

from __future__ import annotations

import array
import errno
import struct
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core
from usbip import host as usbip_host

from hcard.device.errors import DeviceError, DeviceStall, DeviceTimeout
from hcard.device.transports.usbip_connect import UsbipConnector
from hcard.device.transports.usbip_link import UsbipLink, reason_of
from hcard.quantities import MS_PER_S

_DEVICE = [
    "bLength", "bDescriptorType", "bcdUSB", "bDeviceClass", "bDeviceSubClass",
    "bDeviceProtocol", "bMaxPacketSize0", "idVendor", "idProduct", "bcdDevice", "iManufacturer",
    "iProduct", "iSerialNumber", "bNumConfigurations",
]
_CONFIG = [
    "bLength", "bDescriptorType", "wTotalLength", "bNumInterfaces", "bConfigurationValue",
    "iConfiguration", "bmAttributes", "bMaxPower",
]
_INTERFACE = [
    "bLength", "bDescriptorType", "bInterfaceNumber", "bAlternateSetting", "bNumEndpoints",
    "bInterfaceClass", "bInterfaceSubClass", "bInterfaceProtocol", "iInterface",
]
_ENDPOINT = [
    "bLength", "bDescriptorType", "bEndpointAddress", "bmAttributes", "wMaxPacketSize",
    "bInterval",
]


def _desc(names: list[str], layout: str, raw: bytes, **extra: Any) -> SimpleNamespace:
    return SimpleNamespace(**dict(zip(names, struct.unpack_from(layout, raw), strict=True)),
                           **extra)


def parse_configuration(raw: bytes) -> SimpleNamespace:
    """A configuration descriptor blob as nested namespaces (``interfaces[i][alt]`` with
    ``endpoints``), each carrying its class-specific descriptors in ``extra_descriptors``."""
    config = _desc(_CONFIG, "<BBHBBBBB", raw, extra_descriptors=[], interfaces=[])
    target: list[int] = config.extra_descriptors
    i = raw[0]
    while i + 2 <= len(raw) and raw[i] >= 2:
        blob = raw[i:i + raw[i]]
        if blob[1] == 4 and len(blob) >= 9:
            intf = _desc(_INTERFACE, "<9B", blob, extra_descriptors=[], endpoints=[])
            if intf.bAlternateSetting == 0:
                config.interfaces.append([])
            config.interfaces[-1].append(intf)
            target = intf.extra_descriptors
        elif blob[1] == 5 and len(blob) >= 7 and config.interfaces:
            ep = _desc(_ENDPOINT, "<BBBBHB", blob, bRefresh=0, bSynchAddress=0,
                       extra_descriptors=[])
            config.interfaces[-1][-1].endpoints.append(ep)
            target = ep.extra_descriptors
        else:
            target.extend(blob)
        i += raw[i]
    return config


def _usb_errors(call: Callable[..., Any]) -> Callable[..., Any]:
    """Translate the link's errors into pyusb's (errno like libusb's backend)."""
    def wrapper(*args: Any) -> Any:
        try:
            return call(*args)
        except DeviceTimeout as exc:
            raise usb.core.USBTimeoutError(str(exc), None, errno.ETIMEDOUT) from None
        except DeviceStall as exc:
            raise usb.core.USBError(str(exc), None, errno.EPIPE) from None
        except DeviceError as exc:
            raise usb.core.USBError(str(exc), None, errno.ENODEV) from None
    return wrapper


class UsbipBackend(usb.backend.IBackend):
    """pyusb backend for the devices of one USB/IP server (``transport`` may be a loopback).

    Args:
        host, port: the server. ``transport``: a transport to use instead (in-process device).
        timeout_s: bound of the import, descriptor reads and a 0 ms (infinite) pyusb timeout.
    """

    def __init__(self, host: str, port: int, *, timeout_s: float = 1.0,
                 transport: Any = None) -> None:
        super().__init__()
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self.transport = transport or UsbipConnector(host, port, connect_timeout_s=timeout_s)
        self._links: dict[str, UsbipLink] = {}
        self._busids: dict[tuple[int, int], str] = {}

    def _link(self, dev: SimpleNamespace) -> UsbipLink:
        link = self._links.get(dev.busid)
        if link is None or link.closed:
            link = UsbipLink.open(self.host, self.port, dev.busid, timeout_s=self.timeout_s,
                                  transport=self.transport)
            self._links[dev.busid] = link
        return link

    def _ms(self, timeout_ms: int) -> float:
        return timeout_ms / MS_PER_S if timeout_ms and timeout_ms > 0 else self.timeout_s

    @_usb_errors
    def enumerate_devices(self) -> list[SimpleNamespace]:
        try:
            exported = usbip_host.list_devices(self.transport)
        except (OSError, usbip_host.USBError) as exc:
            raise DeviceError(f"cannot connect to the USB/IP server {self.host}:{self.port} "
                              f"({reason_of(exc)})") from None
        self._busids = {(info["busnum"], info["devnum"]): info["busid"] for info in exported}
        return [SimpleNamespace(busid=info["busid"], info=info, descriptor=None, config=None)
                for info in exported]

    def busid_of(self, device: usb.core.Device) -> str:
        """The USB/IP bus ID of a device this backend enumerated ("" when unknown)."""
        return self._busids.get((device.bus, device.address), "")

    def buffered_in(self) -> int:
        """IN reports already received by this backend's links and not yet read by pyusb
        (checked without waiting): lets a caller skip a read that would only time out."""
        return sum(link.poll_in() for link in self._links.values() if not link.closed)

    def close_all(self) -> None:
        """Close every link this backend opened."""
        for link in self._links.values():
            link.close()
        self._links.clear()

    @_usb_errors
    def get_device_descriptor(self, dev: SimpleNamespace) -> SimpleNamespace:
        if dev.descriptor is None:
            raw = self._link(dev).control_in(0x80, 6, 0x0100, 0, 18, timeout_s=self.timeout_s)
            dev.descriptor = _desc(_DEVICE, "<BBHBBBBHHHBBBB", raw, bus=dev.info["busnum"],
                                   address=dev.info["devnum"], port_number=None,
                                   port_numbers=None, speed=dev.info["speed"])
        return dev.descriptor

    @_usb_errors
    def get_configuration_descriptor(self, dev: SimpleNamespace, config: int) -> SimpleNamespace:
        if config != 0:
            raise IndexError(f"configuration index {config}: the device has one")
        if dev.config is None:
            link = self._link(dev)
            head = link.control_in(0x80, 6, 0x0200, 0, 9, timeout_s=self.timeout_s)
            total = struct.unpack_from("<H", head, 2)[0]
            raw = link.control_in(0x80, 6, 0x0200, 0, total, timeout_s=self.timeout_s)
            dev.config = parse_configuration(raw)
        return dev.config

    def get_interface_descriptor(self, dev: SimpleNamespace, intf: int, alt: int,
                                 config: int) -> SimpleNamespace:
        return self.get_configuration_descriptor(dev, config).interfaces[intf][alt]

    def get_endpoint_descriptor(self, dev: SimpleNamespace, ep: int, intf: int, alt: int,
                                config: int) -> SimpleNamespace:
        return self.get_interface_descriptor(dev, intf, alt, config).endpoints[ep]

    def open_device(self, dev: SimpleNamespace) -> UsbipLink:
        return _usb_errors(self._link)(dev)

    def close_device(self, dev_handle: UsbipLink) -> None:
        dev_handle.close()

    @_usb_errors
    def set_configuration(self, dev_handle: UsbipLink, config_value: int) -> None:
        dev_handle.control_out(0x00, 9, config_value, 0, b"", timeout_s=self.timeout_s)

    @_usb_errors
    def get_configuration(self, dev_handle: UsbipLink) -> int:
        return dev_handle.control_in(0x80, 8, 0, 0, 1, timeout_s=self.timeout_s)[0]

    def claim_interface(self, dev_handle: UsbipLink, intf: int) -> None:
        """Nothing to claim: a USB/IP import is exclusive already."""

    def release_interface(self, dev_handle: UsbipLink, intf: int) -> None:
        """See :meth:`claim_interface`."""

    def is_kernel_driver_active(self, dev_handle: UsbipLink, intf: int) -> bool:
        return False

    @_usb_errors
    def ctrl_transfer(self, dev_handle: UsbipLink, bmRequestType: int, bRequest: int,
                      wValue: int, wIndex: int, data: array.array, timeout: int) -> int:
        if bmRequestType & 0x80:
            got = dev_handle.control_in(bmRequestType, bRequest, wValue, wIndex, len(data),
                                        timeout_s=self._ms(timeout))
            data[:len(got)] = array.array("B", got)
            return len(got)
        return dev_handle.control_out(bmRequestType, bRequest, wValue, wIndex,
                                      data.tobytes(), timeout_s=self._ms(timeout))

    @_usb_errors
    def intr_write(self, dev_handle: UsbipLink, ep: int, intf: int, data: array.array,
                   timeout: int) -> int:
        return dev_handle.interrupt_out(ep, data.tobytes(), timeout_s=self._ms(timeout))

    @_usb_errors
    def intr_read(self, dev_handle: UsbipLink, ep: int, intf: int, buff: array.array,
                  timeout: int) -> int:
        dev_handle.start_in(ep, len(buff), timeout_s=self.timeout_s)
        got = dev_handle.read_in(self._ms(timeout))
        if got is None:
            raise DeviceTimeout(f"{dev_handle.description}: no IN report within {timeout} ms")
        got = got[:len(buff)]
        buff[:len(got)] = array.array("B", got)
        return len(got)

    @_usb_errors
    def clear_halt(self, dev_handle: UsbipLink, ep: int) -> None:
        dev_handle.control_out(0x02, 1, 0, ep, b"", timeout_s=self.timeout_s)
