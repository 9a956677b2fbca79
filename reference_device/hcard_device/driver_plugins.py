"""The built-in drivers as an hcard plugin (entry point ``builtin-drivers`` in the
``hcard.plugins`` group): each a :class:`~hcard.plugins.lazy_plugins.LazyDriver`, so that
listing the plugins imports no driver, no transport library and no protocol codec; a driver is
imported when a device is first opened or enumerated through it. The name, description and
schemes below are the driver classes' own (a test compares them).
"""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.lazy_plugins import LazyDriver

BUILTIN_DRIVERS: tuple[LazyDriver, ...] = (
    LazyDriver("sim", "in-process firmware and simulation on the driver's clock: "
               "sim://[evita|coupled]", ("sim",), "hcard_device.drivers.sim:SimDriver"),
    LazyDriver("usbip", "USB/IP client (usbip package): usbip://HOST:PORT/BUSID, NODELAY, "
               "timeouts", ("usbip",), "hcard_device.drivers.usbip_client:UsbipDriver"),
    LazyDriver("pyusb", "pyusb through an in-process USB/IP backend: pyusb://HOST:PORT/BUSID",
               ("pyusb",), "hcard_device.drivers.pyusb_driver:PyusbDriver"),
    LazyDriver("hid", "hidapi (hidraw on Linux): hid://VID:PID or hid:///dev/hidrawN", ("hid",),
               "hcard_device.drivers.hidapi_driver:HidapiDriver"),
)
"""sim://, usbip://, pyusb:// and hid://, in the order ``hcard plugins`` lists them."""


@hookimpl
def hcard_drivers() -> list[LazyDriver]:
    """sim://, usbip://, pyusb:// and hid:// drivers (:data:`BUILTIN_DRIVERS`)."""
    return list(BUILTIN_DRIVERS)
