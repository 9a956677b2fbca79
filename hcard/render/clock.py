"""The frame grid: the time of every frame of a rendering (spec/README.md rule R3)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

GALLOP_STEPS = 64
"""Doublings a frame search may take before it trusts its estimate (a frame rate so high that
frames share their times)."""


@dataclass(frozen=True)
class FrameClock:
    """Frame j is at ``t0 + j / frame_rate_hz`` (R3: in double precision, ``(double) j / fs``
    added to ``t0``), plus ``shift_s`` (a stream rendering on another time line,
    :meth:`hcard.render.RenderStream.render`). Frames before frame 0 (negative j) follow the
    same rule."""

    t0: float
    frame_rate_hz: float
    shift_s: float = 0.0

    def times(self, first: int, count: int, out: np.ndarray | None = None) -> np.ndarray:
        """Times of frames ``first .. first + count - 1``, s (into ``out`` when given)."""
        if out is None:
            return self.times_of(np.arange(first, first + count, dtype=np.float64))
        np.divide(np.arange(first, first + count, dtype=np.float64), self.frame_rate_hz,
                  out=out)
        np.add(self.t0, out, out=out)  # the operations of times_of
        if self.shift_s:
            out += self.shift_s
        return out

    def times_of(self, frames: np.ndarray | list[int]) -> np.ndarray:
        """Times of the frames ``frames``, s."""
        times = self.t0 + np.asarray(frames, dtype=np.float64) / self.frame_rate_hz
        if self.shift_s:
            times += self.shift_s
        return times

    def time(self, frame: int) -> float:
        """Time of frame ``frame``, s: the number :meth:`times` gives."""
        time = self.t0 + frame / self.frame_rate_hz
        return time + self.shift_s if self.shift_s else time

    def first_at_or_after(self, t: float) -> int:
        """The first frame at or after ``t`` (s)."""
        return self._first(lambda j: self.time(j) >= t, t)

    def first_past(self, t: float, interval_s: float) -> int:
        """The first frame at least ``interval_s`` after ``t``, by the per-frame difference
        ``time - t >= interval_s`` (R6's ``min(tau - t_i, H)``)."""
        return self._first(lambda j: self.time(j) - t >= interval_s, t + interval_s)

    def _first(self, reached: Callable[[int], bool], t: float) -> int:
        """The first frame where ``reached`` (monotonic in the frame) holds, searched from the
        estimate at time ``t``: a step or two in practice, a galloping binary search else."""
        ratio = (t - self.shift_s - self.t0) * self.frame_rate_hz
        guess = math.ceil(ratio) if math.isfinite(ratio) and abs(ratio) < 2.0**52 else 0
        if reached(guess):
            low, high, step = guess - 1, guess, 1
            while reached(low):
                if step > 2**GALLOP_STEPS:
                    return guess
                high, low, step = low, low - step, 2 * step
        else:
            low, high, step = guess, guess + 1, 1
            while not reached(high):
                if step > 2**GALLOP_STEPS:
                    return guess
                low, high, step = high, high + step, 2 * step
        while high - low > 1:  # reached(high), not reached(low)
            middle = (low + high) // 2
            if reached(middle):
                high = middle
            else:
                low = middle
        return high
