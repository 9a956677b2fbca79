"""Taxtel crossings: the frames of a segment (the frames of one touch sample) where the
dead-reckoned finger may enter another taxtel, or leave or enter the card (spec/README.md rule
R7), found by a search over a few frames instead of a lookup of every frame.

Along a segment the dead-reckoned position ``p + v min(t - t_i, H)`` moves monotonically along
each axis (every floating-point operation in it rounds monotonically), so along each axis the
*key* ``cell + [p >= 0] + [p >= extent]`` (R7's clipped cell plus the card edges passed) is
monotonic too: a sum of monotonic terms, constant only where each term is. Between two changes
of either key the cells and the sides of the card's edges stay, and with them the frame's
taxtel and whether it lies on the card: such frames share their texture. Each change is the
first frame whose key reaches the next value, found by a binary search on the per-frame key
(the numbers of a lookup of that frame), started at the frame where the straight line meets
the cell's edge: the answer, bar rounding.
"""

from __future__ import annotations

import numpy as np

from hcard.render.compiled import CompiledCard

CROSSINGS_PER_FRAME = 0.5
"""A segment is searched when its key changes are at most this many per frame; one with more
(a finger that skips taxtels between frames) is looked up frame by frame, which costs less."""


def grid_line(position: np.ndarray, pitch: float | np.ndarray,
              count: int | np.ndarray) -> np.ndarray:
    """``min(max(floor(position / pitch), 0), count - 1)`` as integers (R7): clipped in
    floating point, where truncation is the floor. A position that is not a number (a track
    whose velocity overflows) gets cell 0; it is off the card."""
    cell = position / pitch
    np.fmin(cell, count - 1, out=cell)
    np.fmax(cell, 0.0, out=cell)
    return cell.astype(np.intp)


def axis_keys(card: CompiledCard, x: np.ndarray, y: np.ndarray,
              inside: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The x and y keys of positions (x, y mm) and their flat grid index ``row * cols + col``
    (R7, clipped to the grid); ``inside`` (which this updates) is cleared off the card."""
    rows, cols = card.grid.shape
    key_x, key_y = grid_line(x, card.taxtel_width_mm, cols), grid_line(y, card.taxtel_height_mm,
                                                                          rows)
    cell = key_y * cols
    cell += key_x
    for key, position, extent in ((key_x, x, card.width_mm), (key_y, y, card.height_mm)):
        on, past = position >= 0, position >= extent
        inside &= on
        inside &= ~past
        key += on
        key += past
    return key_x, key_y, cell


def segment_crossings(card: CompiledCard, times: np.ndarray, horizon_s: float,
                      first: np.ndarray, last: np.ndarray, sample_t: np.ndarray,
                      position: np.ndarray, velocity: np.ndarray, key_first: np.ndarray,
                      key_last: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frames where the texture of S segments may change.

    Args:
        times: (N,) frame times of the block, s.
        first, last: (S,) first and last frame of each segment (block frame index).
        sample_t: (S,) time of each segment's touch sample, s.
        position, velocity: (2, S) its position (mm) and velocity (mm/s), finite.
        key_first, key_last: (2, S) the x and y keys of its first and last frames.

    Returns:
        frames: frames (block frame index, each after its segment's first; not sorted, and
            some may repeat) where an axis key changes, in the searched segments.
        segment: the segment of each.
        frame_by_frame: (S,) the segments not searched (too many changes per frame).
    """
    segments = first.shape[0]
    changes = np.abs(key_last - key_first)
    frame_by_frame = changes.sum(axis=0) > CROSSINGS_PER_FRAME * (last - first + 1)
    changes[:, frame_by_frame] = 0
    changes = changes.ravel()  # items: the x axis of each segment, then its y axis
    # one search per key value passed: the first frame where direction * key >= target
    item = np.repeat(np.arange(2 * segments), changes)
    on_y = item >= segments
    segment = item - on_y * segments
    direction = np.sign(key_last - key_first).ravel().take(item)
    target = direction * key_first.ravel().take(item)
    target += np.arange(1, item.shape[0] + 1)
    target -= np.repeat(np.cumsum(changes) - changes, changes)  # the nth key value passed
    line = Line(card, times, horizon_s, on_y, sample_t.take(segment),
                position.ravel().take(item), velocity.ravel().take(item))
    found = first_reached(line, direction, target, first.take(segment), last.take(segment),
                          line.guess(direction, target))
    return found, segment, frame_by_frame


def first_reached(line: Line, direction: np.ndarray, target: np.ndarray, low: np.ndarray,
                  high: np.ndarray, guess: np.ndarray) -> np.ndarray:
    """For each search, the first frame after ``low`` (not reached) and up to ``high``
    (reached) where ``direction * key >= target`` along ``line``: the guess and the frame
    before it decide most searches at once, a bisection the rest (a guess off by rounding)."""
    guess = np.clip(guess, low + 1, high)
    low, high = low.copy(), high.copy()
    before = line.reached(direction, target, guess - 1)
    at = line.reached(direction, target, guess)
    np.copyto(low, guess - 1, where=~before)
    np.copyto(high, guess - 1, where=before)
    np.copyto(low, guess, where=~at)
    np.copyto(high, guess, where=at & ~before)
    while True:
        open_ = np.flatnonzero(high - low > 1)
        if open_.shape[0] == 0:
            return high
        middle = (low.take(open_) + high.take(open_)) // 2
        hit = line.reached(direction.take(open_), target.take(open_), middle, open_)
        high[open_[hit]] = middle[hit]
        low[open_[~hit]] = middle[~hit]


class Line:
    """The dead-reckoned position along one axis of the segment of each search (R6), from
    per-search arrays: ``on_y`` (the y axis, else x), ``sample_t`` (time of the segment's touch
    sample, s), ``start`` (its position on the axis, mm) and ``velocity`` (mm/s)."""

    def __init__(self, card: CompiledCard, times: np.ndarray, horizon_s: float,
                 on_y: np.ndarray, sample_t: np.ndarray, start: np.ndarray,
                 velocity: np.ndarray) -> None:
        rows: int
        cols: int
        rows, cols = card.grid.shape
        self.times, self.horizon_s = times, horizon_s
        self.sample_t, self.start, self.velocity = sample_t, start, velocity
        self.pitch = np.where(on_y, card.taxtel_height_mm, card.taxtel_width_mm)
        self.count = np.where(on_y, rows, cols)
        self.extent = np.where(on_y, card.height_mm, card.width_mm)

    def reached(self, direction: np.ndarray, target: np.ndarray, frame: np.ndarray,
                which: np.ndarray | None = None) -> np.ndarray:
        """Whether ``direction * key >= target`` at block frames ``frame``, for the searches
        ``which`` (default: all), from the position R6 gives the frame: the lookup's numbers."""
        def of(a: np.ndarray) -> np.ndarray:
            return a if which is None else a.take(which)

        reckon = self.times.take(frame)
        reckon -= of(self.sample_t)
        np.minimum(reckon, self.horizon_s, out=reckon)
        position = of(self.velocity) * reckon
        position += of(self.start)
        key = grid_line(position, of(self.pitch), of(self.count))
        key += position >= 0
        key += position >= of(self.extent)
        key *= direction
        return key >= target

    def guess(self, direction: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The frame where the straight line first reaches key ``direction * target`` (the
        edge of cell ``key - 1``, or the card's edge), before any rounding."""
        edge = direction * target
        edge -= direction > 0
        edge = edge * self.pitch
        np.clip(edge, 0.0, self.extent, out=edge)
        edge -= self.start
        edge /= self.velocity
        edge += self.sample_t
        return self.times.searchsorted(edge)
