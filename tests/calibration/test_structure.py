"""Structure tests with stated power: a sliding-direction regressor, a
noise model from the lifts and rests so coloured noise is not structure, small but significant
structure reported as such, and the power of each test.

Recordings are written out by hand (:mod:`test_selection_recordings`).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from hcard.calibration.dataset import CalibrationData, prepare
from hcard.calibration.judges import default_free, residual_structure, verdict_of
from hcard.calibration.loop import ResidualAnalyser, calibrate
from hcard.calibration.model_pool import ModelPool
from hcard.calibration.noise import detectable_eta2, measure_noise
from hcard.calibration.results import NO_EFFECT, NOT_EXPLAINED, LoopSettings, ModelFit, Structure
from hcard.calibration.summary import summarise
from hcard.plugins.registry import get_registry
from tests.calibration.test_selection_recordings import Hidden, ar1, uv_recording

BASE = "dimensionless-group"


def run(m):
    registry = get_registry()
    data = prepare([m])
    return data, calibrate(data, registry.get("predictor", BASE),
                           list(registry.calibration_effects.values()))


def base_model_left(m) -> tuple[CalibrationData, Structure, str]:
    """The structure left by the base model alone and the loop's summary when it adds no
    effect (the steps of :func:`~hcard.calibration.loop.calibrate` after its base fit). On
    these clean recordings the whole loop adds none: that is shown end to end in
    test_independent_recordings.py (clean white and coloured noise) and test_loop.py."""
    data = prepare([m])
    base = get_registry().get("predictor", BASE)
    settings = LoopSettings()
    pool = ModelPool(data, base, default_free(base), "lateral_force", None, lambda _text: None)
    fit = pool.fit([], {})
    analysis = ResidualAnalyser(data, settings.bins)(fit)
    structure = residual_structure(analysis, settings, data.time_ordered, data.noise)
    verdict = verdict_of(structure, (), None)
    model = ModelFit((), fit, analysis, 0.0)
    return data, structure, summarise(BASE, verdict, model, model, (), structure, "N")


@pytest.mark.parametrize(("seed", "noise"), [(1, 1.5e-3), (2, 3e-3)])
def test_a_direction_dependent_friction_is_reported_against_direction(
    seed: int, noise: float
) -> None:
    # friction 10 % higher in one direction than the mean, 10 % lower in the other
    data, result = run(uv_recording(Hidden(direction=0.1), seed=seed, noise_n=noise))
    assert "direction" in data.regressors
    assert result.verdict == NOT_EXPLAINED, result.summary
    found = {name: eta2 for name, eta2, _ in result.structure.regressors}
    assert found.get("direction", 0.0) > 0.3, result.summary
    assert "direction (eta2" in result.summary


@pytest.mark.parametrize(("seed", "noise", "lag1"), [(2, 1.5e-3, 0.73), (3, 1.5e-3, 0.9),
                                                     (4, 3e-3, 0.8)])
def test_coloured_noise_on_clean_data_is_not_structure(
    seed: int, noise: float, lag1: float
) -> None:
    data, structure, summary = base_model_left(
        uv_recording(Hidden(), seed=seed, noise_n=noise, noise_lag1=lag1))
    # the noise model, measured out of contact, finds the AR(1) the recording was made with
    assert data.noise is not None
    assert data.noise.lag1 == pytest.approx(lag1, abs=0.04)
    assert data.noise.sigma == pytest.approx(noise, rel=0.15)
    # a fixed lag-1 threshold of 0.5 would call this residual structured in time; against
    # the noise's own autocorrelation it is not
    assert structure.autocorrelation > 0.5
    assert not structure.in_time
    assert verdict_of(structure, (), None) == NO_EFFECT, summary
    assert structure.time_threshold == pytest.approx(lag1 + (1 - lag1) / 2, abs=0.03)


@pytest.mark.parametrize("seed", [1, 2])
def test_small_but_significant_structure_is_reported_as_such(seed: int) -> None:
    # 0.1 % direction dependence: significant with ~10,000 samples, far below eta2 0.10
    _data, structure, summary = base_model_left(
        uv_recording(Hidden(direction=0.001), seed=seed, noise_n=1e-3))
    small = {name: (eta2, p) for name, eta2, p in structure.small}
    assert "direction" in small, summary
    eta2, p = small["direction"]
    assert 0.0 < eta2 < LoopSettings().min_eta2 and p < LoopSettings().alpha
    assert "direction" not in {name for name, _, _ in structure.regressors}
    assert "small structure against" in summary and "direction: eta2" in summary
    assert "below the practical threshold" in summary
    # the power is stated per regressor and is what lets such a structure be seen
    detectable = dict(structure.detectable)
    assert detectable["direction"] < eta2


@pytest.mark.parametrize(("n_eff", "groups"), [(200, 10), (1000, 2)])
def test_the_stated_power_is_the_detection_rate(n_eff: int, groups: int) -> None:
    # Independent path: simulate the F-test (scipy.stats.f_oneway) on groups whose means
    # explain exactly the stated eta2 and count how often it is detected at alpha = 0.01.
    alpha = 0.01
    eta2 = detectable_eta2(n_eff, groups, alpha)
    rng = np.random.default_rng(7)
    per = n_eff // groups
    means = np.linspace(-1.0, 1.0, groups)
    means *= np.sqrt(eta2 / (1 - eta2)) / np.std(means)  # between variance / within (1)
    hits = 0
    trials = 800
    for _ in range(trials):
        samples = [rng.normal(m, 1.0, per) for m in means]
        hits += stats.f_oneway(*samples).pvalue < alpha
    assert hits / trials == pytest.approx(0.8, abs=0.05)


@pytest.mark.parametrize(("lag1", "seed"), [(0.0, 1), (0.6, 2), (0.95, 3)])
def test_the_noise_model_measures_an_ar1(lag1: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    values = ar1(rng, 60_000, 2e-3, lag1) + 0.05  # a zero the runs' means take out
    lifted = (np.arange(values.size) // 300) % 2 == 0  # runs of 300 lifted samples
    model = measure_noise(values, lifted)
    assert model is not None and model.runs == 100 and model.samples == 30_000
    assert model.lag1 == pytest.approx(lag1, abs=0.03)
    assert model.sigma == pytest.approx(2e-3, rel=0.1)
