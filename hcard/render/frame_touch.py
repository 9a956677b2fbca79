"""Per frame of a block: its touch sample, whether dead reckoning has stopped and the taxtel
under the dead-reckoned finger (spec/README.md rules R5-R7)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard.render.compiled import PHASE_INPUTS, CompiledCard
from hcard.render.crossings import axis_keys, grid_line, segment_crossings
from hcard.render.options import RenderMode, RenderOptions
from hcard.render.touch import TouchTable


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
    """Touch state of the N frames of a block, in S *segments*: runs of frames with one touch
    sample. Per segment, sequences of length S: lists for one segment (the common streaming
    block), else NumPy arrays.

    Attributes:
        texture: (N,) palette index of the taxtel under the dead-reckoned finger (R7), -1 for
            a neutral frame.
        starts: first frame of each segment (the first is 0).
        sample: its touch sample (R5; -1: before the first).
        horizon: its first frame past the dead-reckoning horizon H (R6), the frame after the
            segment if none.
        one_texture: every frame has the same texture.
    """

    texture: np.ndarray
    starts: np.ndarray | list[int]
    sample: np.ndarray | list[int]
    horizon: np.ndarray | list[int]
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
    """The :class:`TouchFrames` of frames at ``times`` (sorted), from the non-empty ``table``.

    Along a segment the dead-reckoned position moves monotonically along each axis
    (``p + v min(t - t_i, H)`` rounds monotonically), and the card and each taxtel are intervals
    per axis: when a segment's first and last frames are on the card in one taxtel (or the
    card, when every taxtel holds the same texture), so is every frame between. The other
    segments are cut where the finger crosses into another taxtel (hcard/render/crossings.py),
    and each piece is looked up at its first frame."""
    n = times.shape[0]
    horizon_s = options.dead_reckoning_s
    sample_t = table.t
    first = int(sample_t.searchsorted(times.item(0), side="right")) - 1
    last = int(sample_t.searchsorted(times.item(-1), side="right")) - 1
    if first == last:
        return _one_segment(card, table, columns, times, first, horizon_s)
    starts = np.empty(last - first + 1, dtype=np.intp)
    starts[0] = 0
    starts[1:] = times.searchsorted(sample_t[first + 1:last + 1])  # R5: t_i <= frame time
    sample = np.arange(first, last + 1)
    ends = np.empty_like(starts)
    ends[:-1] = starts[1:]
    ends[-1] = n
    owned = ends > starts  # a sample followed by another before the next frame owns none
    if not owned.all():
        starts, sample, ends = starts[owned], sample[owned], ends[owned]
    i = np.maximum(sample, 0)
    t_i = sample_t.take(i)
    contact = table.contact.take(i)
    contact &= sample >= 0
    horizon = _first_frames_past(times, t_i, horizon_s, starts, ends)
    horizon[sample < 0] = ends[sample < 0]
    # the axis keys (hcard/render/crossings.py) of the segments' first and last frames
    x0, y0, vx, vy = (a.take(i) for a in (columns.x, columns.y, columns.vx, columns.vy))
    ends -= 1
    keys, inside = [], contact.copy()
    for frame in (starts, ends):
        reckon = times.take(frame) - t_i
        np.minimum(reckon, horizon_s, out=reckon)
        keys.append(axis_keys(card, x0 + vx * reckon, y0 + vy * reckon, inside))
    ends += 1
    (key_x, key_y, cell), (last_x, last_y, _) = keys
    uniform = inside if card.one_texture_grid else inside & (key_x == last_x) & (key_y == last_y)
    segment_texture = np.where(uniform, card.grid.ravel().take(cell), -1)
    counts = ends - starts
    uniform |= ~contact  # neutral throughout
    if uniform.all():
        texture = np.repeat(segment_texture.astype(np.int32), counts)
        one_texture = bool((segment_texture == segment_texture[0]).all())
        return TouchFrames(texture, starts, sample, horizon, one_texture)
    texture = _piecewise_textures(card, table, columns, times, horizon_s, starts, counts, i,
                                  segment_texture, np.flatnonzero(~uniform),
                                  np.stack((key_x, key_y)), np.stack((last_x, last_y)))
    return TouchFrames(texture, starts, sample, horizon, False)


def _piecewise_textures(card: CompiledCard, table: TouchTable, columns: SampleColumns,
                        times: np.ndarray, horizon_s: float, starts: np.ndarray,
                        counts: np.ndarray, sample: np.ndarray, segment_texture: np.ndarray,
                        crossing: np.ndarray, key_first: np.ndarray,
                        key_last: np.ndarray) -> np.ndarray:
    """(N,) texture of every frame: ``segment_texture`` on the segments that hold one, and on
    the ``crossing`` ones (in contact, not in one taxtel throughout) the texture of each piece
    between two taxtel crossings (:func:`hcard.render.crossings.segment_crossings`), looked up
    at its first frame; segments of a position that is not finite, or that skip taxtels
    between frames, are looked up frame by frame. Per segment: ``starts``, ``counts``,
    ``sample`` (its touch sample, in contact), (2, S) x and y keys of its first and last
    frames."""
    rows = sample.take(crossing)
    position = np.stack((columns.x.take(rows), columns.y.take(rows)))
    velocity = np.stack((columns.vx.take(rows), columns.vy.take(rows)))
    finite = np.isfinite(position).all(axis=0) & np.isfinite(velocity).all(axis=0)
    searched = crossing[finite]
    frames, of_segment, by_frame = segment_crossings(
        card, times, horizon_s, starts.take(searched),
        starts.take(searched) + counts.take(searched) - 1, table.t.take(rows[finite]),
        position[:, finite], velocity[:, finite], key_first.take(searched, axis=1),
        key_last.take(searched, axis=1))
    # pieces: every segment from its first frame, the searched ones also from each crossing
    piece_start = np.concatenate((starts, frames))
    piece_texture = np.concatenate((segment_texture, np.empty(frames.shape[0], np.intp)))
    looked_up = np.concatenate((searched, starts.shape[0] + np.arange(frames.shape[0])))
    piece_texture[looked_up] = _textures_at(
        card, table, columns, times, horizon_s, piece_start.take(looked_up),
        sample.take(np.concatenate((searched, searched.take(of_segment)))))
    order = np.argsort(piece_start, kind="stable")
    piece_start = piece_start.take(order)
    lengths = np.empty_like(piece_start)
    np.subtract(piece_start[1:], piece_start[:-1], out=lengths[:-1])
    lengths[-1] = times.shape[0] - piece_start[-1]
    texture = np.repeat(piece_texture.take(order).astype(np.int32), lengths)
    frame_by_frame = np.zeros(starts.shape[0], dtype=bool)
    frame_by_frame[crossing] = True
    frame_by_frame[searched[~by_frame]] = False
    if frame_by_frame.any():
        _look_up_frames(card, table, columns, times, horizon_s, frame_by_frame, sample,
                        np.ones(starts.shape[0], dtype=bool), counts, texture)
    return texture


def _textures_at(card: CompiledCard, table: TouchTable, columns: SampleColumns,
                 times: np.ndarray, horizon_s: float, frames: np.ndarray,
                 sample: np.ndarray) -> np.ndarray:
    """Texture of block frames ``frames`` whose touch samples ``sample`` are in contact (R6,
    R7): the numbers of :func:`_look_up_frames`."""
    x, y = _reckoned_positions(table, columns, times.take(frames), sample, horizon_s)
    return frame_textures(card, x, y, np.ones(frames.shape[0], dtype=bool))


def _reckoned_positions(table: TouchTable, columns: SampleColumns, frame_times: np.ndarray,
                        sample: np.ndarray, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Dead-reckoned finger position (R6), mm, at each of ``frame_times`` (s) from its touch
    sample (row ``sample`` of ``table``), moving for at most ``horizon_s``."""
    reckon = frame_times - table.t.take(sample)
    np.minimum(reckon, horizon_s, out=reckon)
    x = columns.vx.take(sample)
    x *= reckon
    x += columns.x.take(sample)
    y = columns.vy.take(sample)
    y *= reckon
    y += columns.y.take(sample)
    return x, y


def _one_segment(card: CompiledCard, table: TouchTable, columns: SampleColumns,
                 times: np.ndarray, sample: int, horizon_s: float) -> TouchFrames:
    """:func:`touch_frames` of frames that all hold touch sample ``sample``."""
    n = times.shape[0]
    row = max(sample, 0)
    t_i = sample_t = table.t.item(row)
    horizon = first_past_horizon(times, sample_t, horizon_s) if sample >= 0 else n
    if sample < 0 or not table.contact.item(row):
        return TouchFrames(_filled(n, -1), [0], [sample], [horizon], True)
    x0, y0 = columns.x.item(row), columns.y.item(row)
    vx, vy = columns.vx.item(row), columns.vy.item(row)
    start, end = min(times.item(0) - t_i, horizon_s), min(times.item(-1) - t_i, horizon_s)
    index = one_taxtel(card, (x0 + vx * start, y0 + vy * start), (x0 + vx * end, y0 + vy * end))
    if index is not None:
        return TouchFrames(_filled(n, index), [0], [sample], [horizon], True)
    texture = _filled(n, -1)
    _look_up_frames(card, table, columns, times, horizon_s, np.ones(1, dtype=bool),
                    np.array([row]), np.ones(1, dtype=bool), np.array([n]), texture)
    return TouchFrames(texture, [0], [sample], [horizon], False)


def _look_up_frames(card: CompiledCard, table: TouchTable, columns: SampleColumns,
                    times: np.ndarray, horizon_s: float, chosen: np.ndarray, sample: np.ndarray,
                    contact: np.ndarray, counts: np.ndarray, texture: np.ndarray) -> None:
    """Write into ``texture`` the taxtel of each frame of the ``chosen`` segments, frame by
    frame (R6, R7); ``sample``, ``contact``, ``counts``: per segment (samples >= 0)."""
    every = bool(chosen.all())
    if every:
        frame_times = times
    else:
        frames = np.flatnonzero(np.repeat(chosen, counts))
        frame_times = times.take(frames)
        sample, contact, counts = sample[chosen], contact[chosen], counts[chosen]
    x, y = _reckoned_positions(table, columns, frame_times, np.repeat(sample, counts),
                               horizon_s)
    looked_up = frame_textures(card, x, y, np.repeat(contact, counts))
    if every:
        texture[:] = looked_up
    else:
        texture[frames] = looked_up


def _first_frames_past(times: np.ndarray, sample_t: np.ndarray, horizon_s: float,
                       starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """:func:`first_past_horizon` of each segment, within it: ``starts``, ``ends`` (one past)."""
    n = times.shape[0]
    j = times.searchsorted(sample_t + horizon_s)
    while True:  # the binary search on t_i + H may miss the per-frame comparison by a frame
        back = (j > 0) & (times.take(np.maximum(j - 1, 0)) - sample_t >= horizon_s)
        if not back.any():
            break
        j -= back
    while True:
        ahead = (j < n) & (times.take(np.minimum(j, n - 1)) - sample_t < horizon_s)
        if not ahead.any():
            break
        j += ahead
    return np.minimum(np.maximum(j, starts), ends)


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
    card in one taxtel (or, when every taxtel holds the same texture, on the card). With one
    sample the positions move monotonically along each axis (``p + v min(t - t_i, H)`` rounds
    monotonically), and the card and each taxtel are intervals per axis, so then every frame of
    the block is in that taxtel: the numbers of :func:`frame_textures`, from two points."""
    (x0, y0), (x1, y1) = first, last
    width, height = card.width_mm, card.height_mm
    if not (0 <= x0 < width and 0 <= y0 < height and 0 <= x1 < width and 0 <= y1 < height):
        return None
    if card.one_texture_grid:
        return int(card.grid.flat[0])
    column = math.floor(x0 / card.taxtel_width_mm)
    row = math.floor(y0 / card.taxtel_height_mm)
    if column != math.floor(x1 / card.taxtel_width_mm) or \
            row != math.floor(y1 / card.taxtel_height_mm):
        return None
    rows, cols = card.grid.shape
    return int(card.grid[min(max(row, 0), rows - 1), min(max(column, 0), cols - 1)])


def frame_textures(card: CompiledCard, x: np.ndarray, y: np.ndarray,
                   contact: np.ndarray) -> np.ndarray:
    """Palette index of the taxtel under each dead-reckoned position (x, y mm) (R7); -1
    without ``contact`` (which this overwrites) or off the card."""
    inside = contact
    inside &= x >= 0
    inside &= x < card.width_mm
    inside &= y >= 0
    inside &= y < card.height_mm
    return np.where(inside, card.grid.ravel().take(_cells(card, x, y)), -1)


def _cells(card: CompiledCard, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Flat grid index ``row * cols + col`` of each position (x, y mm), clipped to the grid
    (R7)."""
    rows, cols = card.grid.shape
    cell = grid_line(y, card.taxtel_height_mm, rows)
    cell *= cols
    cell += grid_line(x, card.taxtel_width_mm, cols)
    return cell
