"""Measures of a rendered preview read from its pixels: how much of it is blank paper and the
largest blank rectangle, the columns of a curve of a given ink, colour distances."""

from __future__ import annotations

import numpy as np

NEAR_WHITE = 245
"""A pixel whose three channels are all at least this (of 255) is blank paper."""
TILE_PX = 20
"""Side of the tiles the blank-block scan works in, pixels."""


def near_white(rgb: np.ndarray) -> np.ndarray:
    """``(h, w)`` booleans: the near-white pixels of an ``(h, w, 3)`` uint8 image."""
    return np.all(rgb >= NEAR_WHITE, axis=2)


def white_share(rgb: np.ndarray) -> float:
    """Fraction of the image's pixels that are near-white."""
    return float(near_white(rgb).mean())


def blank_tiles(rgb: np.ndarray, tile: int = TILE_PX) -> np.ndarray:
    """``(rows, cols)`` booleans: tiles of ``tile`` x ``tile`` pixels holding only near-white
    pixels (the image's ragged right and bottom edges are left out)."""
    white = near_white(rgb)
    rows, cols = white.shape[0] // tile, white.shape[1] // tile
    blocks = white[:rows * tile, :cols * tile].reshape(rows, tile, cols, tile)
    return blocks.all(axis=(1, 3))


def largest_blank_rectangle(rgb: np.ndarray, tile: int = TILE_PX) -> tuple[int, int]:
    """``(width, height)`` in pixels of the largest rectangle of blank tiles (by area): the
    largest rectangle under the histogram of blank tiles above each row."""
    blank = blank_tiles(rgb, tile)
    heights = np.zeros(blank.shape[1], dtype=int)
    best = (0, 0)
    for row in blank:
        heights = np.where(row, heights + 1, 0)
        stack: list[tuple[int, int]] = []  # (left edge, height), heights increasing
        for i, h in enumerate([*heights.tolist(), 0]):
            left = i
            while stack and stack[-1][1] >= h:
                left, top = stack.pop()
                if (i - left) * top > best[0] * best[1]:
                    best = (i - left, top)
            stack.append((left, h))
    return best[0] * tile, best[1] * tile


def blank_block_share(rgb: np.ndarray, tile: int = TILE_PX) -> float:
    """Area of the largest blank rectangle as a fraction of the image's area."""
    width, height = largest_blank_rectangle(rgb, tile)
    return width * height / (rgb.shape[0] * rgb.shape[1])
