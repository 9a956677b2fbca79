"""Contact decided by the normal force, and a check of a recording's own stroke column.

A finger touches when the recorded normal force is at least a threshold (rule MS2). The
threshold defaults to the larger of :data:`~hcard.calibration.measurement.CONTACT_THRESHOLD_N`
(10 mN) and :data:`NOISE_MULTIPLE` standard deviations of the normal-force sensor's noise,
measured on the lifted samples (those below the 10 mN floor): a noisier sensor needs a higher
threshold, or its lifts would count as touches.

A ``stroke`` column says which samples belong to a stroke; some files carry the stroke number
through the lifts, so samples with ``fn ~ 0`` would count as "in contact", be fitted as if the
finger slid, and leave the lateral-force zero unmeasured. The forces decide instead, and
:func:`stroke_column_disagreement` says how many samples the column and the forces disagree on.
"""

from __future__ import annotations

import numpy as np

from hcard.calibration.measurement import CONTACT_THRESHOLD_N, Measurement, MeasurementError
from hcard.quantities import MN_PER_N

NOISE_MULTIPLE = 5.0
"""Standard deviations of the lifted normal-force noise below the contact threshold."""

MIN_LIFTED_SAMPLES = 20
"""Lifted samples needed to measure the normal-force noise; fewer keep the 10 mN floor."""

MAD_TO_SIGMA = 1.4826
"""Median absolute deviation -> standard deviation of a normal distribution."""

DISAGREEMENT_FRACTION = 0.01
"""Share of a stroke column's contact samples below the force threshold that is reported (a
few samples at each touch-down and lift-off are the threshold's own blur)."""


def normal_force_noise(normal_force: np.ndarray) -> float | None:
    """Standard deviation of the normal-force sensor's noise, N, from the lifted samples (below
    :data:`CONTACT_THRESHOLD_N`), by the median absolute deviation; None with fewer than
    :data:`MIN_LIFTED_SAMPLES` of them."""
    fn = np.asarray(normal_force, dtype=np.float64)
    lifted = fn[fn < CONTACT_THRESHOLD_N]
    if lifted.size < MIN_LIFTED_SAMPLES:
        return None
    return float(MAD_TO_SIGMA * np.median(np.abs(lifted - np.median(lifted))))


def default_contact_threshold(normal_force: np.ndarray) -> float:
    """The contact threshold for a recording, N: the larger of :data:`CONTACT_THRESHOLD_N` and
    :data:`NOISE_MULTIPLE` times :func:`normal_force_noise` above the lifted samples' median."""
    fn = np.asarray(normal_force, dtype=np.float64)
    sigma = normal_force_noise(fn)
    if sigma is None:
        return CONTACT_THRESHOLD_N
    zero = float(np.median(fn[fn < CONTACT_THRESHOLD_N]))
    return max(CONTACT_THRESHOLD_N, zero + NOISE_MULTIPLE * sigma)


def check_threshold(threshold_n: float) -> float:
    """``threshold_n`` as a float, or a :class:`MeasurementError` naming it when it is not a
    positive finite force."""
    value = float(threshold_n)
    if not np.isfinite(value) or value <= 0:
        raise MeasurementError(
            f"contact_threshold_n must be a positive force in N, got {threshold_n!r}"
        )
    return value


def in_contact(m: Measurement, threshold_n: float) -> np.ndarray:
    """Per sample, a finger touches: ``normal_force >= threshold_n`` (N), and the ``contact``
    column where the recording has one."""
    pressing = np.asarray(m.normal_force) >= check_threshold(threshold_n)
    return pressing if m.contact is None else pressing & np.asarray(m.contact, dtype=bool)


def stroke_column_disagreement(m: Measurement, threshold_n: float) -> int:
    """Samples a ``stroke`` column puts in a stroke (value >= 0) where the normal force is below
    ``threshold_n`` (N); 0 without a stroke column."""
    if m.stroke is None:
        return 0
    column = np.asarray(m.stroke) >= 0
    return int(np.count_nonzero(column & ~in_contact(m, threshold_n)))


def contact_warning(m: Measurement, threshold_n: float, label: str) -> str | None:
    """A warning when the stroke column of ``m`` counts more than
    :data:`DISAGREEMENT_FRACTION` of its stroke samples as in contact where the normal force is
    below ``threshold_n``; None when they agree."""
    count = stroke_column_disagreement(m, threshold_n)
    if m.stroke is None or count == 0:
        return None
    marked = int(np.count_nonzero(np.asarray(m.stroke) >= 0))
    if count <= DISAGREEMENT_FRACTION * marked:
        return None
    lowest = float(np.min(np.asarray(m.normal_force)[(np.asarray(m.stroke) >= 0)
                                                     & ~in_contact(m, threshold_n)]))
    return (
        f"{label}: the stroke column puts {count} of its {marked} stroke samples in contact "
        f"where the normal force is below the contact threshold of {threshold_n * MN_PER_N:.3g} mN "
        f"(down to {lowest * MN_PER_N:.3g} mN, e.g. a stroke number carried through the lifts); "
        "contact is taken from the normal force"
    )
