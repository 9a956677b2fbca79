"""The vector finger tracks: 50 Hz touch samples after thesis section 5.4.

Speed classes (thesis 5.4.3, spec/conformance.md): ``slow`` below 30 mm/s, ``moderate`` 30 to
180 mm/s, ``fast`` above 180 mm/s, judged by the median speed between consecutive in-contact
samples. Every track is short (at most 1.2 s) so that the golden renders stay small.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hcard.rates import TOUCH_RATE_HZ
from hcard.render.touch import has_velocity, speed_estimate
from hcard.track import FingerTrack, make_track

SLOW_MAX_MM_S = 30.0
"""Upper bound of the slow class, mm/s (thesis 5.4)."""
FAST_MIN_MM_S = 180.0
"""Lower bound of the fast class, mm/s (thesis 5.4)."""
STROKE_Y_MM = 35.0
"""The line of the strokes along x, mm: mid-taxtel on every vector grid (10, 15, 20, 40 mm
pitches: 5 mm from a boundary; 2 mm: 1 mm), never on a boundary, where a touch one protocol
count (10 um) off plays the neighbouring row (tests/conformance/test_vector_boundaries.py)."""
NOISY_Y_MM = 55.0
"""The line of the noisy stroke, mm: as :data:`STROKE_Y_MM`, 5 mm or more from the boundaries
of 10, 15, 20 and 40 mm pitches."""
NOISE_SEED = 20260601
"""Seed of the only random track (sensor noise), fixed so that generation is deterministic."""


@dataclass(frozen=True)
class VectorTrack:
    """A vector track with its name, speed class and tags."""

    name: str
    speed_class: str
    tags: tuple[str, ...]
    track: FingerTrack
    description: str = ""


def _times(duration_s: float) -> np.ndarray:
    n = math.floor(duration_s * TOUCH_RATE_HZ + 1e-9) + 1
    return np.arange(n) / TOUCH_RATE_HZ


def _stroke(start: tuple[float, float], velocity: tuple[float, float],
            duration_s: float) -> FingerTrack:
    t = _times(duration_s)
    return make_track(t, start[0] + velocity[0] * t, start[1] + velocity[1] * t)


def slow_stroke() -> VectorTrack:
    """25 mm/s along +x at y = 35 mm, 1.2 s, crossing x = 60 mm."""
    return VectorTrack("slow-stroke", "slow", ("stroke",),
                       _stroke((45.0, STROKE_Y_MM), (25.0, 0.0), 1.2))


def moderate_stroke() -> VectorTrack:
    """100 mm/s along +x at y = 35 mm from x = 5 to 115 mm, 1.1 s."""
    return VectorTrack("moderate-stroke", "moderate", ("stroke",),
                       _stroke((5.0, STROKE_Y_MM), (100.0, 0.0), 1.1))


def fast_stroke() -> VectorTrack:
    """250 mm/s along +x at y = 35 mm from x = 5 to 115 mm, 0.44 s."""
    return VectorTrack("fast-stroke", "fast", ("stroke",),
                       _stroke((5.0, STROKE_Y_MM), (250.0, 0.0), 0.44))


def diagonal_stroke() -> VectorTrack:
    """120 mm/s along the direction (3, 2) from (10, 10) mm, 0.8 s, across all quadrants."""
    norm = math.hypot(3.0, 2.0)
    velocity = (120.0 * 3.0 / norm, 120.0 * 2.0 / norm)
    return VectorTrack("diagonal-stroke", "moderate", ("stroke", "diagonal"),
                       _stroke((10.0, 10.0), velocity, 0.8))


def _back_and_forth(x0_mm: float, x1_mm: float, speed_mm_s: float,
                    duration_s: float) -> FingerTrack:
    """From ``x0_mm`` to ``x1_mm`` and back at ``speed_mm_s`` along y = 35 mm, for
    ``duration_s`` (s)."""
    t = _times(duration_s)
    period = 2.0 * (x1_mm - x0_mm) / speed_mm_s
    phase = np.mod(t, period) / period
    x = x0_mm + (x1_mm - x0_mm) * np.where(phase < 0.5, 2.0 * phase, 2.0 - 2.0 * phase)
    return make_track(t, x, np.full_like(t, STROKE_Y_MM))


def reversal() -> VectorTrack:
    """80 mm/s back and forth between x = 44 and 76 mm at y = 35 mm: reversals at 0.4 and
    0.8 s, 1.2 s; crosses x = 60 mm (the ``edge`` card) three times."""
    return VectorTrack("reversal", "moderate", ("reversal",),
                       _back_and_forth(44.0, 76.0, 80.0, 1.2))


def scrub() -> VectorTrack:
    """250 mm/s back and forth between x = 20 and 100 mm at y = 35 mm: reversals at 0.32, 0.64
    and 0.96 s, 1.2 s. At each reversal an odometer (R4) overshoots by twice the speed times a
    touch period, 10 mm, until the next one: a position-locked texture rendered velocity-locked
    (R8) is a quarter of a 40 mm period off for a whole leg."""
    return VectorTrack("scrub", "fast", ("reversal",), _back_and_forth(20.0, 100.0, 250.0, 1.2))


def flick() -> VectorTrack:
    """Along +x at y = 35 mm from x = 5 mm, accelerating evenly from 1000 to 1400 mm/s, 0.08 s:
    a 1 mm grating's temporal frequency (R10) stays at or above the band limit (B = 1000 Hz),
    where a renderer plays none of it. (A device reports at 1 kHz, so what it plays above 500 Hz
    reaches the suite aliased: a flat golden shows a grating that was not faded, while a fade
    inside the band could not be judged.)"""
    t = _times(0.08)
    accel = (1400.0 - 1000.0) / 0.08
    x = 5.0 + 1000.0 * t + 0.5 * accel * t * t
    return VectorTrack("flick", "fast", ("stroke", "band-limit"),
                       make_track(t, x, np.full_like(t, STROKE_Y_MM)))


def liftoff() -> VectorTrack:
    """60 mm/s along +x at y = 35 mm; lift-off at 0.5 s, touch-down 0.2 s later 30 mm further
    on; 1.2 s."""
    t = _times(1.2)
    x = 10.0 + 60.0 * t
    lifted = (t > 0.5 + 1e-9) & (t < 0.7 - 1e-9)
    x = np.where(t >= 0.7 - 1e-9, 70.0 + 60.0 * (t - 0.7), x)
    fn = np.where(lifted, 0.0, 0.5)
    return VectorTrack("liftoff", "moderate", ("liftoff", "touchdown"),
                       make_track(t, x, np.full_like(t, STROKE_Y_MM), fn, ~lifted))


def noisy_stroke() -> VectorTrack:
    """60 mm/s along +x at y = 55 mm with seeded sensor noise: 0.05 mm position noise (normal)
    and +-1 ms time-stamp jitter (uniform), 1.0 s."""
    rng = np.random.default_rng(NOISE_SEED)
    t = _times(1.0)
    t = t + rng.uniform(-0.001, 0.001, t.shape)
    x = 20.0 + 60.0 * t + rng.normal(0.0, 0.05, t.shape)
    y = NOISY_Y_MM + rng.normal(0.0, 0.05, t.shape)
    return VectorTrack("noisy-stroke", "moderate", ("noise",), make_track(t, x, y))


TRACK_FACTORIES: tuple[Callable[[], VectorTrack], ...] = (
    slow_stroke,
    moderate_stroke,
    fast_stroke,
    diagonal_stroke,
    reversal,
    liftoff,
    noisy_stroke,
    scrub,
    flick,
)


def vector_tracks() -> list[VectorTrack]:
    """Every vector track, in manifest order."""
    out = []
    for factory in TRACK_FACTORIES:
        doc = " ".join((factory.__doc__ or "").split())
        out.append(dataclasses.replace(factory(), description=doc))
    return out


def contact_speeds(track: FingerTrack) -> np.ndarray:
    """Speeds between consecutive samples that are both in contact, mm/s."""
    both = has_velocity(track.contact[1:], track.contact[:-1])
    return speed_estimate(track.t, track.x, track.y, track.contact)[1:][both]


def speed_class(track: FingerTrack) -> str:
    """``slow``, ``moderate`` or ``fast`` from the median in-contact speed (thesis 5.4)."""
    median = float(np.median(contact_speeds(track)))
    if median < SLOW_MAX_MM_S:
        return "slow"
    if median > FAST_MIN_MM_S:
        return "fast"
    return "moderate"
