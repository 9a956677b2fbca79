"""Selection that can undo itself, the runner-up and the margin.

Recordings are written out by hand from the formulas (:mod:`test_selection_recordings`), not by
the effect plugins the loop fits.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hcard.calibration.dataset import prepare
from hcard.calibration.loop import calibrate
from hcard.calibration.results import AMBIGUOUS, EXPLAINED
from hcard.calibration.selection import MEASUREMENTS, separating_regressor
from hcard.plugins.registry import get_registry
from tests.calibration.test_selection_recordings import Hidden, uv_recording

UV = "dimensionless-group"


def run(m):
    registry = get_registry()
    return calibrate(
        prepare([m]), registry.get("predictor", UV), list(registry.calibration_effects.values())
    )


@pytest.mark.parametrize(("seed", "noise"), [(1, 1.5e-3), (2, 5e-3), (3, 3e-3)])
def test_occlusion_plus_load_index_is_found_where_no_single_effect_pays(
    seed: int, noise: float
) -> None:
    truth = Hidden(occlusion_gain=0.3, occlusion_tau_s=15.0, load_index=0.8)
    result = run(uv_recording(truth, seed=seed, noise_n=noise))
    assert result.verdict == EXPLAINED, result.summary
    assert set(result.effects_added) == {"occlusion-drift", "load-index"}
    # the truth's own error: the noise (the loop reaches it; 5 % for the fitted parameters)
    assert result.after.test_rmse < 1.1 * noise
    assert result.after.test_rmse < 0.5 * result.before.test_rmse
    params = result.after.fit.params
    assert params["load-index.load_index"] == pytest.approx(0.8, abs=0.03)
    assert params["occlusion-drift.gain"] == pytest.approx(0.3, rel=0.15)
    # every pair of the usable effects was scored (in the pair search, or in round 2 as one
    # added to the effect of round 1), and the runner-up and margin are stated
    usable = set(result.library) - set(result.skipped)
    scored = {frozenset(c.effect.split(" + ")) for c in result.candidates if " + " in c.effect}
    first = [c.effect for c in result.candidates if c.round == 1 and c.accepted]
    scored |= {frozenset([*first, c.effect]) for c in result.candidates if c.round == 2}
    assert scored >= {frozenset(pair) for pair in itertools.combinations(usable, 2)}
    comparison = result.comparison
    assert comparison is not None and not comparison.ambiguous
    assert set(comparison.chosen) == {"occlusion-drift", "load-index"}
    assert len(comparison.runner_up) == 2 and set(comparison.runner_up) != set(comparison.chosen)
    assert comparison.rmse_margin > 0.2 and comparison.criterion_margin > 100
    expected = comparison.runner_up_rmse / result.after.test_rmse - 1
    assert comparison.rmse_margin == pytest.approx(expected)
    assert f"Runner-up {' + '.join(comparison.runner_up)}" in result.summary


@pytest.mark.parametrize("seed", [1, 2])
def test_without_rests_occlusion_and_skin_recovery_are_ambiguous_and_rests_separate_them(
    seed: int,
) -> None:
    # No vibration (mu0 inside Psi plays no part) and no rest: the stroke count grows with
    # time, so a slow rise in time (occlusion) and one per stroke (skin recovery) look alike.
    truth = Hidden(occlusion_gain=0.3, occlusion_tau_s=15.0)
    unrested = run(uv_recording(truth, seed=seed, noise_n=6e-3, rest_every=0,
                                amplitudes=(0.0,)))
    assert unrested.verdict == AMBIGUOUS, unrested.summary
    comparison = unrested.comparison
    assert {*comparison.chosen, *comparison.runner_up} == {"occlusion-drift", "skin-recovery"}
    assert comparison.rmse_margin < 0.01 or comparison.criterion_margin < 10
    assert comparison.separating_regressor in ("time", "stroke")
    assert "ambiguous between" in unrested.summary.lower()
    assert comparison.measurement == MEASUREMENTS[comparison.separating_regressor]
    assert "rests" in comparison.measurement
    # The measurement it names: rests every 8 strokes restart the stroke count, not time.
    rested = run(uv_recording(truth, seed=seed, noise_n=6e-3, rest_every=4, amplitudes=(0.0,)))
    assert rested.verdict == EXPLAINED, rested.summary
    assert rested.effects_added == ("occlusion-drift",)
    assert not rested.comparison.ambiguous
    (skin,) = [c for c in rested.candidates if c.round == 1 and c.effect == "skin-recovery"]
    assert skin.test_rmse > 1.05 * rested.after.test_rmse


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_separating_regressor_is_where_the_difference_varies(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5000
    # x evenly spread and shuffled: exactly a fifth lies above 0.8 and the decile edge falls
    # on the step (a uniform draw puts 19-21 % there, and a bin straddling the step dilutes
    # eta2 by a few hundredths, which says nothing about the code)
    x = rng.permutation((np.arange(n) + 0.5) / n)
    other = rng.uniform(0.0, 1.0, n)
    # A difference that is 0 below x = 0.8 and 0.1 above, plus noise, plus a constant offset
    difference = 0.3 + np.where(x > 0.8, 0.1, 0.0) + rng.normal(0.0, 0.01, n)
    name, eta2, largest, at = separating_regressor(difference, {"other": other, "x": x})
    assert name == "x"
    # between-bin variance of a step of 0.1 on a fifth of the samples, p (1 - p) 0.1^2,
    # over that plus the noise variance 0.01^2 (by hand: 0.0016 / 0.0017 = 0.941)
    p = 0.2
    expected = p * (1 - p) * 0.1**2 / (p * (1 - p) * 0.1**2 + 0.01**2)
    assert eta2 == pytest.approx(expected, abs=0.01)
    # the top bins against the mean: 0.1 - 0.1 p = 0.08
    assert largest == pytest.approx(0.1 * (1 - p), abs=0.005)
    assert at > 0.8
