"""The built-in drivers as an hcard plugin (entry point ``builtin-drivers`` in the
``hcard.plugins`` group). Each driver class is its own plugin object (a
:class:`~hcard.plugins.kinds.DriverPlugin`): ``name``, ``description``, ``kind = "driver"``,
``schemes``, ``open(uri)`` and ``enumerate(hosts)``.

It lives outside :mod:`hcard_device.drivers` so that discovering the plugins imports no driver:
they are imported when the hook is called.
"""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.kinds import DriverPlugin


@hookimpl
def hcard_drivers() -> list[DriverPlugin]:
    """sim://, usbip://, pyusb:// and hid:// drivers."""
    from hcard_device.drivers.hidapi_driver import HidapiDriver
    from hcard_device.drivers.pyusb_driver import PyusbDriver
    from hcard_device.drivers.sim import SimDriver
    from hcard_device.drivers.usbip_client import UsbipDriver

    return [SimDriver, UsbipDriver, PyusbDriver, HidapiDriver]
