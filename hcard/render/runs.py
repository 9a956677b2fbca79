"""Runs of frames and what is constant along one: anchor phase, phase step, band-limited
amplitude (spec/README.md rules R6, R9-R11).

The frames of one touch sample fall into up to two *parts*: before and past the dead-reckoning
horizon H. Along a part the dead-reckoned position, the odometer and the time since touch-down
each advance by a fixed step per frame (or the first two stand still, past H), so every
component's phase is affine in the frame index. The phase is formed in double precision at
*anchors*: a part's first frame and every :data:`ANCHOR_FRAMES` frames after it, which bound
the frames advanced from one anchor in fixed point (hcard/render/synthesis.py). A *run* is the
frames of one anchor with one texture: its band-limit gain, amplitude and channel group are
constant too. A texture change keeps the anchor (its phase inputs do not depend on the
texture). Anchors depend on the frame times and the touch samples only, not on how a stream
cuts its blocks (R12).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.render.clock import FrameClock
from hcard.render.compiled import CompiledCard
from hcard.render.frame_touch import SampleColumns, TouchFrames
from hcard.render.options import PASSBAND_FRACTION, RenderOptions
from hcard.render.touch import TouchTable

ANCHOR_FRAMES = 256
"""Most frames advanced from one anchor: a part's anchors are this many frames apart."""
FIXED_TURN = 4294967296.0
"""Units of the fixed-point phase per turn (2^32)."""


@dataclass(frozen=True)
class Runs:
    """The R runs of a block of N frames, as sequences of length R: NumPy arrays, or lists for
    a block of one touch sample and one texture (the common streaming block, where making
    arrays would cost more than the rest of its runs' bookkeeping) and for a run taken alone.

    Attributes:
        starts: first frame of each run in the block.
        lengths: frames of each run in the block.
        anchors: each run's anchor, as a frame index of the block (<= its start; the first
            run's may precede the block by up to ANCHOR_FRAMES - 1 frames).
        sample: touch sample.
        texture: palette index (-1: neutral frames).
        capped: whether dead reckoning has reached its horizon H.
        time: time of the anchor frame, s.
    """

    starts: np.ndarray | list[int]
    lengths: np.ndarray | list[int]
    anchors: np.ndarray | list[int]
    sample: np.ndarray | list[int]
    texture: np.ndarray | list[int]
    capped: np.ndarray | list[bool]
    time: np.ndarray | list[float]

    def __len__(self) -> int:
        return len(self.starts)

    def single(self, run: int) -> Runs:
        """Run ``run`` alone."""
        return Runs([self.starts[run]], [self.lengths[run]], [self.anchors[run]],
                     [self.sample[run]], [self.texture[run]], [bool(self.capped[run])],
                     [self.time[run]])


def find_runs(table: TouchTable, clock: FrameClock, first: int, frames: TouchFrames,
              horizon_s: float) -> Runs:
    """The :class:`Runs` of the block of frames ``first ..`` of ``clock``.

    A segment (one touch sample) has up to two *parts*, before and past the dead-reckoning
    horizon; a part's anchors are its first frame (which may precede the block) and every
    :data:`ANCHOR_FRAMES` frames after it; a run is the frames of one anchor with one
    texture."""
    count = frames.texture.shape[0]
    if len(frames.starts) == 1:
        row, horizon = frames.sample[0], frames.horizon[0]
        parts = _parts_of_first_segment(table, clock, first, row, horizon, count, horizon_s)
        anchors: list[int] = []
        capped: list[bool] = []
        for start, end, base, past in parts:
            anchor = base + (first + start - base) // ANCHOR_FRAMES * ANCHOR_FRAMES
            while anchor < first + end:
                anchors.append(anchor - first)
                capped.append(past)
                anchor += ANCHOR_FRAMES
        if frames.one_texture:  # the common streaming block
            run_starts = [max(a, 0) for a in anchors]
            return Runs(run_starts,
                        [b - a for a, b in zip(run_starts, [*run_starts[1:], count], strict=True)],
                        anchors, [row] * len(run_starts),
                        [frames.texture.item(0)] * len(run_starts),
                        capped, [clock.time(first + a) for a in anchors])
        anchor_at, part_capped = np.array(anchors, dtype=np.intp), np.array(capped)
        sample = np.full(len(anchors), row)
    else:
        anchor_at, part_capped, sample = _anchors_of_segments(table, clock, first, frames,
                                                              horizon_s)
    anchor_start = np.maximum(anchor_at, 0)
    starts: np.ndarray
    if frames.one_texture:
        starts, which = anchor_start, np.arange(anchor_at.shape[0])
    else:
        texture = frames.texture
        new = np.empty(count, dtype=bool)
        new[0] = True
        np.not_equal(texture[1:], texture[:-1], out=new[1:])
        new[anchor_start] = True
        starts = np.flatnonzero(new)
        which = anchor_start.searchsorted(starts, side="right") - 1  # each run's anchor
    lengths = np.empty_like(starts)
    np.subtract(starts[1:], starts[:-1], out=lengths[:-1])
    lengths[-1] = count - starts[-1]
    run_anchors = anchor_at.take(which)
    return Runs(starts, lengths, run_anchors, sample.take(which), frames.texture.take(starts),
                part_capped.take(which), clock.times_of(run_anchors + first))


def _parts_of_first_segment(table: TouchTable, clock: FrameClock, first: int, row: int,
                            horizon: int, end: int, horizon_s: float
                            ) -> list[tuple[int, int, int, bool]]:
    """``(start, end, base, past the horizon)`` of the parts of the block's first segment:
    block frames ``start .. end - 1`` whose anchors are frame ``base`` of the clock and every
    ANCHOR_FRAMES frames after it."""
    if row < 0:  # before the first sample: neutral frames, any anchor will do
        return [(0, end, first, False)]
    sample_t = table.t.item(row)
    parts = []
    if horizon > 0:
        parts.append((0, min(horizon, end), clock.first_at_or_after(sample_t), False))
    if horizon < end:
        base = first + horizon if horizon > 0 else clock.first_past(sample_t, horizon_s)
        parts.append((horizon, end, base, True))
    return parts


def _anchors_of_segments(table: TouchTable, clock: FrameClock, first: int,
                         frames: TouchFrames, horizon_s: float
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every anchor of a block of several segments (block frame index, ascending), whether it
    is past the horizon, and its touch sample."""
    starts, horizon = frames.starts, frames.horizon
    count = frames.texture.shape[0]
    ends = np.empty_like(starts)
    ends[:-1] = starts[1:]
    ends[-1] = count
    parts = _parts_of_first_segment(table, clock, first, frames.sample[0], horizon[0],
                                    ends[0], horizon_s)
    rest = slice(1, None)  # the other segments start in the block
    before = np.greater(horizon[rest], starts[rest])
    past = np.less(horizon[rest], ends[rest])
    part_start = np.concatenate(([p[0] for p in parts], starts[rest][before],
                                 horizon[rest][past]))
    part_end = np.concatenate(([p[1] for p in parts], np.minimum(horizon, ends)[rest][before],
                               ends[rest][past]))
    part_base = np.concatenate(([p[2] - first for p in parts], starts[rest][before],
                                horizon[rest][past]))  # block frame index
    part_capped = np.concatenate(([p[3] for p in parts], np.zeros(before.sum(), dtype=bool),
                                  np.ones(past.sum(), dtype=bool)))
    segment = np.concatenate((np.zeros(len(parts), dtype=np.intp),
                              np.flatnonzero(before) + 1, np.flatnonzero(past) + 1))
    order = np.argsort(part_start, kind="stable")
    part_start, part_end, part_base, part_capped, segment = (
        a.take(order) for a in (part_start, part_end, part_base, part_capped, segment))
    anchor = part_base + (part_start - part_base) // ANCHOR_FRAMES * ANCHOR_FRAMES
    per_part = (part_end - anchor + ANCHOR_FRAMES - 1) // ANCHOR_FRAMES
    part = np.repeat(np.arange(part_start.shape[0]), per_part)
    nth = np.arange(part.shape[0]) - np.repeat(np.cumsum(per_part) - per_part, per_part)
    return (anchor.take(part) + nth * ANCHOR_FRAMES, part_capped.take(part),
            np.take(frames.sample, segment.take(part)))


@dataclass(frozen=True)
class RunParameters:
    """What is constant along each of R runs, for C components and G channel groups.

    Attributes:
        anchor: (C, R) phase at the anchor, fixed-point turns (uint32, 2^-32 turn).
        step: (C, R) phase step per frame, fixed-point turns.
        weights: (G, C, R) band-limited amplitude in each channel group (float32).
        baseline: (G, R) baseline - 1 in each channel group.
        phase: (R, C) unwrapped phase at the anchor, turns.
        rate: (R, C) phase rate, turns per second.
    """

    anchor: np.ndarray
    step: np.ndarray
    weights: np.ndarray
    baseline: np.ndarray
    phase: np.ndarray
    rate: np.ndarray


def run_parameters(card: CompiledCard, table: TouchTable, columns: SampleColumns, runs: Runs,
                   options: RenderOptions) -> RunParameters:
    """The :class:`RunParameters` of ``runs`` (arrays or lists): R6 and R9 in double precision
    at each anchor, R10 and R11's gain, amplitude and channel group per run."""
    palette = card.palette
    i = np.maximum(runs.sample, 0)
    texture = runs.texture
    phase_weights = palette.phase_weights.take(texture, axis=0)  # (R, 6, C)
    rate = columns.rate.take(i, axis=0)
    reckon = np.minimum(runs.time - table.t.take(i), options.dead_reckoning_s)
    inputs = columns.start.take(i, axis=0)
    inputs += rate * reckon[:, None]
    inputs[:, 4] += runs.time
    rate[:, 4] = 1.0
    turns = np.empty((2, *phase_weights[:, 0].shape))  # at the anchor, turns; then per second
    np.einsum("rk,rkc->rc", inputs, phase_weights, out=turns[0])
    np.einsum("rk,rkc->rc", rate, phase_weights, out=turns[1])
    # R10's F_c: k |n . v| of a spatial component (its phase moves with the velocity, position-
    # and velocity-locked alike), f of a temporal one: the phase rate before the horizon, taken
    # with the sample's velocity also past it (in position-only mode spatial components have
    # no band limit, so their rate of zero is not used)
    frequency = np.abs(turns[1])
    if np.any(runs.capped):  # past the horizon only the time since touch-down advances
        rate[runs.capped, :4] = 0.0
        np.einsum("rk,rkc->rc", rate, phase_weights, out=turns[1])
    weights = palette.group_amplitude.take(texture, axis=0)  # (R, G, C)
    if frequency.max(initial=0.0) > PASSBAND_FRACTION * options.band_limit_hz:
        gain = band_limit_gain(frequency, options.band_limit_hz)
        gain[~palette.band_limited.take(texture, axis=0)] = 1.0
        weights *= gain[:, None, :]
    # (below 0.8 B every gain is exactly 1: the numbers of multiplying by it)
    per_frame = turns.copy()  # at the anchor, turns; then per frame
    per_frame[1] /= options.frame_rate_hz
    fixed = fixed_turns(per_frame)
    return RunParameters(
        anchor=fixed[0].T,
        step=fixed[1].T,
        weights=weights.transpose(1, 2, 0).astype(np.float32),
        baseline=palette.baseline.take(texture, axis=0).T,
        phase=turns[0],
        rate=turns[1],
    )


def band_limit_gain(frequency_hz: np.ndarray, band_limit_hz: float) -> np.ndarray:
    """Gain of a component at ``frequency_hz``: 1 below 0.8 B, 0 from B on, smoothstep between
    (R10)."""
    edge = PASSBAND_FRACTION * band_limit_hz
    x = np.subtract(frequency_hz, edge)
    x /= band_limit_hz - edge
    np.clip(x, 0.0, 1.0, out=x)
    slope = np.multiply(x, -2.0)
    slope += 3.0
    x *= x
    x *= slope
    return np.subtract(1.0, x, out=x)  # 1 - x^2 (3 - 2x), in place


def fixed_turns(turns: np.ndarray) -> np.ndarray:
    """``turns`` modulo one turn as unsigned 32-bit fixed point (2^-32 turn, rounded): the
    fractional part ``turns - trunc(turns)`` (exact in floating point: ``np.modf``'s numbers,
    at a tenth of its cost) in units of 2^-32, wrapped to [0, 2^32). A phase that is not a
    finite number (a track whose velocity overflows) gives zero."""
    fraction = np.trunc(turns)
    with np.errstate(invalid="ignore"):  # an infinity minus itself: a NaN, as intended
        np.subtract(turns, fraction, out=fraction)  # in (-1, 1), the sign of ``turns``
    np.fmax(fraction, -1.0, out=fraction)  # a NaN becomes -1 turn, which wraps to 0
    fraction *= FIXED_TURN
    np.rint(fraction, out=fraction)
    return fraction.astype(np.int64).astype(np.uint32)  # two's complement: modulo 2^32
