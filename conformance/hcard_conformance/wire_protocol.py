"""Which implementations the checks of the wire protocol concern (spec/conformance.md
section 4.4).

``device.upload-integrity``, ``device.report-loss``, ``device.refusals``,
``device.descriptor``, ``device.session-ownership`` and ``device.profile-upload`` judge what
a device does with the hcard HID protocol: how it takes a card upload, numbers its STATE
reports, refuses reports it must not carry out, declares its reports, shares itself between
hosts and takes a host's device profile. A driver that renders on the host for a device of
actuator frames (:class:`hcard.device.frame_driver.FrameDriver`, ``Driver.renders_on_host``)
does that bookkeeping itself on the host, and its device speaks a HID protocol of its own;
those checks would judge the host library, not the device, so they are not applicable to
it. ``device.profile-upload`` concerns only a device that takes profiles (capability
PROFILE, protocol 1.1), and judges which profile is in force by the friction rendered,
which needs a host that keeps real time (as ``device.friction``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.device.errors import DeviceError
from hcard.device.protocol import Capability
from hcard_conformance.timing import timing_class

if TYPE_CHECKING:
    from hcard_conformance.context import Context

RENDERS_ON_HOST_KEY = "renders-on-host"
"""``Context.cache`` key of whether the driver renders on the host (asked once per run)."""


def speaks_wire_protocol(ctx: Context) -> bool:
    """The implementation is a device that speaks the hcard protocol itself: a driver that
    does not render on the host. A device that cannot be opened counts as one (its checks
    then report the error)."""
    if ctx.open_driver is None:
        return False
    if RENDERS_ON_HOST_KEY not in ctx.cache:
        try:
            with ctx.open_driver() as driver:
                ctx.cache[RENDERS_ON_HOST_KEY] = bool(getattr(driver, "renders_on_host", False))
        except DeviceError:
            return True
    return not ctx.cache[RENDERS_ON_HOST_KEY]


def takes_host_profiles(ctx: Context) -> bool:
    """The implementation speaks the protocol itself (:func:`speaks_wire_protocol`), its
    device takes a device profile from the host (DEVICE_INFO capability PROFILE, protocol 9.5)
    and the host keeps real time (the timing class; the profile in force is judged by the
    friction rendered). A device that cannot be opened counts as one that takes profiles (its
    check then reports the error)."""
    if not speaks_wire_protocol(ctx) or not timing_class(ctx).keeps_real_time:
        return False
    try:
        info = ctx.device_info()
    except DeviceError:
        return True
    return bool(info.capabilities & Capability.PROFILE)
