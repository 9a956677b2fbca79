"""The rendered friction error of a device recording (spec/calibration.md K17), on recordings
built here with a known rendering error, a drifting natural friction and sensor noise."""

from __future__ import annotations

import numpy as np
import pytest

from hcard.calibration.measurement import Measurement, MeasurementError
from hcard.calibration.rendering import SETTLE_S, rendering_error

RATE_HZ = 1000.0


def recording(targets: list[float], errors: list[float], *, patch_s: float = 0.25,
              mu0: float = 0.4, drift_per_s: float = 0.0, noise_n: float = 0.0,
              fn_n: float = 0.5, seed: int = 0, lift_every: int = 0) -> Measurement:
    """Patches of ``patch_s`` at ``targets`` rendered at ``target + error``, one contact (or a
    lift of 50 ms after every ``lift_every`` patches), the finger's natural friction
    ``mu0 (1 + drift_per_s t)``, Gaussian noise on the lateral force."""
    rng = np.random.default_rng(seed)
    per = round(patch_s * RATE_HZ)
    target, rendered, contact = [], [], []
    for k, (goal, error) in enumerate(zip(targets, errors, strict=True)):
        target += [goal] * per
        rendered += [goal + error] * per
        contact += [True] * per
        if lift_every and (k + 1) % lift_every == 0:
            target += [1.0] * 50
            rendered += [1.0] * 50
            contact += [False] * 50
    target_a, rendered_a = np.array(target), np.array(rendered)
    touching = np.array(contact)
    n = target_a.size
    t = np.arange(n) / RATE_HZ
    fn = np.where(touching, fn_n, 0.0)
    natural = mu0 * (1.0 + drift_per_s * t)
    lateral = natural * fn * rendered_a + rng.normal(0.0, noise_n, n)
    uv = np.where(target_a < 1.0, target_a, 1.0)
    ev = np.where(target_a > 1.0, target_a, 1.0)
    return Measurement(
        t=t, normal_force=fn, lateral_force=lateral, voltage=np.zeros(n),
        contact=touching, device={"target_uv": uv, "target_ev": ev},
        conditions={"device": "test"},
    )


TARGETS = [1.0, 0.5, 1.0, 0.8, 1.0, 1.2, 1.0, 0.65, 1.0]
ERRORS = [0.0, 0.04, 0.0, -0.02, 0.0, 0.05, 0.0, 0.0, 0.0]


def test_patch_error_is_the_systematic_error_of_each_patch():
    result = rendering_error(recording(TARGETS, ERRORS))
    modulated = [e for goal, e in zip(TARGETS, ERRORS, strict=True) if goal != 1.0]
    assert result.patches == 4
    assert result.patch_rms == pytest.approx(np.sqrt(np.mean(np.square(modulated))), rel=1e-9)
    assert result.bias == pytest.approx(np.mean(modulated), rel=1e-9)  # patches of equal size
    assert result.mu0 == pytest.approx(0.4, rel=1e-12)
    assert result.noise == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_averages_out_of_the_patch_error_but_not_of_the_report_error(seed):
    clean = rendering_error(recording(TARGETS, ERRORS))
    noisy = rendering_error(recording(TARGETS, ERRORS, noise_n=0.008, seed=seed))
    per_report = 0.008 / (0.4 * 0.5)  # the noise in relative friction: 0.04
    assert noisy.noise == pytest.approx(per_report, rel=0.1)
    # the patch error stays within a few noise floors (0.04 / sqrt(220) ~ 0.003) of the truth
    assert abs(noisy.patch_rms - clean.patch_rms) < 0.01
    # per report, the noise adds in quadrature to the systematic error
    assert noisy.rms == pytest.approx(np.hypot(clean.patch_rms, per_report), rel=0.1)


def test_a_drifting_natural_friction_is_measured_against_the_plain_patches_next_to_it():
    # the finger's friction rises 20 % a second (occlusion): a global mu0 would read the
    # late patches as rendered too high by up to ~0.4
    drifting = rendering_error(recording(TARGETS, ERRORS, drift_per_s=0.2))
    modulated = [e for goal, e in zip(TARGETS, ERRORS, strict=True) if goal != 1.0]
    truth = np.sqrt(np.mean(np.square(modulated)))
    # linear interpolation between the plain neighbours cancels a linear drift, up to the
    # curvature of target * mu0 (1 + d t) averaged over a patch: well under the 8 % JND
    assert drifting.patch_rms == pytest.approx(truth, abs=2e-3)


def test_each_contact_has_its_own_reference():
    # after every lift the finger's friction differs (a new contact: occlusion starts again);
    # a lift after each pair of patches: plain, textured | plain, textured | ...
    targets = [1.0, 0.5, 1.0, 0.7, 1.0, 1.1, 1.0, 0.9]
    errors = [0.0, 0.03, 0.0, -0.01, 0.0, 0.02, 0.0, 0.0]
    m = recording(targets, errors, lift_every=2)
    # scale each contact's natural friction by another factor, as a new contact may
    contact_id = np.cumsum(np.diff(m.contact.astype(int), prepend=0) == 1)
    m.lateral_force = m.lateral_force * (1.0 + 0.3 * contact_id)
    result = rendering_error(m)
    truth = np.sqrt(np.mean(np.square([0.03, -0.01, 0.02, 0.0])))
    assert result.patch_rms == pytest.approx(truth, rel=1e-9)


def test_the_first_settle_time_of_a_patch_does_not_count():
    m = recording(TARGETS, ERRORS)
    # a rise-time lag: the first 20 ms of each patch still at the previous level
    target = m.device["target_uv"] * m.device["target_ev"]
    change = np.flatnonzero(np.diff(target) != 0) + 1
    lagged = m.lateral_force.copy()
    for start in change:
        lagged[start:start + round(0.02 * RATE_HZ)] = m.lateral_force[start - 1]
    m.lateral_force = lagged
    assert SETTLE_S >= 0.02
    result = rendering_error(m)
    modulated = [e for goal, e in zip(TARGETS, ERRORS, strict=True) if goal != 1.0]
    assert result.patch_rms == pytest.approx(np.sqrt(np.mean(np.square(modulated))), rel=1e-9)


def test_recordings_without_targets_or_patches_are_errors():
    m = recording(TARGETS, ERRORS)
    with pytest.raises(MeasurementError, match="no target_uv and target_ev columns"):
        rendering_error(Measurement(m.t, m.normal_force, m.lateral_force, voltage=m.voltage,
                                    conditions={"device": "x"}))
    plain = recording([1.0, 1.0], [0.0, 0.0])
    with pytest.raises(MeasurementError, match="no modulated patch"):
        rendering_error(plain)
    textured = recording([0.5, 0.7], [0.0, 0.0])
    with pytest.raises(MeasurementError, match="no plain patch"):
        rendering_error(textured)
