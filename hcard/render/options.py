"""Renderer settings, with the defaults of spec/README.md section 6."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import hcard.limits as limits
from hcard.rates import DEFAULT_FRAME_RATE_HZ

DEFAULT_BAND_LIMIT_HZ = 1_000.0
"""Upper edge of the perceptual band of friction signals (thesis 5.2.3: ~800 Hz content felt)."""
DEFAULT_DEAD_RECKONING_S = 0.1
"""Longest extrapolation past the last touch sample, s (five periods of a 50 Hz sensor)."""
PASSBAND_FRACTION = 0.8
"""Components below this fraction of the band limit pass with unit gain."""
MAX_BAND_LIMIT_FRACTION_OF_FRAME_RATE = 0.4


class RenderMode(str, Enum):
    """``hybrid``: the hcard rendering equation. ``position-only``: the classic map lookup of
    thesis 5.3.1 (every spatial component position-locked, the map sampled at the last touch
    sample with no dead reckoning), kept as the baseline that hybrid control is judged against."""

    HYBRID = "hybrid"
    POSITION_ONLY = "position-only"


@dataclass(frozen=True)
class RenderOptions:
    """Settings of a rendering.

    Attributes:
        frame_rate_hz: output frames per second, Hz.
        band_limit_hz: components whose temporal frequency reaches this are silenced, Hz; they
            pass unchanged below ``0.8 *`` it. At most 0.4 x the frame rate.
        dead_reckoning_s: longest extrapolation of the finger past its last touch sample, s.
        auto_period_mm: LOCKING_AUTO threshold; shorter spatial periods are velocity-locked, mm.
        mode: hybrid (default) or the position-only baseline.
    """

    frame_rate_hz: float = DEFAULT_FRAME_RATE_HZ
    band_limit_hz: float = DEFAULT_BAND_LIMIT_HZ
    dead_reckoning_s: float = DEFAULT_DEAD_RECKONING_S
    auto_period_mm: float = limits.AUTO_LOCKING_PERIOD_MM
    mode: RenderMode = RenderMode.HYBRID

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", RenderMode(self.mode))
        for name in ("frame_rate_hz", "band_limit_hz", "auto_period_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        if not (math.isfinite(self.dead_reckoning_s) and self.dead_reckoning_s >= 0):
            raise ValueError(f"dead_reckoning_s must be >= 0, got {self.dead_reckoning_s}")
        most = MAX_BAND_LIMIT_FRACTION_OF_FRAME_RATE * self.frame_rate_hz
        if self.band_limit_hz > most:
            raise ValueError(
                f"band_limit_hz {self.band_limit_hz} is above 0.4 x the frame rate ({most} Hz): "
                "components near the Nyquist frequency would alias"
            )
