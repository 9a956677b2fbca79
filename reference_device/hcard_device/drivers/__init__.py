"""Host drivers of the hcard reference device (and of any device speaking its protocol).

:func:`open_device` picks the driver of a URI's scheme among the installed driver plugins
(the built-ins are ``sim``, ``usbip``, ``pyusb`` and ``hid``; see :mod:`.uri`), and
:func:`list_devices` asks every driver what it can reach.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

from hcard.plugins.kinds import DriverPlugin
from hcard_device.drivers.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard_device.drivers.errors import (
    DeviceError,
    DeviceStall,
    DeviceTimeout,
    PlayTooLong,
    SessionBusy,
    SessionLost,
    UriError,
)
from hcard_device.drivers.uri import SCHEMES, DeviceUri, parse_uri
from hcard_device.usb.transport import DEFAULT_HOST, DEFAULT_PORT

__all__ = [
    "DEFAULT_TIMEOUT_S",
    "DeviceError",
    "DeviceListing",
    "DeviceStall",
    "DeviceTimeout",
    "DeviceUri",
    "Driver",
    "PlayTooLong",
    "SessionBusy",
    "SessionLost",
    "UriError",
    "driver_classes",
    "list_devices",
    "open_device",
    "parse_uri",
]


def driver_classes() -> dict[str, DriverPlugin]:
    """Driver plugins of the plugin registry by URI scheme: the built-ins (package ``hcard``:
    ``sim``, ``usbip``, ``pyusb``, ``hid``), which keep their schemes, then the other installed
    or registered drivers for other schemes."""
    from hcard.plugins.discovery import CORE_DISTRIBUTION
    from hcard.plugins.registry import get_registry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # `hcard plugins` reports broken plugins
        infos = get_registry().infos("driver")
    by_scheme: dict[str, DriverPlugin] = {}
    for info in sorted(infos, key=lambda info: info.package != CORE_DISTRIBUTION):
        for scheme in getattr(info.obj, "schemes", ()):
            by_scheme.setdefault(str(scheme), info.obj)
    return by_scheme


def open_device(uri: str | DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> Driver:
    """Open the device a URI names with the driver of its scheme.

    Raises:
        UriError: malformed URI or unknown scheme.
        DeviceError: the device is missing, unreachable or not an hcard device.
    """
    drivers = driver_classes()
    if isinstance(uri, str):
        uri = parse_uri(uri, schemes=tuple(dict.fromkeys((*SCHEMES, *drivers))))
    driver = drivers.get(uri.scheme)
    if driver is None:
        raise UriError(f"bad device URI {uri.text!r}: no driver for scheme {uri.scheme!r}")
    return driver.open(uri, timeout_s=timeout_s)


def list_devices(hosts: Sequence[tuple[str, int]] = ((DEFAULT_HOST, DEFAULT_PORT),), *,
                 timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
    """Every device reachable now: hidapi devices with the hcard VID:PID, hcard devices on the
    USB/IP servers ``hosts`` (devlist request), and the in-process ``sim://`` devices. One
    driver failing does not hide the others."""
    listings: list[DeviceListing] = []
    seen: set[Any] = set()
    for driver in driver_classes().values():
        if driver in seen:
            continue
        seen.add(driver)
        try:
            listings += driver.enumerate(hosts, timeout_s=timeout_s)
        except Exception as exc:  # a third-party driver must not break the listing
            warnings.warn(f"driver {getattr(driver, 'name', driver)!r} cannot enumerate: {exc}",
                          stacklevel=2)
    return listings
