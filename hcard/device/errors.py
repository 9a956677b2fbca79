"""Errors of the host drivers. All are :class:`hcard.errors.HcardError`: one line on the CLI."""

from __future__ import annotations

from hcard.errors import HcardError, UsageError


class DeviceError(HcardError):
    """The device failed: it vanished (unplugged, server killed), stopped answering within the
    timeout, refused a request, or sent something the driver cannot use."""


class DeviceTimeout(DeviceError, TimeoutError):
    """A transfer got no answer within its timeout (the device is hung or gone); also a
    :class:`TimeoutError`, as any other timeout."""


class DeviceStall(DeviceError):
    """The device refused a request with a USB STALL (e.g. an unknown or read-only report ID)."""


class DescriptorUnavailable(DeviceError):
    """This driver's transport cannot read the device's USB descriptors (the HID report
    descriptor, or the HID descriptor that announces its length; device protocol PD1, PD2): a
    limit of the transport, not a fault of the device. The conformance suite reports what it
    needed them for as not assessed, with this message."""


class SessionBusy(DeviceError):
    """Another host's session is live on the device (spec section 14, rules PN3, PN8): this
    host's START was refused, or the driver saw the session and sent nothing that changes the
    device. The other host keeps the device; wait for it to STOP, or take the session over."""


class SessionLost(DeviceError):
    """This host's session ended under it (spec section 14, rule PN9): another host took it
    over or began a new session (STATE ``session_number`` changed), or the active card was
    replaced (``card_generation`` changed). Nothing the host received after that is its own;
    the driver sends nothing more that changes the device."""


class UriError(UsageError):
    """A device URI is malformed or names an unknown scheme."""


class PlayTooLong(UsageError):
    """A track would play for longer than one session may last
    (:data:`hcard.device.play.MAX_PLAY_S`)."""
