"""The built-in drivers as an hcard plugin (entry point ``builtin-drivers`` in the
``hcard.plugins`` group). Each driver class is its own plugin object: ``name``,
``description``, ``kind = "driver"``, ``schemes``, ``open(uri)`` and ``enumerate(hosts)``."""

from __future__ import annotations

from typing import Any

from hcard.plugins.hookspecs import hookimpl


@hookimpl
def hcard_drivers() -> list[Any]:
    """sim://, usbip://, pyusb:// and hid:// drivers."""
    from hcard_device.drivers.hidapi_driver import HidapiDriver
    from hcard_device.drivers.pyusb_driver import PyusbDriver
    from hcard_device.drivers.sim import SimDriver
    from hcard_device.drivers.usbip_client import UsbipDriver

    return [SimDriver, UsbipDriver, PyusbDriver, HidapiDriver]
