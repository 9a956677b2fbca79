"""The friction an .hjif channel describes, evaluated in numpy from the format's definitions
(rule IJ60 of spec/interchange/hjif.md), and a card texture's friction along the same axis:
the two sides of the fidelity figures of the hjif importer and exporter.

A channel's signal at position ``u`` (ticks) is the sum over its bands, clamped to -1..1 as
the reference's ``Channel::Evaluate`` clamps it. A band plays its last effect whose position is
at or before ``u``, while ``u`` is within that effect's extent (its last keyframe). A
vectorial effect gives ``amp(r) * wave(2 pi f r / timescale + phase)`` with ``r = u -
position``, ``amp`` linear between the amplitude keyframes (constant beyond them), ``f`` the
frequency keyframe in force (the last at or before ``r``; the first before it) and ``wave``
the effect's base signal (sine, or the square, triangle and sawtooth waves of the same
phase); a curve effect gives its amplitude keyframes interpolated linearly. Transient and
wavelet bands contribute nothing here.
"""

from __future__ import annotations

import math

import numpy as np

from hcard.v1 import card_pb2 as pb

from .hjif_model import Band, Channel, Effect

MAX_SAMPLES = 4_000_000
"""Positions evaluated in all channels together (memory and time bound of a fidelity)."""


def channel_signal(channel: Channel, timescale: int, ticks: np.ndarray) -> np.ndarray:
    """The channel's signal (-1..1) at positions ``ticks`` (float ticks)."""
    total = np.zeros_like(ticks, dtype=float)
    for band in channel.bands:
        total += band_signal(band, timescale, ticks)
    return np.clip(total, -1.0, 1.0)


def band_signal(band: Band, timescale: int, ticks: np.ndarray) -> np.ndarray:
    """One band's contribution at ``ticks``."""
    out = np.zeros_like(ticks, dtype=float)
    if band.band_type not in ("VectorialWave", "Curve") or not band.effects:
        return out
    order = sorted(range(len(band.effects)), key=lambda i: band.effects[i].position)
    starts = np.array([band.effects[i].position for i in order], dtype=float)
    which = np.searchsorted(starts, ticks, side="right") - 1
    for slot, i in enumerate(order):
        effect = band.effects[i]
        mask = (which == slot) & (ticks <= effect.position + effect.length)
        if not mask.any():
            continue
        r = ticks[mask] - effect.position
        if band.band_type == "Curve":
            out[mask] = _amplitude(effect, r, default=0.0)
        else:
            out[mask] = _amplitude(effect, r, default=1.0) * _wave(effect, r, timescale)
    return out


def _amplitude(effect: Effect, r: np.ndarray, *, default: float) -> np.ndarray:
    points = [(k.position, k.amplitude) for k in effect.keyframes
              if k.amplitude is not None and k.position is not None]
    if not points:
        return np.full_like(r, default)
    xs = np.array([p for p, _ in points], dtype=float)
    ys = np.array([a for _, a in points], dtype=float)
    return np.interp(r, xs, ys)


def _frequency(effect: Effect, r: np.ndarray) -> np.ndarray:
    points = [(k.position if k.position is not None else 0, k.frequency)
              for k in effect.keyframes if k.frequency is not None]
    if not points:
        return np.zeros_like(r)
    xs = np.array([p for p, _ in points], dtype=float)
    fs = np.array([f for _, f in points], dtype=float)
    index = np.clip(np.searchsorted(xs, r, side="right") - 1, 0, len(fs) - 1)
    return fs[index]


def _wave(effect: Effect, r: np.ndarray, timescale: int) -> np.ndarray:
    """The base signal of ``effect`` at ``r`` ticks from its start; a frequency of 0 gives
    0 for a sine (``sin(0)``), as the reference's ``computeBaseSignal`` does."""
    f = _frequency(effect, r)
    cycles = f * r / timescale + np.where(f != 0, effect.phase / (2 * math.pi), 0.0)
    signal = effect.base_signal
    if signal == "Sine":
        return np.where(f != 0, np.sin(2 * math.pi * cycles), 0.0)
    frac = cycles - np.floor(cycles)
    if signal == "Square":
        return 1.0 - 2.0 * np.round(frac)
    if signal == "Triangle":
        shifted = cycles - 0.25
        return 1.0 - 4.0 * np.abs(np.round(shifted) - shifted)
    if signal == "SawToothUp":
        return 2.0 * (cycles - np.floor(cycles + 0.5))
    return 2.0 * (np.floor(cycles + 0.5) - cycles)


def texture_profile(texture: pb.Texture, u_mm: np.ndarray) -> np.ndarray:
    """Relative friction of ``texture`` at distance ``u_mm`` along each spatial component's
    own wave vector: ``baseline + sum A cos(2 pi k u + phase)`` (temporal components, which
    run in time, are left out)."""
    total = np.full_like(u_mm, texture.baseline, dtype=float)
    for component in texture.components:
        if component.domain == pb.DOMAIN_SPATIAL:
            total += component.amplitude * np.cos(2 * math.pi * component.frequency * u_mm
                                                  + component.phase)
    return total


def sample_grid(length_mm: float, max_k: float, budget: int) -> np.ndarray:
    """Positions along ``[0, length_mm]``, mm: 8 per period of the finest grating and at
    least every 0.05 mm, at most ``budget`` of them (at least 256)."""
    step = min(0.05, 1.0 / (8 * max_k)) if max_k > 0 else 0.05
    count = int(min(max(256, math.ceil(length_mm / step) + 1), max(256, budget)))
    return np.linspace(0.0, length_mm, count)
