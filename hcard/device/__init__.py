"""The host library: talk to friction-display devices from a host, with or without the
reference device installed.

* :mod:`.protocol`: the hcard HID wire protocol (spec/device-protocol.md): reports, codec,
  descriptor, upload chunking, USB identity;
* :class:`Driver` (:mod:`.base`): the driver contract a vendor implements (five transport
  primitives; the protocol on top is the base class's), :mod:`.transports`: the built-in
  transports (USB/IP, pyusb, hidapi), :mod:`.driver_table`: their registration;
* :func:`open_device` / :func:`list_devices` (:mod:`.open`) and device URIs (:mod:`.uri`);
* the host workflows: :mod:`.play` (play a card along a finger track), :mod:`.recording` (the
  session as a recording), :mod:`.verify` (a calibration checked on a device);
* what the host library asks of plugins: devices simulated in this process
  (:mod:`.in_process`) and the profile a device publishes (:mod:`.published_profiles`).

The names below are imported on first use, so that importing a submodule (the plugin
registration in :mod:`.driver_table`, listed by ``hcard plugins``) loads no driver.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
    from hcard.device.errors import (
        DescriptorUnavailable,
        DeviceError,
        DeviceStall,
        DeviceTimeout,
        PlayTooLong,
        SessionBusy,
        SessionLost,
        UriError,
    )
    from hcard.device.open import driver_classes, list_devices, open_device
    from hcard.device.uri import DeviceUri, parse_uri

_LAZY = {
    **dict.fromkeys(("DEFAULT_TIMEOUT_S", "DeviceListing", "Driver"), "hcard.device.base"),
    **dict.fromkeys(("DescriptorUnavailable", "DeviceError", "DeviceStall", "DeviceTimeout",
                     "PlayTooLong", "SessionBusy", "SessionLost", "UriError"),
                    "hcard.device.errors"),
    **dict.fromkeys(("driver_classes", "list_devices", "open_device"), "hcard.device.open"),
    **dict.fromkeys(("DeviceUri", "parse_uri"), "hcard.device.uri"),
}
"""The module of each name, imported on first use."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hcard.device' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = [
    "DEFAULT_TIMEOUT_S",
    "DescriptorUnavailable",
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
