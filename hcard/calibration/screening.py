"""Screening the loop's candidate models on a decimated training split.

Each candidate of the calibration loop (:mod:`hcard.calibration.loop`) is first fitted on every
``k``-th training sample in time order (:func:`screening_mask`), about :data:`SCREEN_SAMPLES`
of them, with the held-out error computed on every held-out sample as usual. A screened fit
costs a fraction of a full one (about a third at one sample in 8: a model evaluation has costs
that do not shrink with the samples); most candidates of a round are effects the data do not
hold, and their screened figures lie far from every threshold of the criterion. A candidate
whose screened figures come within :data:`SCREEN_TOLERANCE` of a threshold, or of a rival it
must be ranked against, is fitted again on every training sample, from the same start as
without screening, before the loop decides anything on it: the effects chosen, the verdict and
the fitted parameters of every accepted model are those of full fits. A model with memory (a
filter over time) is evaluated on every sample whatever its training split, so screening it
would save little; such candidates are fitted on every training sample at once.

A screened fit generalises a little worse than a full one, and so does its start model's:
the loop reads a screened candidate's held-out RMSE multiplied by its start model's full over
screened RMSE (the start refitted on the same samples), which takes that common part out (a
model with a 7.7 ms high-pass fitted on one sample in 8 read 4 % high without it). The
tolerance is the largest relative difference between that estimate
and the full fit's held-out RMSE that the loop allows for, with a margin; it is measured over
the independent recordings of tests/helpers/independent_recordings.py by
bench/bench_calibration_screening.py.
"""

from __future__ import annotations

import math

import numpy as np

SCREEN_SAMPLES = 4000
"""Training samples a candidate is screened on, about (the stride is the smallest that keeps
at most this many)."""

MIN_STRIDE = 4
"""Smallest stride worth screening with; a training split that a smaller one would thin to
:data:`SCREEN_SAMPLES` (fewer than 16000 samples) is not screened. A model evaluation costs
about 0.2 ms whatever the sample count (0.3 ms at 4000 samples, 0.5 ms at 12000), so a fit
screened at stride 3 costs over half a full one, and the full fits of the candidates near a
decision took the rest: over the independent recordings (12000 training samples), loops
screened at stride 3 ran 0.8-1.4 times as fast as without screening."""

SCREEN_TOLERANCE = 0.03
"""Relative held-out RMSE by which a screened fit's estimate may differ from the full fit of
the same model; a screened figure decides nothing that a difference of this size could
change."""


def screening_stride(n_train: int, samples: int) -> int:
    """The stride ``k`` that keeps at most ``samples`` of ``n_train`` training samples; 1 (no
    screening) for ``samples <= 0`` or when ``k`` would be below :data:`MIN_STRIDE`."""
    if samples <= 0:
        return 1
    stride = math.ceil(n_train / samples)
    return stride if stride >= MIN_STRIDE else 1


def screening_mask(train: np.ndarray, samples: int) -> np.ndarray | None:
    """Every ``k``-th training sample of the boolean mask ``train`` (in sample order, so every
    stroke keeps samples along its length), ``k`` from :func:`screening_stride`; None when
    ``k`` is 1 (not screened: fit on the whole training split)."""
    index = np.flatnonzero(train)
    stride = screening_stride(index.size, samples)
    if stride == 1:
        return None
    mask = np.zeros_like(train, dtype=bool)
    mask[index[::stride]] = True
    return mask


def may_fall_to(screened_rmse: float, target_rmse: float) -> bool:
    """Whether a model whose screened held-out RMSE is ``screened_rmse`` may reach
    ``target_rmse`` or less when fitted on every training sample."""
    return screened_rmse * (1.0 - SCREEN_TOLERANCE) <= target_rmse


def criterion_band(n_eff: float) -> float:
    """How far the held-out criterion ``H = n_eff ln(MSE) + 2k`` of a screened fit may lie
    from that of the full fit: the MSE within ``(1 +- SCREEN_TOLERANCE)^2``."""
    return 2.0 * n_eff * -math.log1p(-SCREEN_TOLERANCE)


def describe_screening(n_train: int, samples: int) -> str:
    """How the candidates of a loop on ``n_train`` training samples were screened, in one
    sentence for the report (empty when they were not)."""
    stride = screening_stride(n_train, samples)
    if stride == 1:
        return ""
    kept = -(-n_train // stride)
    return (
        f"Screening: each candidate was first fitted on one training sample in {stride} "
        f"({kept} of {n_train}); one whose screened held-out RMSE came within "
        f"{SCREEN_TOLERANCE:.0%} of a threshold or of a rival was fitted again on every "
        "training sample before the loop decided on it. Figures marked 'screened' are the "
        "screened fit's, its held-out RMSE scaled by its start model's full over screened one."
    )
