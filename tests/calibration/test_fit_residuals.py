"""Fit and residual analysis of the calibration loop (spec/calibration.md), on synthetic data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard.calibration.fit import FitResult, fit_predictor
from hcard.calibration.residuals import analyse_residuals
from hcard.physics import PredictorError
from hcard_builtins.physics.ultrasonic import DimensionlessGroup

TRUE_PSI_STAR = 1.8
NOISE = 0.02  # standard deviation of the added noise, relative friction (dimensionless)
SAMPLE_RATE = 1000.0  # Hz


def recording(n: int = 2000, seed: int = 1) -> dict[str, np.ndarray]:
    """Synthetic tribometer-like inputs in SI units, in time order."""
    rng = np.random.default_rng(seed)
    return {
        "amplitude": rng.uniform(0.2e-6, 3e-6, n),  # m peak-to-peak
        "speed": rng.uniform(0.01, 0.1, n),  # m/s
        "normal_force": rng.uniform(0.2, 1.5, n),  # N
        "time": np.arange(n) / SAMPLE_RATE,  # s
    }


def model_inputs(data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: data[k] for k in ("amplitude", "speed", "normal_force")}


def clean_output(data: dict[str, np.ndarray]) -> np.ndarray:
    return DimensionlessGroup(psi_star=TRUE_PSI_STAR).forward(**model_inputs(data))


def time_block_split(n: int) -> np.ndarray:
    """Held-out split: the last quarter of the recording (a time block, not random samples)."""
    return np.arange(n) >= (3 * n) // 4


def test_fit_recovers_psi_star_with_its_uncertainty() -> None:
    data = recording()
    n = data["time"].size
    observed = clean_output(data) + np.random.default_rng(2).normal(0.0, NOISE, n)
    result = fit_predictor(
        DimensionlessGroup(psi_star=5.0), model_inputs(data), observed,
        free=["psi_star"], test=time_block_split(n),
    )
    assert isinstance(result, FitResult)
    assert result.success
    assert result.free == ("psi_star",) and result.n_free == 1
    assert result.n_train == 1500 and result.n_test == 500
    sigma = result.uncertainties["psi_star"]
    assert abs(result.params["psi_star"] - TRUE_PSI_STAR) < 3 * sigma
    assert 1e-4 < sigma < 3e-2
    assert result.params["mu0"] == 0.5  # fixed parameters untouched
    assert result.train_rmse == pytest.approx(NOISE, rel=0.1)
    assert result.test_rmse is not None
    assert result.test_rmse == pytest.approx(NOISE, rel=0.1)
    assert result.residuals.shape == (n,)
    assert result.at_bounds == ()


def test_reported_uncertainty_matches_scatter_of_repeated_fits() -> None:
    data = recording(n=400, seed=3)
    clean = clean_output(data)
    rng = np.random.default_rng(4)
    estimates, sigmas = [], []
    for _ in range(40):
        observed = clean + rng.normal(0.0, NOISE, clean.size)
        result = fit_predictor(
            DimensionlessGroup(), model_inputs(data), observed, free=["psi_star"]
        )
        estimates.append(result.params["psi_star"])
        sigmas.append(result.uncertainties["psi_star"])
    scatter = float(np.std(estimates, ddof=1))
    assert 0.6 < scatter / float(np.mean(sigmas)) < 1.5
    assert abs(np.mean(estimates) - TRUE_PSI_STAR) < 3 * scatter / math.sqrt(40)


def test_aic_bic_and_held_out_error_prefer_the_right_model() -> None:
    data = recording(seed=5)
    n = data["time"].size
    true = DimensionlessGroup(psi_star=2.5, psi_star_normal_force_slope=-1.0)
    observed = true.forward(**model_inputs(data)) + np.random.default_rng(6).normal(0, NOISE, n)
    test = time_block_split(n)
    small = fit_predictor(DimensionlessGroup(), model_inputs(data), observed,
                          free=["psi_star"], test=test)
    large = fit_predictor(DimensionlessGroup(), model_inputs(data), observed,
                          free=["psi_star", "psi_star_normal_force_slope"], test=test)
    assert large.params["psi_star_normal_force_slope"] == pytest.approx(-1.0, abs=0.1)
    assert large.bic() < small.bic() and large.aic() < small.aic()
    assert large.test_rmse is not None and small.test_rmse is not None
    assert large.test_rmse < 0.7 * small.test_rmse
    rss = float(np.sum(large.residuals[large.train] ** 2))
    assert large.aic() == pytest.approx(1500 * math.log(rss / 1500) + 4)
    assert large.bic() == pytest.approx(1500 * math.log(rss / 1500) + 2 * math.log(1500))


@pytest.mark.parametrize(
    ("missing", "term"),
    [
        ("normal_force", lambda d: 0.08 * (d["normal_force"] - 0.85)),
        ("time", lambda d: 0.06 * (d["time"] - 1.0)),
    ],
)
def test_missing_effect_leaves_structure_against_its_regressor(missing: str, term) -> None:
    data = recording(seed=7)
    n = data["time"].size
    rng = np.random.default_rng(8)
    observed = clean_output(data) + term(data) + rng.normal(0.0, NOISE, n)
    result = fit_predictor(DimensionlessGroup(), model_inputs(data), observed,
                           free=["psi_star"], test=time_block_split(n))
    regressors = {**data, "unrelated": rng.normal(size=n)}
    report = analyse_residuals(result.residuals, regressors, sample_rate_hz=SAMPLE_RATE)
    found = report.structured()
    assert found[0][0] == missing
    assert found[0][1] > 0.3  # the bins explain most of the residual variance
    assert "unrelated" not in [name for name, _, _ in found]
    assert report.regressors["unrelated"].eta2 < 0.02
    assert report.regressors[missing].monotonic
    assert not report.regressors["unrelated"].monotonic
    if missing == "time":
        assert report.time_structured()
        assert report.time.lag1_autocorrelation > 0.5
    else:
        assert not report.time_structured()
    table = report.table()
    assert missing in table and "unrelated" in table and "Ljung-Box" in table


def test_white_noise_residual_is_unstructured() -> None:
    rng = np.random.default_rng(9)
    n = 3000
    residual = rng.normal(0.0, NOISE, n)
    regressors = {
        "amplitude": rng.uniform(0.2e-6, 3e-6, n),
        "stroke": np.repeat(np.arange(10), n // 10).astype(float),
        "time": np.arange(n) / SAMPLE_RATE,
    }
    report = analyse_residuals(residual, regressors, sample_rate_hz=SAMPLE_RATE)
    assert report.structured() == []
    assert not report.time_structured()
    assert abs(report.time.lag1_autocorrelation) < 0.06
    assert report.rms == pytest.approx(NOISE, rel=0.05)
    assert all(s.eta2 < 0.01 and not s.monotonic for s in report.regressors.values())
    assert report.regressors["stroke"].bin_counts.tolist() == [300] * 10  # one bin per stroke


def test_dominant_frequency_of_a_periodic_residual() -> None:
    rng = np.random.default_rng(10)
    t = np.arange(4000) / SAMPLE_RATE
    residual = 0.05 * np.sin(2 * np.pi * 50.0 * t) + rng.normal(0.0, NOISE, t.size)
    report = analyse_residuals(residual, {"time": t}, sample_rate_hz=SAMPLE_RATE)
    assert report.time.dominant_frequency_hz == pytest.approx(50.0, abs=0.25)
    assert report.time.dominant_power_fraction is not None
    assert report.time.dominant_power_fraction > 0.5
    assert report.time_structured()
    assert "50 Hz" in report.table()
    assert analyse_residuals(residual, {}).time.dominant_frequency_hz is None


def test_fit_rejects_bad_inputs_clearly() -> None:
    data = model_inputs(recording(n=100))
    observed = clean_output(recording(n=100))
    model = DimensionlessGroup()
    with pytest.raises(PredictorError, match=r"unknown free parameter\(s\) psi_str"):
        fit_predictor(model, data, observed, free=["psi_str"])
    with pytest.raises(PredictorError, match="no data: observed is empty"):
        fit_predictor(model, {}, np.array([]), free=["psi_star"])
    nan_input = {**data, "speed": data["speed"].copy()}
    nan_input["speed"][17] = np.nan
    with pytest.raises(PredictorError, match=r"input speed has 1 non-finite value.*sample 17"):
        fit_predictor(model, nan_input, observed, free=["psi_star"])
    bad_observed = observed.copy()
    bad_observed[3] = np.inf
    with pytest.raises(PredictorError, match=r"observed has 1 non-finite.*sample 3"):
        fit_predictor(model, data, bad_observed, free=["psi_star"])
    with pytest.raises(PredictorError, match="unknown input"):
        fit_predictor(model, {**data, "voltage": 1.0}, observed, free=["psi_star"])
    with pytest.raises(PredictorError, match="not broadcastable to 100 samples"):
        fit_predictor(model, {**data, "speed": np.ones(7)}, observed, free=["psi_star"])
    overlap = np.arange(100) < 60
    with pytest.raises(PredictorError, match="share 10 sample"):
        fit_predictor(model, data, observed, free=["psi_star"], train=overlap,
                      test=np.arange(100) >= 50)
    with pytest.raises(PredictorError, match="need more samples than parameters"):
        fit_predictor(model, data, observed, free=["psi_star"], train=np.array([0]))


def test_residual_analysis_rejects_bad_inputs_clearly() -> None:
    r = np.random.default_rng(11).normal(size=50)
    with pytest.raises(PredictorError, match="regressor speed has shape"):
        analyse_residuals(r, {"speed": np.ones(49)})
    bad = np.ones(50)
    bad[4] = np.nan
    with pytest.raises(PredictorError, match="regressor force has 1 non-finite"):
        analyse_residuals(r, {"force": bad})
    with pytest.raises(PredictorError, match="residual has 1 non-finite"):
        analyse_residuals(bad, {})
    with pytest.raises(PredictorError, match="residual has 2 sample"):
        analyse_residuals(np.ones(2), {})
    with pytest.raises(PredictorError, match="sample_rate_hz must be positive"):
        analyse_residuals(r, {}, sample_rate_hz=0.0)
    constant = analyse_residuals(r, {"fixed": np.full(50, 2.0)}).regressors["fixed"]
    assert constant.p_value == 1.0 and constant.eta2 == 0.0


def test_degenerate_parameters_are_reported_unidentifiable() -> None:
    # The parameters enter DimensionlessGroup only as mu0 (1 + nu) (psi_star + slope Fn): scaling
    # all of mu0 (1 + nu), psi_star and the slope together leaves the output unchanged.
    data = recording(n=500, seed=12)
    observed = clean_output(data) + np.random.default_rng(13).normal(0.0, NOISE, 500)
    result = fit_predictor(DimensionlessGroup(), model_inputs(data), observed)
    assert result.free == ("mu0", "poisson_ratio", "psi_star", "psi_star_normal_force_slope")
    assert not result.identifiable
    assert result.condition_number > 1e8
    assert all(math.isinf(u) for u in result.uncertainties.values())
    assert np.isnan(result.covariance[0, 2])
    assert result.train_rmse == pytest.approx(NOISE, rel=0.1)
    single = fit_predictor(DimensionlessGroup(), model_inputs(data), observed, free=["psi_star"])
    assert single.identifiable and single.condition_number == 1.0


def test_p_values_count_autocorrelated_samples_once() -> None:
    """An AR(1) residual (rho 0.9) has no relation to time, yet a plain F-test over 20,000
    samples calls its wander across time bins significant (p ~ 1e-16). Corrected to the
    ~1,050 effectively independent samples (n (1 - rho) / (1 + rho)) it is not."""
    from scipy import signal, stats

    rng = np.random.default_rng(0)
    residual = signal.lfilter([1.0], [1.0, -0.9], rng.normal(size=20_000))
    time = np.arange(20_000.0)
    report = analyse_residuals(residual, {"time": time})
    assert report.effective_samples == pytest.approx(20_000 * 0.1 / 1.9, rel=0.05)
    assert stats.f_oneway(*np.array_split(residual, 10)).pvalue < 1e-10
    assert report.regressors["time"].p_value > 0.5
    assert report.structured() == []
    # A real trend of the same size as the wander stays significant after the correction.
    trended = residual + 2.0 * np.sin(2 * np.pi * time / 20_000)
    assert analyse_residuals(trended, {"time": time}).regressors["time"].p_value < 1e-6
    # Samples that are not a time series (a table) count as independent.
    table = analyse_residuals(residual, {"time": time}, time_ordered=False)
    assert table.effective_samples == 20_000


def _lateral(effects: tuple[str, ...] = ()):
    from hcard.calibration.observation import lateral_force_model
    from hcard.physics.effects import augment
    from hcard.plugins.registry import get_registry

    registry = get_registry()
    base = registry.get("predictor", "dimensionless-group")
    if effects:
        base = augment(base, [registry.calibration_effects[name] for name in effects])
    return lateral_force_model(base)


def test_parameters_the_data_never_move_are_held_and_the_rest_converge() -> None:
    # No plate vibration: mu' = 1 at any psi_star (Eq. 2.33, Psi -> inf), so the lateral
    # force is mu0 Fn + offset and the ultrasonic parameters move nothing. Kept free they
    # left the optimiser crawling; held, the fit is ordinary least squares in mu0 and the
    # offset, checked here against a straight-line fit of the force on the load.
    rng = np.random.default_rng(4)
    n = 3000
    fn = rng.uniform(0.2, 1.5, n)
    inputs = {"amplitude": np.zeros(n), "frequency": np.full(n, 30e3),
              "speed": rng.uniform(0.01, 0.1, n), "normal_force": fn}
    observed = 0.42 * fn + 0.003 + rng.normal(0.0, 2e-3, n)
    result = fit_predictor(_lateral(), inputs, observed)
    assert set(result.held) == {"poisson_ratio", "psi_star", "psi_star_normal_force_slope"}
    assert result.success and result.n_free == 2
    assert all(math.isinf(result.uncertainties[name]) for name in result.held)
    slope, intercept = np.polyfit(fn, observed, 1)
    assert result.params["mu0"] == pytest.approx(slope, rel=1e-6)
    assert result.params["force_offset"] == pytest.approx(intercept, abs=1e-7)
    assert math.isfinite(result.uncertainties["mu0"])
    assert result.params["psi_star"] == DimensionlessGroup().params["psi_star"]  # untouched


def test_a_time_constant_behind_a_gain_that_starts_at_zero_stays_free() -> None:
    # Occlusion from its neutral value (gain 0): at the start its time constant moves nothing,
    # but it does once the gain moves, so it is fitted (probed at a second point).
    rng = np.random.default_rng(5)
    n = 4000
    t = np.arange(n) / 100.0  # 40 s at 100 Hz
    fn = rng.uniform(0.2, 1.5, n)
    inputs = {"amplitude": np.zeros(n), "frequency": np.full(n, 30e3),
              "speed": np.full(n, 0.05), "normal_force": fn,
              "occlusion_time": t}  # in contact throughout
    observed = 0.4 * (1.0 + 0.3 * (1.0 - np.exp(-t / 8.0))) * fn + rng.normal(0.0, 1e-3, n)
    model = _lateral(("occlusion-drift",)).with_params(**{"occlusion-drift.gain": 0.0})
    free = ["mu0", "force_offset", "occlusion-drift.gain", "occlusion-drift.time_constant"]
    result = fit_predictor(model, inputs, observed, free=free, dynamic=True)
    assert result.held == ()
    assert result.params["occlusion-drift.gain"] == pytest.approx(0.3, rel=0.05)
    assert result.params["occlusion-drift.time_constant"] == pytest.approx(8.0, rel=0.05)
