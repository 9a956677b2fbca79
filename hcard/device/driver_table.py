"""The host library's drivers as an hcard plugin (entry point ``host-drivers`` in the
``hcard.plugins`` group): the transports of the hcard HID protocol, each a
:class:`~hcard.plugins.lazy_plugins.LazyDriver`, so that listing the plugins imports no driver,
no transport library and no protocol codec; a driver is imported when a device is first opened
or enumerated through it. The name, description and schemes below are the driver classes' own
(a test compares them). The devices simulated in this process (``sim://``) are the reference
device's driver (package ``hcard_device``), registered by its own entry point.
"""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.lazy_plugins import LazyDriver

HOST_DRIVERS: tuple[LazyDriver, ...] = (
    LazyDriver("usbip", "USB/IP client (usbip package): usbip://HOST:PORT/BUSID, NODELAY, "
               "timeouts", ("usbip",), "hcard.device.transports.usbip_client:UsbipDriver"),
    LazyDriver("pyusb", "pyusb through an in-process USB/IP backend: pyusb://HOST:PORT/BUSID",
               ("pyusb",), "hcard.device.transports.pyusb_driver:PyusbDriver"),
    LazyDriver("hid", "hidapi (hidraw on Linux): hid://VID:PID or hid:///dev/hidrawN", ("hid",),
               "hcard.device.transports.hidapi_driver:HidapiDriver"),
)
"""usbip://, pyusb:// and hid://, in the order ``hcard plugins`` lists them."""


@hookimpl
def hcard_drivers() -> list[LazyDriver]:
    """usbip://, pyusb:// and hid:// drivers (:data:`HOST_DRIVERS`)."""
    return list(HOST_DRIVERS)
