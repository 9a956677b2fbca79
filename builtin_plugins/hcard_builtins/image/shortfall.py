"""Where an encode misses its error target, by how much, and why.

A taxtel misses the target when the 95th percentile of the absolute difference between the
card and the image over its pixels exceeds it. The reason is one of:

- ``detail``: the taxtel's own texture misses the target even with the most components a
  texture can hold (16): what it shows is not a few gratings (fine detail, noise, many edges).
  Smaller taxtels (``--taxtel-mm``) give each texture less to carry;
- ``components``: its own texture misses the target with the ``--components`` cap, but the
  format's limit would let it meet it (by the energy of its residual's strongest harmonics);
- ``palette``: its own texture meets the target, but it shares a palette texture that does not
  (the palette is full: ``--max-textures``, at most 256 in the format).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hcard import limits

from .analysis import Target, TaxtelTextures
from .reconstruct import ReconstructionError

REASONS = ("detail", "components", "palette")
"""Reason codes 1, 2, 3 of :attr:`Shortfall.reason` (0: the taxtel meets the target)."""


@dataclass(frozen=True)
class Shortfall:
    """The taxtels over the error target.

    Attributes:
        target: the target, relative friction (95th percentile per taxtel).
        p95: ``(rows, cols)`` 95th percentile of each taxtel's error, relative friction.
        reason: ``(rows, cols)`` 0 where the taxtel meets the target, else 1 + the index of its
            reason in :data:`REASONS`.
        palette_full: whether the palette reached its size limit.
    """

    target: float
    p95: np.ndarray
    reason: np.ndarray
    palette_full: bool

    @property
    def over(self) -> int:
        """Number of taxtels over the target."""
        return int(np.count_nonzero(self.reason))

    def figures(self) -> dict[str, Any]:
        """The summary's figures: the target and the statistic it bounds, how many taxtels
        are over it by reason, the worst, and every taxtel over it (worst first; column, row,
        95th percentile in JND and reason)."""
        jnd = limits.RELATIVE_FRICTION_JND
        rows, cols = np.nonzero(self.reason)
        order = np.argsort(-self.p95[rows, cols], kind="stable")
        listed = [
            {"col": int(c), "row": int(r), "p95_jnd": float(self.p95[r, c]) / jnd,
             "reason": REASONS[int(self.reason[r, c]) - 1]}
            for r, c in zip(rows[order], cols[order], strict=True)
        ]
        return {
            "target_jnd": self.target / jnd,
            "statistic": "95th percentile of the absolute error over each taxtel's pixels",
            "taxtels_over": self.over,
            "reasons": {name: int(np.count_nonzero(self.reason == code + 1))
                        for code, name in enumerate(REASONS)},
            "palette_full": self.palette_full,
            "worst": listed[0] if listed else None,
            "over_target": listed,
        }


def shortfall(
    error: ReconstructionError,
    taxtels: TaxtelTextures,
    target: Target,
    *,
    palette_full: bool,
) -> Shortfall:
    """The taxtels of ``error`` over ``target`` and why (see the module docstring)."""
    if error.taxtel_p95 is None:
        raise ValueError("the reconstruction error has no per-taxtel percentiles")
    p95 = error.taxtel_p95
    shape = p95.shape
    over = p95 > target.p95
    own_misses = (taxtels.own_p95 > target.p95).reshape(shape)
    capped = target.components < limits.MAX_COMPONENTS_PER_TEXTURE
    limit_would_do = (taxtels.rms_at_limit <= target.goal_rms).reshape(shape)
    reason = np.where(
        own_misses,
        np.where(capped & limit_would_do, 2, 1),
        3,
    )
    return Shortfall(target.p95, p95, np.where(over, reason, 0).astype(np.int8), palette_full)
