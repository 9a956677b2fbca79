"""Image encoder: a grayscale friction picture (black = high friction) to a haptic card.

Modules, one job each: :mod:`.loading` (reading files, pixel limit, gray levels),
:mod:`.geometry` (physical size, taxtel tiling), :mod:`.spectral` (per-taxtel spectral
analysis), :mod:`.textures` and :mod:`.palette` (texture arrays and merging),
:mod:`.reconstruct` (rendering the card back, error), :mod:`.encoder` (options, the encoder).
"""

from __future__ import annotations

from .encoder import (
    DEFAULT_FRICTION_RANGE,
    EncodeOptions,
    ImageEncoder,
    encode_image,
    raw_bitmap_bytes,
)
from .loading import DEFAULT_MAX_PIXELS, load_gray

__all__ = [
    "DEFAULT_FRICTION_RANGE",
    "DEFAULT_MAX_PIXELS",
    "EncodeOptions",
    "ImageEncoder",
    "encode_image",
    "load_gray",
    "raw_bitmap_bytes",
]
