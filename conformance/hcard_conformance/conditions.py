"""The conditions a run was judged under: device class and timing class, with why (spec
conformance.md section 6, QP5). They are stated in every report so that a reader knows which
thresholds applied without reading the code."""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard_conformance.timing import timing_class

if TYPE_CHECKING:
    from hcard_conformance.context import Context


def run_conditions(ctx: Context, levels: tuple[str, ...]) -> dict[str, str]:
    """``device_class``, ``device_class_why``, ``timing_class`` and ``timing_class_why`` of a
    run of ``levels`` on ``ctx`` (empty unless the device level runs with a driver). Opens the
    driver once for DEVICE_INFO; a driver that cannot be opened leaves the device class as
    ``unknown`` with the reason (the checks report the failure themselves)."""
    if "device" not in levels or ctx.open_driver is None:
        return {}
    from hcard_conformance.device_checks.device_classes import CLASS_DYNAMICS, device_class

    timing = timing_class(ctx)
    found = {"timing_class": timing.name, "timing_class_why": timing.why}
    try:
        with ctx.open_driver() as driver:
            name = device_class(ctx, driver.info())
    except Exception as exc:  # reported per case by the checks
        return {**found, "device_class": "unknown",
                "device_class_why": f"DEVICE_INFO unavailable: {exc}"}
    chosen = "--option device_class" if ctx.options.get("device_class") else "DEVICE_INFO"
    return {"device_class": name,
            "device_class_why": f"{CLASS_DYNAMICS[name].why} (from {chosen})", **found}
