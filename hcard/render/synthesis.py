"""The sum of components' cosines per channel group, and the split into the UV and EV channels
(spec/README.md rules R9-R11, R13).

A component's phase along a run is advanced from its anchor in 32-bit fixed-point turns
(units of 2^-32 turn): unsigned integer arithmetic is exact and its wrap-around is the
reduction to one turn, so the per-frame work needs no floor and no double precision. The
reduced phase is converted to single precision and its cosine evaluated there (R13).

Error of one component: the anchor phase and the per-frame step are each rounded to 2^-33 turn
(:func:`hcard.render.runs.fixed_turns`), so a frame k < ANCHOR_FRAMES frames after its anchor
is off by at most (k + 1) 2^-33 < 3.0e-8 turn; the conversion to single precision adds at most
2^-26 (1.5e-8) turn, the scaling to radians 3.3e-8 turn (the rounded constant and the product):
below 4.9e-7 rad in all. With the single-precision cosine, amplitude and product (6e-8 each)
this is below 7e-7 relative friction per unit of amplitude, plus the single-precision sum over
the components.
"""

from __future__ import annotations

import math

import numpy as np

from hcard.channels import GROUP_BIPOLAR, GROUP_EV, GROUP_UV
from hcard.render.runs import ANCHOR_FRAMES, FIXED_TURN

MAX_RELATIVE_FRICTION = 4.0
SYNTHESIS_FRAMES = 32 * ANCHOR_FRAMES
"""Frames synthesised per pass (the (components, frames) arrays stay in the core's cache)."""
FIXED_TO_RADIANS = np.float32(2.0 * math.pi / FIXED_TURN)


def frame_targets(
    anchor: np.ndarray,
    step: np.ndarray,
    weights: np.ndarray,
    baseline: np.ndarray,
    lengths: np.ndarray | None,
    offset: np.ndarray,
    columns: list[int],
    uv: np.ndarray,
    ev: np.ndarray,
) -> None:
    """UV and EV targets of frames along runs (R9-R11), written into ``uv`` and ``ev``.

    Args:
        anchor: (C, R) phase of each component at each run's anchor, fixed-point turns.
        step: (C, R) its change per frame, fixed-point turns.
        weights: (G, C, R) amplitude of each component per channel group and run.
        baseline: (G, R) baseline - 1 per channel group and run.
        lengths: (R,) frames of each run; None for one run (R = 1).
        offset: (N,) uint32 frames from each frame's anchor (< ANCHOR_FRAMES).
        columns: the channel group of each of the G rows (:func:`split_channels`).
        uv, ev: (N,) float64 outputs.

    Frames go in passes of at most SYNTHESIS_FRAMES, cut between runs: every array of a pass
    stays in the core's cache, and the memory a pass takes is reused by the next.
    """
    n = offset.shape[0]
    if lengths is None or n <= SYNTHESIS_FRAMES:
        _targets_of_pass(anchor, step, weights, baseline, lengths, offset, columns, uv, ev)
        return
    ends = np.cumsum(lengths)
    done, run = 0, 0
    while done < n:
        last = max(int(ends.searchsorted(done + SYNTHESIS_FRAMES, side="right")), run + 1)
        end = int(ends[last - 1])
        _targets_of_pass(anchor[:, run:last], step[:, run:last], weights[:, :, run:last],
                         baseline[:, run:last], lengths[run:last], offset[done:end], columns,
                         uv[done:end], ev[done:end])
        done, run = end, last


def _targets_of_pass(anchor: np.ndarray, step: np.ndarray, weights: np.ndarray,
                     baseline: np.ndarray, lengths: np.ndarray | None, offset: np.ndarray,
                     columns: list[int], uv: np.ndarray, ev: np.ndarray) -> None:
    """:func:`frame_targets` of one pass: the components' sum per group in single precision,
    plus the baseline in double precision, split into the channels."""
    groups, components, _ = weights.shape
    deviation = np.zeros((groups, offset.shape[0]), dtype=np.float32)
    if components:
        _pass(anchor, step, weights, lengths, offset, deviation)
    total = deviation.astype(np.float64)
    total += baseline if lengths is None else np.repeat(baseline, lengths, axis=1)
    split_channels(total, columns, uv, ev)


def _pass(anchor: np.ndarray, step: np.ndarray, weights: np.ndarray,
          lengths: np.ndarray | None, offset: np.ndarray, out: np.ndarray) -> None:
    """:func:`synthesise` of consecutive runs into ``out`` (G, their frames); one run's
    columns broadcast instead of repeating (the same numbers)."""
    if lengths is None:
        fixed = np.multiply(step, offset)
        fixed += anchor  # wraps: modulo one turn
    else:
        fixed = np.repeat(step, lengths, axis=1)
        fixed *= offset
        fixed += np.repeat(anchor, lengths, axis=1)
    wave = fixed.view(np.int32).astype(np.float32)  # [-1/2, 1/2) turn
    wave *= FIXED_TO_RADIANS
    np.cos(wave, out=wave)
    for g in range(weights.shape[0]):
        if lengths is None:
            term = np.multiply(weights[g], wave)
        else:
            term = np.repeat(weights[g], lengths, axis=1)
            term *= wave
        out[g] = _sum_rows(term)


def _sum_rows(terms: np.ndarray) -> np.ndarray:
    """Sum of the rows of ``terms`` (which it overwrites), added in pairs in an order that
    depends on the number of rows only: a frame's sum is the same in a block of any length, so
    streaming gives the batch numbers (R12; ``np.add.reduce`` changes its order for one
    column)."""
    rows = terms.shape[0]
    while rows > 1:
        half = rows // 2
        terms[:half] += terms[rows - half:rows]
        rows -= half
    return terms[0]


def channel_targets(deviation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UV and EV targets ``(u, e)`` of group deviations, spec rule R11: ``deviation`` holds
    ``D_UV, D_EV, D_BI`` (the sums of the group's components plus ``baseline - 1`` of the
    texture's group), shape (3,) or (3, N); ``u`` and ``e`` have shape (N,) (1 for (3,)).

    The renderer's own split (:func:`split_channels`), for callers outside the kernel (the
    device's clip report evaluates a texture's extremes with it)."""
    rows = np.array(deviation, dtype=np.float64).reshape(3, -1)  # a copy: the split overwrites
    uv = np.empty(rows.shape[1])
    ev = np.empty(rows.shape[1])
    split_channels(rows, [GROUP_UV, GROUP_EV, GROUP_BIPOLAR], uv, ev)
    return uv, ev


def split_channels(deviation: np.ndarray, columns: list[int], uv: np.ndarray,
                   ev: np.ndarray) -> None:
    """UV and EV targets from the (G, N) group deviations (which this overwrites), written
    into ``uv`` and ``ev`` (spec rule R11; thesis Eq. 4.1).

    ``1 + deviation`` is never -0.0 or a NaN, so ``np.clip`` gives the numbers of ``maximum``
    then ``minimum``; a channel without its own group starts from exactly 1, and ``1 * x =
    x``, so the bipolar group alone sets it."""
    np.add(deviation, 1.0, out=deviation)

    def group(g: int, low: float, high: float, out: np.ndarray | None = None
              ) -> np.ndarray | None:
        if g not in columns:
            return None
        row = deviation[columns.index(g)]
        return np.clip(row, low, high, out=row if out is None else out)

    if GROUP_BIPOLAR not in columns:
        if group(GROUP_UV, 0.0, 1.0, uv) is None:
            uv.fill(1.0)
        if group(GROUP_EV, 1.0, MAX_RELATIVE_FRICTION, ev) is None:
            ev.fill(1.0)
        return
    uv_group = group(GROUP_UV, 0.0, 1.0)
    ev_group = group(GROUP_EV, 1.0, MAX_RELATIVE_FRICTION)
    bipolar = group(GROUP_BIPOLAR, 0.0, MAX_RELATIVE_FRICTION)
    assert bipolar is not None  # GROUP_BIPOLAR is in columns (above)
    np.minimum(bipolar, 1.0, out=uv)  # the bipolar group's lowering
    if uv_group is not None:
        uv *= uv_group
    np.maximum(bipolar, 1.0, out=ev)  # and raising, at most MAX_RELATIVE_FRICTION already
    if ev_group is not None:
        ev *= ev_group
        np.minimum(ev, MAX_RELATIVE_FRICTION, out=ev)
