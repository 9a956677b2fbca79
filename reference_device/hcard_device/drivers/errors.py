"""Errors of the host drivers. All are :class:`hcard.errors.HcardError`: one line on the CLI."""

from __future__ import annotations

from hcard.errors import HcardError


class DeviceError(HcardError):
    """The device failed: it vanished (unplugged, server killed), stopped answering within the
    timeout, refused a request, or sent something the driver cannot use."""


class DeviceTimeout(DeviceError):
    """A transfer got no answer within its timeout (the device is hung or gone)."""


class DeviceStall(DeviceError):
    """The device refused a request with a USB STALL (e.g. an unknown or read-only report ID)."""


class UriError(HcardError):
    """A device URI is malformed or names an unknown scheme."""
