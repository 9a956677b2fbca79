"""Held-out splits of a measurement by stroke or by time block, never by random sample.

Neighbouring samples of one stroke are strongly correlated (same finger state, same moisture,
same contact area), so a random-sample split leaks the training data into the test set and
under-states the held-out error. These splits keep whole strokes, or whole contiguous time
blocks, on one side (spec/measurement-format.md section 4).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hcard.calibration.measurement import CONTACT_THRESHOLD_N, Measurement, MeasurementError

SPLITS = ("stroke", "time")
"""Held-out split kinds: whole strokes, or the last time block of each recording."""

#: A new stroke starts after a time gap longer than this many median sample intervals.
GAP_FACTOR = 5.0


def stroke_ids(
    m: Measurement,
    *,
    gap_factor: float = GAP_FACTOR,
    contact_threshold_n: float = CONTACT_THRESHOLD_N,
) -> np.ndarray:
    """The stroke number of every sample, shape (M,), int; -1 marks samples out of contact.

    With a ``stroke`` column its values are kept where the finger touches by the forces
    (``normal_force >= contact_threshold_n`` and the ``contact`` column) and are -1 elsewhere:
    a column that carries the stroke number through the lifts does not put samples with
    ``fn ~ 0`` in contact (:mod:`hcard.calibration.contact` reports the disagreement). Without
    one, strokes are derived (rule MS2): a sample is out of contact when
    ``normal_force < contact_threshold_n`` (N) or, with a ``contact`` column, where that column
    is 0, and gets -1; a new stroke starts at the first
    contact sample after a lift, after a time gap longer than ``gap_factor`` times the median
    sample interval (s), and, when a ``speed`` column exists, where the sign of the speed
    changes (a back-and-forth stroke reverses; zero speeds carry the previous sign). Strokes
    are numbered 0, 1, 2, ... in time order.
    """
    contact = m.normal_force >= contact_threshold_n
    if m.contact is not None:
        contact &= m.contact
    if m.stroke is not None:
        return np.where(contact, np.asarray(m.stroke, dtype=np.int64), -1).astype(np.int64)
    return stroke_numbers(m.t, contact, m.speed, gap_factor=gap_factor)


def stroke_numbers(
    t: np.ndarray,
    contact: np.ndarray,
    speed: np.ndarray | None = None,
    *,
    gap_factor: float = GAP_FACTOR,
) -> np.ndarray:
    """Rule MS2 on arrays: the stroke number of every sample, -1 where ``contact`` is False.

    A new stroke starts at the first sample, at the first contact sample after a lift, after a
    time gap (``t``, s) longer than ``gap_factor`` times the median interval, and where the sign
    of ``speed`` changes (zero speeds carry the previous sign). Numbered 0, 1, 2, ... in time
    order."""
    n = t.shape[0]
    start = np.zeros(n, dtype=bool)
    if n:
        start[0] = True
    if n > 1:
        dt = np.diff(t)
        start[1:] |= dt > gap_factor * float(np.median(dt))
        start[1:] |= contact[1:] & ~contact[:-1]
    if speed is not None and n > 1:
        sign = np.sign(speed)
        # Zero speeds carry the previous non-zero sign (forward fill).
        last = np.maximum.accumulate(np.where(sign != 0, np.arange(n), 0))
        sign = sign[last]
        start[1:] |= (sign[1:] * sign[:-1]) < 0
    # Every counted start is a contact sample, so the numbering is dense: 0, 1, 2, ...
    ids = np.cumsum(start & contact) - 1
    return np.where(contact, ids, -1).astype(np.int64)


def split_by_stroke(
    m: Measurement,
    test_fraction: float = 0.25,
    seed: int = 0,
    contact_threshold_n: float = CONTACT_THRESHOLD_N,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)`` holding out whole strokes.

    ``round(test_fraction * K)`` of the K strokes (at least 1, at most K-1) are drawn without
    replacement by ``numpy.random.default_rng(seed)``; every sample of a drawn stroke is in the
    test set, every sample of the others in the training set. Samples with stroke -1 (out of
    contact, normal force below ``contact_threshold_n``, N) are in neither. Indices are sorted
    ascending. Raises :class:`MeasurementError` with
    fewer than two strokes or a fraction outside (0, 1).
    """
    if not 0.0 < test_fraction < 1.0:
        raise MeasurementError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    ids = stroke_ids(m, contact_threshold_n=contact_threshold_n)
    strokes = np.unique(ids[ids >= 0])
    if strokes.size < 2:
        raise MeasurementError(
            f"a split by stroke needs at least 2 strokes, the recording has {strokes.size}"
        )
    n_test = min(max(1, round(test_fraction * strokes.size)), strokes.size - 1)
    rng = np.random.default_rng(seed)
    test_strokes = rng.choice(strokes, size=n_test, replace=False)
    in_test = np.isin(ids, test_strokes)
    train = np.flatnonzero(~in_test & (ids >= 0))
    test = np.flatnonzero(in_test)
    return train, test


def split_by_time_blocks(
    m: Measurement, n_blocks: int = 5, test_blocks: Sequence[int] = (4,)
) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)`` from contiguous blocks of equal duration.

    The span ``[t[0], t[-1]]`` (s) is cut into ``n_blocks`` blocks of equal duration; sample i
    belongs to block ``min(floor((t_i - t_0) / T * n_blocks), n_blocks - 1)``. Blocks listed in
    ``test_blocks`` (0-based, negative counts from the end) form the test set, the rest the
    training set. Each block is one contiguous run of indices. Raises
    :class:`MeasurementError` for a bad block number, when all or no blocks are test blocks,
    or when a block holds no sample.
    """
    if n_blocks < 2:
        raise MeasurementError(f"n_blocks must be at least 2, got {n_blocks}")
    chosen = set()
    for k in test_blocks:
        if not -n_blocks <= k < n_blocks:
            raise MeasurementError(f"test block {k} is outside 0..{n_blocks - 1}")
        chosen.add(k % n_blocks)
    if not chosen or len(chosen) == n_blocks:
        raise MeasurementError("test_blocks must name at least one block and not all of them")
    block = time_blocks(m, n_blocks)
    counts = np.bincount(block, minlength=n_blocks)
    if np.any(counts == 0):
        empty = int(np.flatnonzero(counts == 0)[0])
        raise MeasurementError(f"time block {empty} of {n_blocks} holds no sample")
    in_test = np.isin(block, sorted(chosen))
    return np.flatnonzero(~in_test), np.flatnonzero(in_test)


def time_blocks(m: Measurement, n_blocks: int) -> np.ndarray:
    """The block number (0..n_blocks-1) of every sample, for blocks of equal duration."""
    span = float(m.t[-1] - m.t[0]) if len(m) else 0.0
    if span <= 0.0:
        return np.zeros(len(m), dtype=np.int64)
    block = np.floor((m.t - m.t[0]) / span * n_blocks).astype(np.int64)
    return np.minimum(block, n_blocks - 1)
