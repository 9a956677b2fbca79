"""What the bitmap tests share: hand-made PNGs and an evaluation of a card's friction written
directly from the card format (spec/README.md R7-R11 for a finger at rest at each point,
position-locked), independent of the exporter's (the image encoder's reconstruction)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image

from hcard.v1 import card_pb2 as pb

JND = 0.08


def save_png(pixels: np.ndarray, path: Path, *, mode: str | None = None,
             dpi: float | None = None) -> Path:
    """``pixels`` (uint8 or uint16 array, gray or with bands) as a PNG, with pHYs when
    ``dpi``."""
    image = Image.fromarray(pixels, mode=mode) if mode else Image.fromarray(pixels)
    if dpi is None:
        image.save(path)
    else:
        image.save(path, dpi=(dpi, dpi))
    return path


def card_friction(card: pb.Card, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Relative friction ``m`` of ``card`` at surface points ``(x, y)`` mm: taxtel by R7, each
    spatial component ``A cos(2 pi k (n . p) + phase)`` position-locked, temporal components
    at rest (left out), channels split by R11 written out for one texture at a time."""
    tw, th = card.grid.taxtel_width_mm, card.grid.taxtel_height_mm
    col = np.minimum(np.floor(x / tw).astype(int), card.grid.cols - 1)
    row = np.minimum(np.floor(y / th).astype(int), card.grid.rows - 1)
    index = np.asarray(card.grid.texture_index)[row * card.grid.cols + col]
    out = np.empty(x.shape)
    for t, texture in enumerate(card.textures):
        here = index == t
        sums = {key: np.zeros(int(here.sum()))
                for key in (pb.CHANNEL_UV, pb.CHANNEL_EV, pb.CHANNEL_BIPOLAR)}
        sums[texture.channel] += texture.baseline - 1.0
        for c in texture.components:
            if c.domain != pb.DOMAIN_SPATIAL:
                continue
            along = math.cos(c.orientation) * x[here] + math.sin(c.orientation) * y[here]
            wave = c.amplitude * np.cos(2 * math.pi * c.frequency * along + c.phase)
            sums[c.channel or texture.channel] += wave
        uv = np.clip(1 + sums[pb.CHANNEL_UV], 0, 1)
        ev = np.clip(1 + sums[pb.CHANNEL_EV], 1, 4)
        bi = np.clip(1 + sums[pb.CHANNEL_BIPOLAR], 0, 4)
        out[here] = uv * np.minimum(bi, 1) * np.minimum(ev * np.maximum(bi, 1), 4)
    return out


def pixel_centres(card: pb.Card, width_px: int, height_px: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Surface coordinates (mm) of the centres of a ``width_px`` x ``height_px`` raster over
    the card's surface, as ``(height_px, width_px)`` arrays."""
    x = (np.arange(width_px) + 0.5) * card.surface.width_mm / width_px
    y = (np.arange(height_px) + 0.5) * card.surface.height_mm / height_px
    return np.meshgrid(x, y)
