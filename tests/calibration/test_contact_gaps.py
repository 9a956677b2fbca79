"""Contact time counts only samples in contact, also without lift samples
(spec/calibration.md K30).

The recording is written here with numpy from the occlusion law of the ``occlusion-drift``
effect (Fig. 1.11, ``mu0(t_o) = mu0 (1 + g (1 - exp(-t_o / tau_o)))``, ``t_o`` the time in
sliding contact, lifts excluded): strokes of 0.8 s at 100 Hz separated by 0.4 s lifts whose
samples the recording leaves out (no lift samples at all). The true occlusion time of every
sample is computed by this test's own sum of the stroke durations.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import curve_fit

from hcard.calibration.dataset import CONTACT_GAP_PERIODS, accumulated_contact_time

RATE_HZ = 100.0
STROKE_S, LIFT_S, STROKES = 0.8, 0.4, 60
MU0, GAIN, TAU_S, LOAD_N, SIGMA_N = 0.5, 0.6, 12.0, 0.5, 2e-3


def gapped_recording(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), lateral force (N) and the true occlusion time (s) of strokes with their lift
    samples left out."""
    per_stroke = round(STROKE_S * RATE_HZ)
    k = np.arange(per_stroke)
    t = np.concatenate([s * (STROKE_S + LIFT_S) + k / RATE_HZ for s in range(STROKES)])
    # the occlusion time: 1/RATE_HZ per sample in contact (the first sample of the
    # recording starts at 0), counted here by its own rule, independent of the library
    occluded = np.concatenate(
        [s * per_stroke / RATE_HZ + k / RATE_HZ for s in range(STROKES)])
    rng = np.random.default_rng(seed)
    force = MU0 * LOAD_N * (1.0 + GAIN * (1.0 - np.exp(-occluded / TAU_S)))
    return t, force + rng.normal(0.0, SIGMA_N, t.size), occluded


def occlusion_law(t_o: np.ndarray, f0: float, gain: float, tau: float) -> np.ndarray:
    """Fig. 1.11's occlusion rise of a friction force ``f0`` (N) with ``t_o`` in s."""
    return f0 * (1.0 + gain * (1.0 - np.exp(-t_o / tau)))


def test_gaps_without_lift_samples_are_not_contact_time_k30() -> None:
    t, force, truth = gapped_recording(seed=3)
    contact = np.ones(t.size, dtype=bool)  # no lift sample: every row is in contact
    occlusion = accumulated_contact_time(t, contact)
    # K30: the 0.4 s gaps (40 periods > 5) add one period each; 48 s of contact in 71.6 s of clock
    assert occlusion == pytest.approx(truth, abs=1e-9)
    assert occlusion[-1] == pytest.approx(STROKES * STROKE_S - 1 / RATE_HZ)
    assert t[-1] - t[0] == pytest.approx(71.59)
    # the occlusion constant is recovered within its uncertainty from the library's regressor
    params, cov = curve_fit(occlusion_law, occlusion, force, p0=(0.2, 1.0, 20.0))
    sd = np.sqrt(np.diag(cov))
    assert abs(params[2] - TAU_S) < 3 * sd[2]
    assert sd[2] < 0.5  # s: the test can tell 12 s from the clock-time answer below
    # what clock time (the rule before K30) gives: tau 1.49 times too long, far outside
    clock, _ = curve_fit(occlusion_law, t - t[0], force, p0=(0.2, 1.0, 20.0))
    assert clock[2] == pytest.approx(TAU_S * (STROKE_S + LIFT_S) / STROKE_S, rel=0.05)
    assert abs(clock[2] - TAU_S) > 10 * sd[2]


def test_a_gap_up_to_the_bound_is_contact_time_k30() -> None:
    # a dropped sample or two (rule MF6) is still contact: intervals up to 5 periods count
    t = np.array([0.0, 0.01, 0.02, 0.05, 0.06, 0.07, 0.20, 0.21])
    occlusion = accumulated_contact_time(t, np.ones(t.size, dtype=bool))
    assert CONTACT_GAP_PERIODS == 5.0
    assert occlusion == pytest.approx([0.0, 0.01, 0.02, 0.05, 0.06, 0.07, 0.08, 0.09])
