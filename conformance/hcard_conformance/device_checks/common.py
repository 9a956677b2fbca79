"""What several device-level checks share: the level, how a measured metric is judged against
its threshold, and conventions of the measurements (stroke speed in mm/s, read catch-up in s,
the plate amplitude counted as off in m)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence

from hcard.device.base import Driver
from hcard_conformance.context import Context
from hcard_conformance.result import CheckResult, guarded

LEVEL = "device"
"""The level of every check of :mod:`hcard_conformance.device_checks`."""
STROKE_SPEED_MM_S = 60.0
"""Speed of the device-level strokes (moderate class of section 5.4), mm/s."""
READ_CATCH_UP_S = 5.0
"""Longest a measurement reads on while the host catches up with its reports, s."""
OFF_AMPLITUDE_M = 50e-9
"""Plate amplitude counted as off, m (the E-ViTa loop's 50 nm amplitude tolerance)."""


def judged(check: str, case: str, metric: str, value: float, threshold: float, unit: str,
           detail: str, *, at_most: bool = True) -> CheckResult:
    """The result of ``check`` on ``case``: ``metric`` measured ``value`` against
    ``threshold`` (both in ``unit``); it passes when ``value`` is finite and at most the
    threshold (at least, with ``at_most=False``)."""
    passed = math.isfinite(value) and (value <= threshold if at_most else value >= threshold)
    return CheckResult(check, LEVEL, case, passed, metric, value, threshold, unit, detail)


def on_one_driver(ctx: Context, check: str, cases: Sequence[str],
                  measure: Callable[[Driver, Callable[[str], bool]], Iterator[CheckResult]],
                  ) -> Iterator[CheckResult]:
    """The cases of ``check`` the run wants (:meth:`Context.wants`) measured by
    ``measure(driver, wants)`` on one driver opened for them all; nothing for an
    implementation without a driver (the reference renderer). An exception is one ERROR per
    wanted case not yet reported (:func:`~hcard_conformance.result.guarded`)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def wants(case: str) -> bool:
        return ctx.wants(check, case)

    def run() -> Iterator[CheckResult]:
        with open_driver() as driver:
            yield from measure(driver, wants)

    yield from guarded(check, LEVEL, [c for c in cases if wants(c)], run)
