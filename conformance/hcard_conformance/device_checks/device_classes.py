"""The device classes of the device level and the plate dynamics each requires (D1 bandwidth in
Hz, D2 rise time in s): chosen with ``--option device_class=...``, else by DEVICE_INFO's device
kind."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hcard.device.protocol import DeviceInfo, DeviceKind

if TYPE_CHECKING:
    from hcard_conformance.context import Context


@dataclass(frozen=True)
class Dynamics:
    """Plate dynamics required of a device class.

    Attributes:
        min_bandwidth_hz: -3 dB bandwidth of the plate amplitude at least, Hz.
        max_rise_s: 10-90 % rise time of the plate amplitude at most, s.
        why: where the numbers come from.
    """

    min_bandwidth_hz: float
    max_rise_s: float
    why: str


CLASS_DYNAMICS = {
    "e-vita": Dynamics(
        400.0, 0.002, "e-vita class (spec/conformance.md D1, D2): 400 Hz at 2 um (thesis "
        "5.1.2); rise-time JND 2 ms"),
    "coupled": Dynamics(
        20.0, 0.015, "coupled class: standalone plate of thesis 4.3.2, ~15 ms response "
        "(tau 6.8 ms, 23 Hz)"),
}
"""Required plate dynamics by device class (``--option device_class=...``; by default from
DEVICE_INFO.device_kind: 1 e-vita, 2 coupled)."""


def device_class(ctx: Context, info: DeviceInfo) -> str:
    """The device class of the run: ``ctx.options["device_class"]``, else by device kind."""
    name = str(ctx.options.get("device_class", ""))
    if name:
        if name not in CLASS_DYNAMICS:
            raise ValueError(f"unknown device class {name!r}; known: {', '.join(CLASS_DYNAMICS)}")
        return name
    return "coupled" if info.device_kind == DeviceKind.COUPLED else "e-vita"
