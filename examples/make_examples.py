"""Write the example friction images of the image encoder (deterministic, no randomness).

Run from the repository root::

    python examples/make_examples.py

It writes, next to this script, grayscale PNGs at 254 dpi (0.1 mm per pixel; black = high
friction, white = low friction, thesis section 5.4.2):

- ``gratings.png`` (40 x 40 mm): four quadrants of sinusoidal gratings of different period and
  orientation (1.0 mm at 0 deg, 1.6 mm at 45 deg, 2.0 mm at 90 deg, 0.8 mm at -30 deg);
- ``checker.png`` (40 x 40 mm): a 10 mm checkerboard of a 1 mm grating and a flat light region;
- ``button.png`` (40 x 30 mm): a sparse layout on a flat background, a dark rounded button and a
  thin raised ridge.

Encode one with ``hcard encode examples/gratings.png -o gratings.hcard``. The button's sharp edges
fall inside 5 mm taxtels; they are represented as baseline steps between taxtels, so a finer grid
(``--taxtel-mm 2``) halves its reconstruction error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

PIXELS_PER_MM = 10.0
DPI = 254


def _coordinates(width_px: int, height_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates (x, y) in millimetres, origin top-left, +y down."""
    y, x = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
    return (x + 0.5) / PIXELS_PER_MM, (y + 0.5) / PIXELS_PER_MM


def grating(
    x: np.ndarray, y: np.ndarray, period_mm: float, orientation_deg: float, phase: float = 0.0
) -> np.ndarray:
    """``cos(2 pi (cos th x + sin th y) / period + phase)`` on the coordinates (mm)."""
    theta = np.radians(orientation_deg)
    return np.cos(2 * np.pi * (np.cos(theta) * x + np.sin(theta) * y) / period_mm + phase)


def gratings_image() -> np.ndarray:
    """Four quadrants of 20 x 20 mm, each a grating around mid gray."""
    x, y = _coordinates(400, 400)
    left, top = x < 20.0, y < 20.0
    wave = np.select(
        [left & top, ~left & top, left & ~top],
        [grating(x, y, 1.0, 0.0), grating(x, y, 1.6, 45.0), grating(x, y, 2.0, 90.0)],
        grating(x, y, 0.8, -30.0),
    )
    return 0.5 - 0.35 * wave


def checker_image() -> np.ndarray:
    """10 mm squares: a 1 mm grating (dark on average) alternating with flat light gray."""
    x, y = _coordinates(400, 400)
    textured = ((x // 10.0) + (y // 10.0)) % 2 == 0
    return np.where(textured, 0.45 - 0.35 * grating(x, y, 1.0, 0.0), 0.85)


def button_image() -> np.ndarray:
    """Flat light background, a dark rounded button and a thin dark ridge."""
    x, y = _coordinates(400, 300)
    # Rounded rectangle 16 x 10 mm centred at (14, 15) mm with 2 mm corner radius.
    dx = np.maximum(np.abs(x - 14.0) - 6.0, 0.0)
    dy = np.maximum(np.abs(y - 15.0) - 3.0, 0.0)
    button = np.hypot(dx, dy) <= 2.0
    ridge = (np.abs(x - 31.0) <= 0.4) & (y > 5.0) & (y < 25.0)
    return np.where(button | ridge, 0.1, 0.9)


def save(gray: np.ndarray, path: Path) -> None:
    """Save gray levels in [0, 1] (0 = black) as an 8-bit PNG at :data:`DPI`."""
    pixels = np.round(np.clip(gray, 0.0, 1.0) * 255.0).astype(np.uint8)
    Image.fromarray(pixels).save(path, dpi=(DPI, DPI), optimize=True)


def main() -> None:
    """Write the examples next to this file and print their sizes."""
    here = Path(__file__).resolve().parent
    for name, image in (
        ("gratings.png", gratings_image()),
        ("checker.png", checker_image()),
        ("button.png", button_image()),
    ):
        path = here / name
        save(image, path)
        print(f"{path}: {image.shape[1]} x {image.shape[0]} pixels, {path.stat().st_size} bytes")


if __name__ == "__main__":
    main()
