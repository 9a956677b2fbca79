"""Per frame of a block: its touch sample, the time since it and the taxtel under the
dead-reckoned finger (spec/README.md rules R5-R7)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard.render.compiled import PHASE_INPUTS, CompiledCard
from hcard.render.options import RenderMode, RenderOptions
from hcard.render.touch import TouchTable

SEARCH_MAX_FRAMES = 256
"""Blocks of at most this many frames find each frame's touch sample by binary search; longer
ones (batch rendering) by one search per sample and a repeat."""


@dataclass(frozen=True)
class SampleColumns:
    """Per-touch-sample arrays gathered from (one table, one rendering mode).

    Attributes:
        start: (M, 6) phase inputs at the sample time: position, odometer (mm), minus the
            touch-down time (s), 1.
        rate: (M, 6) their change per second of dead reckoning (zero for the position in
            position-only mode).
        x, y, vx, vy: (M,) the position columns of ``start`` and ``rate``, contiguous.
    """

    start: np.ndarray
    rate: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray


def sample_columns(table: TouchTable, options: RenderOptions) -> SampleColumns:
    """The :class:`SampleColumns` of ``table``."""
    m = len(table)
    start = np.empty((m, PHASE_INPUTS))
    start[:, 0:2] = table.position
    start[:, 2:4] = table.odometer
    start[:, 4] = -table.contact_start
    start[:, 5] = 1.0
    rate = np.zeros((m, PHASE_INPUTS))
    if options.mode is not RenderMode.POSITION_ONLY:
        rate[:, 0:2] = table.velocity
    rate[:, 2:4] = table.velocity
    return SampleColumns(start, rate, *(np.ascontiguousarray(a) for a in (
        start[:, 0], start[:, 1], rate[:, 0], rate[:, 1])))


@dataclass(frozen=True)
class TouchFrames:
    """Touch state of the N frames of a block.

    Attributes:
        texture: (N,) palette index of the taxtel under the dead-reckoned finger (R7), -1 for
            a neutral frame.
        sample: (N,) index of the frame's touch sample (R5; -1 before the first), or None when
            every frame has the same one, ``one_sample``.
        capped: (N,) whether dead reckoning has reached its horizon H (R6), or None with
            ``one_sample``.
        one_sample: the one touch sample of every frame (-1: before the first), or None.
        one_texture: every frame has the same texture.
    """

    texture: np.ndarray
    sample: np.ndarray | None
    capped: np.ndarray | None
    one_sample: int | None
    one_texture: bool

    @property
    def neutral(self) -> bool:
        """No frame renders a texture."""
        if self.one_texture:
            return self.texture.item(0) < 0
        return self.texture.max() < 0


def touch_frames(
    card: CompiledCard,
    table: TouchTable,
    columns: SampleColumns,
    times: np.ndarray,
    options: RenderOptions,
) -> TouchFrames:
    """The :class:`TouchFrames` of frames at ``times`` (sorted), from the non-empty ``table``."""
    n = times.shape[0]
    horizon = options.dead_reckoning_s
    sample_t = table.t
    last = int(sample_t.searchsorted(times.item(-1), side="right")) - 1
    if last == int(sample_t.searchsorted(times.item(0), side="right")) - 1:
        row = max(last, 0)  # one sample: the common streaming block
        if last < 0 or not table.contact.item(row):
            return TouchFrames(_filled(n, -1), None, None, last, True)
        t_i = sample_t.item(row)
        x0, y0 = columns.x.item(row), columns.y.item(row)
        vx, vy = columns.vx.item(row), columns.vy.item(row)
        start, end = min(times.item(0) - t_i, horizon), min(times.item(-1) - t_i, horizon)
        index = one_taxtel(card, (x0 + vx * start, y0 + vy * start),
                           (x0 + vx * end, y0 + vy * end))
        if index is not None:
            return TouchFrames(_filled(n, index), None, None, last, True)
    sample = frame_samples(sample_t, times)
    i = np.maximum(sample, 0)
    reckon = times - sample_t.take(i)
    np.minimum(reckon, horizon, out=reckon)
    x = columns.vx.take(i)
    x *= reckon
    x += columns.x.take(i)
    y = columns.vy.take(i)
    y *= reckon
    y += columns.y.take(i)
    contact = table.contact.take(i)
    contact &= sample >= 0
    return TouchFrames(frame_textures(card, x, y, contact), sample, reckon == horizon,
                       None, False)


def first_past_horizon(times: np.ndarray, sample_t: float, horizon_s: float) -> int:
    """Index of the first of the sorted ``times`` with ``time - sample_t >= horizon_s`` (the
    frames where dead reckoning has stopped, R6), ``len(times)`` if none: the per-frame
    comparison, found by a binary search and a check of its neighbours."""
    n = times.shape[0]
    j = int(times.searchsorted(sample_t + horizon_s))
    while j > 0 and times.item(j - 1) - sample_t >= horizon_s:
        j -= 1
    while j < n and times.item(j) - sample_t < horizon_s:
        j += 1
    return j


def _filled(n: int, value: int) -> np.ndarray:
    """``np.full(n, value, np.int32)`` without its Python-level wrapper."""
    out = np.empty(n, dtype=np.int32)
    out.fill(value)
    return out


def one_taxtel(card: CompiledCard, first: tuple[float, float],
               last: tuple[float, float]) -> int | None:
    """The palette index of the taxtel that holds both the first and the last dead-reckoned
    position (x, y mm) of a block with one touch sample, None when they are not both on the
    card in one taxtel. With one sample the positions move monotonically along each axis
    (``p + v min(t - t_i, H)`` rounds monotonically), and the card and each taxtel are
    intervals per axis, so then every frame of the block is in that taxtel: the numbers of
    :func:`frame_textures`, from two points."""
    (x0, y0), (x1, y1) = first, last
    width, height = card.width_mm, card.height_mm
    if not (0 <= x0 < width and 0 <= y0 < height and 0 <= x1 < width and 0 <= y1 < height):
        return None
    column = math.floor(x0 / card.taxtel_width_mm)
    row = math.floor(y0 / card.taxtel_height_mm)
    if column != math.floor(x1 / card.taxtel_width_mm) or \
            row != math.floor(y1 / card.taxtel_height_mm):
        return None
    rows, cols = card.grid.shape
    return int(card.grid[min(max(row, 0), rows - 1), min(max(column, 0), cols - 1)])


def frame_samples(sample_t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Index of the latest touch sample at or before each frame time (-1 before the first);
    both time arrays are sorted."""
    n = times.shape[0]
    if n <= SEARCH_MAX_FRAMES:
        return sample_t.searchsorted(times, side="right") - 1
    # Each sample owns the run of frames from the first one at or after it, so a repeat
    # replaces a per-frame binary search.
    first_frame = np.searchsorted(times, sample_t, side="left")
    run = np.diff(np.concatenate(([0], first_frame, [n])))
    return np.repeat(np.arange(-1, sample_t.shape[0]), run)


def frame_textures(card: CompiledCard, x: np.ndarray, y: np.ndarray,
                   contact: np.ndarray) -> np.ndarray:
    """Palette index of the taxtel under each dead-reckoned position (x, y mm) (R7); -1
    without ``contact`` (which this overwrites) or off the card."""
    inside = contact
    inside &= x >= 0
    inside &= x < card.width_mm
    inside &= y >= 0
    inside &= y < card.height_mm
    rows, cols = card.grid.shape
    cell = _grid_line(y, card.taxtel_height_mm, rows)
    cell *= cols
    cell += _grid_line(x, card.taxtel_width_mm, cols)
    return np.where(inside, card.grid.ravel().take(cell), -1)


def _grid_line(position: np.ndarray, pitch: float, count: int) -> np.ndarray:
    """``min(max(floor(position / pitch), 0), count - 1)`` as integers (R7): clipped in
    floating point, where truncation is the floor."""
    cell = position / pitch
    np.minimum(cell, count - 1, out=cell)
    np.maximum(cell, 0.0, out=cell)
    return cell.astype(np.intp)
