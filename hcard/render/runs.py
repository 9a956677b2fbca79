"""Runs of frames and what is constant along one: anchor phase, phase step, band-limited
amplitude (spec/README.md rules R6, R9-R11).

A *run* is a stretch of consecutive frames with one touch sample, one texture, one side of the
dead-reckoning horizon H, within one stretch of :data:`ANCHOR_FRAMES` of the frame grid. Along
a run the dead-reckoned position, the odometer and the time since touch-down each advance by a
fixed step per frame (or the first two stand still, past H), so every component's phase is
affine in the frame index, and its band-limit gain, amplitude and channel group are constant.
The phase is formed in double precision at the run's *anchor*: the first frame of the stretch
with the same sample, side of H and grid stretch (a texture change within it keeps the anchor,
whose phase inputs do not depend on the texture). Anchors depend on the frame grid and the touch
samples only, not on how a stream cuts its blocks (R12).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.render.compiled import CompiledCard
from hcard.render.frame_touch import SampleColumns, TouchFrames, first_past_horizon
from hcard.render.options import PASSBAND_FRACTION, RenderOptions
from hcard.render.touch import TouchTable

ANCHOR_FRAMES = 256
"""Longest run of frames advanced from one anchor; every multiple of it in the frame grid
starts a new run."""
FIXED_TURN = 4294967296.0
"""Units of the fixed-point phase per turn (2^32)."""


@dataclass(frozen=True)
class Runs:
    """The R runs of a block of N frames, as sequences of length R: NumPy arrays, or lists for
    a block of one touch sample and one texture (the common streaming block, where making
    arrays would cost more than the rest of its runs' bookkeeping).

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


def find_runs(table: TouchTable, times: np.ndarray, lead: int, frames: TouchFrames,
              horizon_s: float) -> Runs:
    """The :class:`Runs` of a block.

    Args:
        table: the touch samples.
        times: times of the ``lead`` frames before the block (back to the anchor grid) and of
            the block's frames, s.
        lead: frames in ``times`` before the block.
        frames: the block's :class:`TouchFrames`.
        horizon_s: dead-reckoning horizon H, s.
    """
    count = times.shape[0] - lead
    grid = range((ANCHOR_FRAMES - lead) % ANCHOR_FRAMES or ANCHOR_FRAMES, count, ANCHOR_FRAMES)
    first = _first_anchor(table, times, lead, frames, horizon_s)
    if len(frames.starts) == 1:
        horizon = frames.horizon[0]
        anchors = sorted({first, *grid, *([horizon] if 0 < horizon < count else [])})
        if frames.one_texture:  # the common streaming block
            starts = [max(a, 0) for a in anchors]
            return Runs(starts, [b - a for a, b in zip(starts, [*starts[1:], count], strict=True)],
                        anchors, frames.sample * len(starts),
                        [frames.texture.item(0)] * len(starts), [s >= horizon for s in starts],
                        [times.item(a + lead) for a in anchors])
        anchor_at = np.array(anchors, dtype=np.intp)
    else:  # the segments' starts, the horizon within each, the grid
        segment_starts, horizon = frames.starts, frames.horizon
        within = horizon > segment_starts
        within[:-1] &= horizon[:-1] < segment_starts[1:]
        within[-1] &= horizon[-1] < count
        anchor_at = np.unique(np.concatenate(
            ([first], segment_starts[1:], horizon[within], np.arange(grid.start, count,
                                                                      ANCHOR_FRAMES))))
    if frames.one_texture:
        starts = np.maximum(anchor_at, 0)
        anchors = anchor_at
    else:
        texture = frames.texture
        new = np.empty(count, dtype=bool)
        new[0] = True
        np.not_equal(texture[1:], texture[:-1], out=new[1:])
        new[anchor_at[1:]] = True
        starts = np.flatnonzero(new)
        anchors = anchor_at[anchor_at.searchsorted(starts, side="right") - 1]
    lengths = np.empty_like(starts)
    np.subtract(starts[1:], starts[:-1], out=lengths[:-1])
    lengths[-1] = count - starts[-1]
    segment = np.searchsorted(frames.starts, starts, side="right") - 1
    return Runs(starts, lengths, anchors, np.take(frames.sample, segment),
                frames.texture.take(starts), starts >= np.take(frames.horizon, segment),
                times.take(anchors + lead))


def _first_anchor(table: TouchTable, times: np.ndarray, lead: int, frames: TouchFrames,
                  horizon_s: float) -> int:
    """The anchor of the block's first frame: the latest of the grid point, the first frame of
    its touch sample and, past the horizon, the first frame past it (frame index, <= 0)."""
    row = int(frames.sample[0])
    if not lead or row < 0:
        return -lead
    before = times[:lead]
    sample_t = table.t.item(row)
    anchor = int(before.searchsorted(sample_t))
    if frames.horizon[0] == 0:  # the first frame is past the horizon
        anchor = max(anchor, first_past_horizon(before, sample_t, horizon_s))
    return anchor - lead


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
    """The :class:`RunParameters` of ``runs``: R6 and R9 in double precision at each anchor,
    R10 and R11's gain, amplitude and channel group per run."""
    palette = card.palette
    i = np.maximum(runs.sample, 0)
    texture = runs.texture
    phase_weights = palette.phase_weights.take(texture, axis=0)  # (R, 6, C)
    rate = columns.rate.take(i, axis=0)
    reckon = np.minimum(runs.time - table.t.take(i), options.dead_reckoning_s)
    inputs = columns.start.take(i, axis=0)
    inputs += rate * reckon[:, None]
    inputs[:, 4] += runs.time
    # the velocity for the band limit: the sample's, also past the horizon (R10)
    frequency = np.einsum("rk,rkc->rc", rate[:, 2:4], palette.wave_vectors.take(texture, axis=0))
    rate[runs.capped, :4] = 0.0  # past the horizon only the time since touch-down advances
    rate[:, 4] = 1.0
    phase = np.einsum("rk,rkc->rc", inputs, phase_weights)
    turns_per_s = np.einsum("rk,rkc->rc", rate, phase_weights)
    np.abs(frequency, out=frequency)
    frequency += palette.temporal_hz.take(texture, axis=0)
    gain = band_limit_gain(frequency, options.band_limit_hz)
    gain[~palette.band_limited.take(texture, axis=0)] = 1.0
    weights = palette.group_amplitude.take(texture, axis=0)  # (R, G, C)
    weights *= gain[:, None, :]
    return RunParameters(
        anchor=fixed_turns(phase).T,
        step=fixed_turns(turns_per_s / options.frame_rate_hz).T,
        weights=weights.transpose(1, 2, 0).astype(np.float32),
        baseline=palette.baseline.take(texture, axis=0).T,
        phase=phase,
        rate=turns_per_s,
    )


def band_limit_gain(frequency_hz: np.ndarray, band_limit_hz: float) -> np.ndarray:
    """Gain of a component at ``frequency_hz``: 1 below 0.8 B, 0 from B on, smoothstep between
    (R10)."""
    edge = PASSBAND_FRACTION * band_limit_hz
    x = np.subtract(frequency_hz, edge)
    x /= band_limit_hz - edge
    np.maximum(x, 0.0, out=x)
    np.minimum(x, 1.0, out=x)
    return 1.0 - x * x * (3.0 - 2.0 * x)


def fixed_turns(turns: np.ndarray) -> np.ndarray:
    """``turns`` modulo one turn as unsigned 32-bit fixed point (2^-32 turn, rounded); zero
    for a phase that is not a finite number (a track whose velocity overflows)."""
    finite = np.isfinite(turns)
    if not finite.all():
        turns = np.where(finite, turns, 0.0)
    fraction = turns - np.floor(turns)
    fraction *= FIXED_TURN
    np.rint(fraction, out=fraction)
    return fraction.astype(np.int64).astype(np.uint32)  # 2^32 (a fraction of 1 - ulp) wraps to 0
