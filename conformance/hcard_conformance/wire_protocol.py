"""Which implementations the checks of the wire protocol concern (spec/conformance.md
section 4.4).

``device.upload-integrity``, ``device.report-loss``, ``device.refusals``, ``device.descriptor``
and ``device.session-ownership`` judge what a device does with the hcard HID protocol: how it
takes a card upload, numbers its STATE reports, refuses reports it must not carry out, declares
its reports and shares itself between hosts. A driver that renders on the host for a device of
actuator frames (:class:`hcard.device.frame_driver.FrameDriver`, ``Driver.renders_on_host``)
does that bookkeeping itself on the host, and its device speaks a HID protocol of its own;
those checks would judge the host library, not the device, so they are not applicable to it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.device.errors import DeviceError

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
