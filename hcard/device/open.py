"""Open a device by URI, and list the devices the installed drivers reach.

:func:`open_device` picks the driver of a URI's scheme among the installed driver plugins (the
host library's ``usbip``, ``pyusb`` and ``hid``, the reference device's ``sim`` and
``control``, and any vendor's; see :mod:`.uri`), and :func:`list_devices` asks every driver
what it can reach.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard.device.errors import UriError
from hcard.device.transports.usbip_connect import DEFAULT_HOST, DEFAULT_PORT
from hcard.device.uri import SCHEMES, DeviceUri, parse_uri
from hcard.plugins.kinds import DriverPlugin


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
