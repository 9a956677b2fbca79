"""How faithfully an imported card plays a .haps texture (spec/interchange/haps.md IH13).

Two evaluations written apart from the mapping of :mod:`.haps_card`: the source's friction
along x straight from its keyframes (the phase integrated numerically over the sample grid
and the keyframes, not by the mapping's closed form), and the card's friction as hcard's
renderer plays it in position-only mode (every spatial component position-locked) along a
straight stroke through the middle of the surface.
"""

from __future__ import annotations

import math

import numpy as np

from hcard import limits
from hcard.v1 import card_pb2 as pb

from .haps_parse import HapsTexture

SAMPLE_MM = 0.05
"""Spacing of the samples compared, mm (the smallest taxtel, hcard.limits.MIN_TAXTEL_MM)."""
MAX_NOTE_SAMPLES = 20_000_000
"""Most (note, sample) pairs evaluated; past it the spacing grows (said in the basis)."""
STROKE_SPEED_MM_S = 50.0
"""Speed of the stroke the card is rendered along, mm/s (position-only: any speed gives the
same friction at a position)."""


def sample_positions(width_mm: float, notes: int) -> np.ndarray:
    """Sample positions along x, mm: every :data:`SAMPLE_MM` (coarser when ``notes`` times the
    samples would pass :data:`MAX_NOTE_SAMPLES`), from 0 to just inside ``width_mm``."""
    step = max(SAMPLE_MM, width_mm * max(notes, 1) / MAX_NOTE_SAMPLES)
    count = max(2, math.floor(width_mm / step - 1e-9) + 1)
    return np.arange(count) * step


def source_friction(texture: HapsTexture, x_mm: np.ndarray, *, length_unit_mm: float,
                    low: float, high: float) -> np.ndarray:
    """The source's relative friction at ``x_mm`` (IH8, IH9), from the keyframes directly."""
    half = (high - low) / 2.0
    if high <= 1.0:
        rest, sign = high, -1.0
    elif low >= 1.0:
        rest, sign = low, 1.0
    else:
        rest, sign = (low + high) / 2.0, 0.0
    u = np.asarray(x_mm, dtype=float) / length_unit_mm
    envelope = np.zeros_like(u)
    signal = np.zeros_like(u)
    for note in texture.notes:
        w = u - note.start
        inside = (w >= 0.0) & (w <= note.length)
        a = np.where(inside, np.interp(w, note.amplitude.t, note.amplitude.v), 0.0)
        envelope += note.gain * a
        signal += note.gain * a * np.sin(2.0 * np.pi * _cycles(note.frequency.t,
                                                               note.frequency.v, w, inside))
    peak = _peak_envelope(texture, envelope)
    scale = 1.0 / peak if peak > 1.0 else 1.0
    return rest + sign * half * scale * envelope + half * scale * signal


def _cycles(t: tuple[float, ...], v: tuple[float, ...], w: np.ndarray,
            inside: np.ndarray) -> np.ndarray:
    """Cycles from the note's start to each ``w`` inside it: the trapezoid rule over the
    positions and the keyframes together (exact for a piecewise-linear frequency)."""
    out = np.zeros_like(w)
    if not np.any(inside):
        return out
    grid = np.unique(np.concatenate(([0.0], w[inside], [k for k in t if k > 0.0])))
    f = np.interp(grid, t, v)
    integral = np.concatenate(([0.0], np.cumsum((f[1:] + f[:-1]) / 2.0 * np.diff(grid))))
    out[inside] = np.interp(w[inside], grid, integral)
    return out


def _peak_envelope(texture: HapsTexture, sampled: np.ndarray) -> float:
    """Largest summed gained amplitude: over the samples and at every keyframe and note edge."""
    knots = np.unique(np.concatenate(
        [[n.start, n.start + n.length, *(n.start + k for k in n.amplitude.t)]
         for n in texture.notes]))
    total = np.zeros_like(knots)
    for note in texture.notes:
        w = knots - note.start
        inside = (w >= 0.0) & (w <= note.length)
        total += np.where(inside, note.gain * np.interp(w, note.amplitude.t,
                                                        note.amplitude.v), 0.0)
    return float(max(total.max(initial=0.0), sampled.max(initial=0.0)))


def card_friction(card: pb.Card, x_mm: np.ndarray) -> np.ndarray:
    """The card's friction at ``x_mm`` along ``y = height / 2``, as hcard's renderer plays it
    position-locked: a stroke sampled once per position, one frame per sample."""
    from hcard.render import Renderer, RenderMode, RenderOptions
    from hcard.track import make_track

    step = float(x_mm[1] - x_mm[0])
    rate = STROKE_SPEED_MM_S / step
    t = np.arange(len(x_mm)) / rate
    y = np.full(len(x_mm), card.surface.height_mm / 2.0)
    track = make_track(t, np.asarray(x_mm, dtype=float), y, 0.5)
    options = RenderOptions(frame_rate_hz=rate, band_limit_hz=0.4 * rate,
                            mode=RenderMode.POSITION_ONLY)
    frames = Renderer(card, options).render(track)
    return np.asarray(frames.friction[: len(x_mm)], dtype=float)


def fidelity(card: pb.Card, texture: HapsTexture, *, length_unit_mm: float, low: float,
             high: float) -> dict[str, float | int | str]:
    """rms and max error of the card against the source, relative friction and in JND."""
    x = sample_positions(card.surface.width_mm, len(texture.notes))
    want = source_friction(texture, x, length_unit_mm=length_unit_mm, low=low, high=high)
    got = card_friction(card, x)
    error = got - want
    rms = float(np.sqrt(np.mean(error * error)))
    worst = float(np.max(np.abs(error)))
    jnd = limits.RELATIVE_FRICTION_JND
    step = float(x[1] - x[0])
    return {
        "rms_error": rms,
        "max_error": worst,
        "rms_error_jnd": rms / jnd,
        "max_error_jnd": worst / jnd,
        "fidelity_samples": len(x),
        "fidelity_basis": (
            f"the card rendered position-locked (hcard renderer, position-only mode) along a "
            f"straight stroke through the middle of the surface, against the source's friction "
            f"evaluated from its keyframes, every {step:g} mm"),
    }
