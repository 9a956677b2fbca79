"""Timing classes: what the host of a device-level run can promise about time (spec/conformance.md
section 5.2).

A device-level measurement is made by the host as much as by the device: the host sends the
finger samples and streamed frames and reads the STATE reports. On a bench PC (``real-time``,
the default) the host keeps real time and every device check applies with the thresholds of
its device class. In a software-emulated machine (``software-emulation``: the QEMU/TCG guest
tier, where the host's own Python runs 10-20x slower) the host cannot feed a 10 kHz stream or
a 50 Hz finger without stalls of tens to hundreds of milliseconds; checks that measure the
device *through* the host's timing (rendered friction along a stroke, plate dynamics under
streaming) would measure the host, so the class declares them not applicable, and bounds what
the host does see: latency and report loss, loosely but finitely.

Choose with ``--option timing=software-emulation``; the report states the class and why.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hcard_conformance.context import Context


@dataclass(frozen=True)
class TimingClass:
    """What the host promises about time, and the thresholds that follow.

    Attributes:
        name: ``real-time`` or ``software-emulation``.
        latency_s: largest median finger-to-plate latency of D3, s.
        host_report_loss: largest fraction of STATE reports the host may fail to read
            (the device itself must drop none it could deliver).
        read_lag_s: largest median delay from a report's own time on the host clock (PI3) to
            the host reading it, s (case ``host-read-lag`` of D3).
        keeps_real_time: the host can stream frames and finger samples without stalls; the
            checks that measure the device through host timing (``device.friction``,
            ``device.dynamics``) apply only then.
        why: where the numbers come from.
    """

    name: str
    latency_s: float
    host_report_loss: float
    read_lag_s: float
    keeps_real_time: bool
    why: str

    @property
    def report_wait_s(self) -> float:
        """Longest a host of this class reads on for a report that shows what it just sent,
        s: the D3 latency of the device applying it plus the host's read lag."""
        return self.latency_s + self.read_lag_s


REAL_TIME = TimingClass(
    "real-time", 0.010, 0.001, 0.010, True,
    "real-time host (bench PC): D3 10 ms keeps v_max * L within A4/A5 (spec 4.3); at most "
    "1 report in 1000 lost, as on a USB full-speed interrupt pipe with a polling host")
SOFTWARE_EMULATION = TimingClass(
    "software-emulation", 0.250, 0.75, 2.0, False,
    "software-emulated host (QEMU TCG guest tier): the guest's Python runs 10-20x slower and "
    "stalls for tens to hundreds of ms; median latency bounded at 250 ms and host-side "
    "report loss at 75 % (measured idle: 40-80 ms median, ~50 % lost); rendered friction and "
    "plate dynamics need a host that keeps real time and are judged in the usbip tier")

TIMING_CLASSES = {c.name: c for c in (REAL_TIME, SOFTWARE_EMULATION)}
"""The timing classes by name."""


def timing_class(ctx: Context) -> TimingClass:
    """The timing class of the run: ``ctx.options["timing"]``, else ``real-time``.

    Raises:
        ValueError: unknown class name.
    """
    name = str(ctx.options.get("timing", "") or REAL_TIME.name)
    if name not in TIMING_CLASSES:
        raise ValueError(f"unknown timing class {name!r}; known: {', '.join(TIMING_CLASSES)}")
    return TIMING_CLASSES[name]


def needs_real_time_host(ctx: Context) -> bool:
    """Applicability of the checks that measure the device through the host's timing: a
    driver, and a host of a timing class that keeps real time."""
    return ctx.open_driver is not None and timing_class(ctx).keeps_real_time
