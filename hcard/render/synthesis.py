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

from hcard.render.compiled import GROUP_BIPOLAR, GROUP_EV, GROUP_UV
from hcard.render.runs import ANCHOR_FRAMES, FIXED_TURN

MAX_RELATIVE_FRICTION = 4.0
SYNTHESIS_FRAMES = 32 * ANCHOR_FRAMES
"""Frames synthesised per pass (the (components, frames) arrays stay in the core's cache)."""
FIXED_TO_RADIANS = np.float32(2.0 * math.pi / FIXED_TURN)


def synthesise(
    anchor: np.ndarray,
    step: np.ndarray,
    weights: np.ndarray,
    lengths: np.ndarray | None,
    offset: np.ndarray,
) -> np.ndarray:
    """Sum over components of ``weight * cos(phase)`` per channel group and frame.

    Args:
        anchor: (C, R) phase of each component at each run's anchor, fixed-point turns.
        step: (C, R) its change per frame, fixed-point turns.
        weights: (G, C, R) amplitude of each component per channel group and run.
        lengths: (R,) frames of each run; None for one run (R = 1).
        offset: (N,) uint32 frames from each frame's anchor (< ANCHOR_FRAMES).

    Returns:
        (G, N) float32 sums.
    """
    groups, components, _ = weights.shape
    n = offset.shape[0]
    deviation = np.zeros((groups, n), dtype=np.float32)
    if components == 0:
        return deviation
    if lengths is None or n <= SYNTHESIS_FRAMES:
        _pass(anchor, step, weights, lengths, offset, deviation)
        return deviation
    ends = np.cumsum(lengths)
    done, run = 0, 0
    while done < n:  # passes of at most SYNTHESIS_FRAMES frames, cut between runs
        last = max(int(ends.searchsorted(done + SYNTHESIS_FRAMES, side="right")), run + 1)
        end = int(ends[last - 1])
        _pass(anchor[:, run:last], step[:, run:last], weights[:, :, run:last],
              lengths[run:last], offset[done:end], deviation[:, done:end])
        done, run = end, last
    return deviation


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


def split_channels(deviation: np.ndarray, columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """UV and EV targets from the (G, N) group deviations (spec rule R11; thesis Eq. 4.1).

    ``1 + deviation`` is never -0.0, so clipping with ``maximum`` then ``minimum`` gives
    ``np.clip``'s numbers; a channel without its own group starts from exactly 1, and
    ``1 * x = x``, so the bipolar group alone sets it."""

    def group(g: int) -> np.ndarray | None:
        return 1.0 + deviation[columns.index(g)] if g in columns else None

    uv_group, ev_group, bipolar = group(GROUP_UV), group(GROUP_EV), group(GROUP_BIPOLAR)
    if uv_group is not None:
        uv_group = np.minimum(np.maximum(uv_group, 0.0, out=uv_group), 1.0, out=uv_group)
    if ev_group is not None:
        ev_group = np.minimum(np.maximum(ev_group, 1.0, out=ev_group), MAX_RELATIVE_FRICTION,
                              out=ev_group)
    if bipolar is None:
        ones = np.ones(deviation.shape[1])
        return (ones.copy() if uv_group is None else uv_group,
                ones if ev_group is None else ev_group)
    np.maximum(bipolar, 0.0, out=bipolar)
    np.minimum(bipolar, MAX_RELATIVE_FRICTION, out=bipolar)
    lowering, raising = np.minimum(bipolar, 1.0), np.maximum(bipolar, 1.0)
    if uv_group is None:
        uv = lowering
    else:
        uv = uv_group
        uv *= lowering
    if ev_group is None:
        ev = raising  # at most MAX_RELATIVE_FRICTION already
    else:
        ev = ev_group
        ev *= raising
        np.minimum(ev, MAX_RELATIVE_FRICTION, out=ev)
    return uv, ev
