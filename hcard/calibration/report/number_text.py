"""Numbers of a calibration report written for people: forces in mN, figures to a few
significant digits, values with their uncertainty in a readable unit (``report.md`` and the
figures' legends)."""

from __future__ import annotations

import math

from hcard.quantities import MN_PER_N, display_unit


def force_in_mn(value: float | None) -> str:
    """A force in N as mN, the way :func:`~hcard.calibration.loop.calibrate` writes it."""
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value * MN_PER_N:.4g}"


def number(value: float | None, spec: str = ".3g") -> str:
    """``value`` formatted by ``spec``; ``"n/a"`` for None or NaN, ``"inf"`` or ``"-inf"``."""
    if value is None or not math.isfinite(value):
        return "n/a" if value is None or math.isnan(value) else ("inf" if value > 0 else "-inf")
    return format(value, spec)


def value_with_unit(value: float, uncertainty: float | None, unit: str) -> str:
    """``"12.3 ± 0.4 ms"``: value (and uncertainty) in a readable unit."""
    scale, shown = display_unit(unit, [value])
    text = f"{value / scale:.4g}"
    if uncertainty is not None:
        text += " ± " + (
            f"{uncertainty / scale:.2g}" if math.isfinite(uncertainty) else "not identified"
        )
    return f"{text} {shown}" if shown else text
