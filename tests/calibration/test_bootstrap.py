"""Uncertainties from a stroke-block bootstrap.

A load index is hidden in hand-written recordings (:mod:`test_selection_recordings`) with
strongly coloured (AR(1)) sensor noise: the Jacobian's ``sigma^2 (J^T J)^-1`` takes the
samples as independent and its interval misses the truth in most seeds; the stroke bootstrap's
interval covers it in most.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hcard.calibration.bootstrap import stroke_bootstrap
from hcard.calibration.dataset import prepare
from hcard.calibration.fit import fit_predictor
from hcard.calibration.observation import lateral_force_model
from hcard.physics import PredictorError
from hcard.physics.effects import augment
from hcard.plugins.registry import get_registry
from tests.calibration.test_selection_recordings import Hidden, uv_recording

LOAD = "load-index.load_index"
FREE = ["mu0", "psi_star", "force_offset", LOAD]


def model():
    registry = get_registry()
    return lateral_force_model(
        augment(registry.get("predictor", "dimensionless-group"),
                [registry.calibration_effects["load-index"]])
    )


@pytest.mark.parametrize(("noise", "lag1"), [(5e-3, 0.99), (3e-3, 0.98)])
def test_the_bootstrap_interval_covers_the_truth_where_the_jacobian_one_does_not(
    noise: float, lag1: float
) -> None:
    truth = 0.8
    jacobian_hits = bootstrap_hits = 0
    seeds = range(1, 7)
    for seed in seeds:
        m = uv_recording(Hidden(load_index=truth), seed=seed, noise_n=noise, noise_lag1=lag1,
                         duration_s=20.0)
        data = prepare([m])
        predictor = model()
        fit = fit_predictor(predictor, data.inputs_for(predictor), data.observed, free=FREE,
                            train=data.train, test=data.test)
        boot = stroke_bootstrap(fit, data, samples=40, seed=seed)
        assert boot.samples == 40 and boot.strokes == len(np.unique(
            data.stroke_labels()[data.train]))
        assert boot.capped == 0  # every refit converged inside the evaluation cap
        low, high = boot.intervals[LOAD]
        bootstrap_hits += low <= truth <= high
        jacobian_hits += abs(fit.params[LOAD] - truth) <= 1.96 * fit.uncertainties[LOAD]
        # the bootstrap spread is several times the Jacobian's for this coloured noise
        assert boot.uncertainties[LOAD] > 3 * fit.uncertainties[LOAD]
    assert bootstrap_hits >= 5
    assert jacobian_hits <= 3


@pytest.mark.parametrize("seed", [3, 4])
def test_weights_are_repeated_samples(seed: int) -> None:
    # Independent path: a fit on physically repeated samples (np.repeat), no weights.
    m = uv_recording(Hidden(load_index=0.7), seed=seed, duration_s=8.0, noise_n=3e-3)
    data = prepare([m])
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 3, len(data))
    predictor = model()
    inputs = data.inputs_for(predictor)
    weighted = fit_predictor(predictor, inputs, data.observed, free=FREE, train=data.train,
                             weights=counts.astype(float))
    keep = data.train & (counts > 0)
    repeated = fit_predictor(
        predictor,
        {k: np.repeat(v[keep], counts[keep]) for k, v in inputs.items()},
        np.repeat(data.observed[keep], counts[keep]),
        free=FREE,
    )
    for name in FREE:
        assert weighted.params[name] == pytest.approx(repeated.params[name], rel=1e-4, abs=1e-7)


def test_bad_bootstrap_requests_are_refused() -> None:
    m = uv_recording(Hidden(), seed=1, duration_s=4.0)
    data = prepare([m])
    predictor = model()
    fit = fit_predictor(predictor, data.inputs_for(predictor), data.observed, free=FREE,
                        train=data.train, test=data.test)
    with pytest.raises(PredictorError, match="samples must be at least 2"):
        stroke_bootstrap(fit, data, samples=1)
    with pytest.raises(PredictorError, match="weights must be finite and non-negative"):
        fit_predictor(predictor, data.inputs_for(predictor), data.observed, free=FREE,
                      weights=-np.ones(len(data)))


def test_held_out_strokes_never_enter_a_refit() -> None:
    """The split may hold out the stroke with the highest number (it once indexed past the
    training strokes and raised IndexError): every held-out stroke gets weight 0, so even a
    huge offset on its force changes no refit."""
    m = uv_recording(Hidden(load_index=0.7), seed=5, duration_s=8.0, noise_n=3e-3)
    data = prepare([m])
    labels = data.stroke_labels()
    last = labels == labels.max()
    split = replace(data, train=(labels >= 0) & ~last, test=last)
    predictor = model()
    fit = fit_predictor(predictor, split.inputs_for(predictor), split.observed, free=FREE,
                        train=split.train, test=split.test)
    boot = stroke_bootstrap(fit, split, samples=6, seed=2)
    assert boot.samples == 6
    assert boot.strokes == len(np.unique(labels[split.train]))
    shifted = replace(split, observed=np.where(last, split.observed + 10.0, split.observed))
    again = stroke_bootstrap(fit, shifted, samples=6, seed=2)
    for name in FREE:
        np.testing.assert_array_equal(again.values[name], boot.values[name])


def test_refits_stopped_at_the_cap_are_counted_and_stated(monkeypatch) -> None:
    """A refit that has not converged at the evaluation cap keeps its values and is counted:
    with a cap of one evaluation no refit of a four-parameter model can converge."""
    import hcard.calibration.bootstrap as bootstrap

    m = uv_recording(Hidden(load_index=0.7), seed=4, duration_s=8.0, noise_n=3e-3)
    data = prepare([m])
    predictor = model()
    start = predictor.with_params(**{LOAD: 0.5})  # away from the optimum
    fit = fit_predictor(start, data.inputs_for(start), data.observed, free=FREE,
                        train=data.train, test=data.test, max_evaluations=1)
    monkeypatch.setattr(bootstrap, "REFIT_EVALUATIONS", 1)
    boot = bootstrap.stroke_bootstrap(fit, data, samples=5, seed=1)
    assert boot.samples == 5 and boot.capped == 5
    assert "5 of the refits stopped at 1 model evaluations" in boot.method()
