"""The outputs of a model's parts kept across one fit's evaluations
(hcard.calibration.forward_cache): a fit with them is the fit without them, bit for bit."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from hcard.calibration import fit as fit_module
from hcard.calibration import forward_cache
from hcard.calibration.device_model import profile_model
from hcard.calibration.fit import fit_predictor
from hcard.calibration.model_pool import free_parameters
from hcard.calibration.observation import lateral_force_model
from hcard.physics.effects import augment
from hcard.physics.profile import DeviceProfile
from hcard.plugins.registry import get_registry

COUPLED = DeviceProfile.coupled_stimulator()
LIBRARY = get_registry().calibration_effects
FINGER = get_registry().get("predictor", "finger-friction")


def _data(n: int = 400, seed: int = 3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "amplitude": rng.uniform(0.0, 2e-6, n),
        "voltage": rng.uniform(0.0, 1500.0, n),
        "speed": rng.uniform(0.01, 0.15, n),
        "normal_force": rng.uniform(0.2, 1.2, n),
        "contact_time": np.linspace(0.0, 8.0, n),
    }


def _model(effects: tuple[str, ...]):
    base = profile_model(COUPLED, finger=FINGER)
    inner = augment(base, [LIBRARY[name] for name in effects]) if effects else base
    return lateral_force_model(inner)


@pytest.mark.parametrize("effects", [(), ("air-layer",), ("load-index",)])
def test_a_fit_with_kept_outputs_is_the_fit_without(monkeypatch, effects):
    model = _model(effects)
    inputs = {k: v for k, v in _data().items() if k in {x.name for x in model.inputs}}
    truth = model.with_params(**{"finger.load_index": 0.8, "uv_psi_star": 3.0})
    rng = np.random.default_rng(1)
    observed = truth.forward(**inputs) + rng.normal(0.0, 1e-3, inputs["speed"].size)
    effect_list = [LIBRARY[name] for name in effects]
    free = free_parameters(model, ("uv_psi_star", "ev_area", "finger.load_index",
                                   "finger.friction_initial"), effect_list)
    train = np.arange(observed.size) % 4 != 0
    kept = fit_predictor(model, inputs, observed, free=free, train=train)
    monkeypatch.setattr(fit_module, "caching_forwards", contextlib.nullcontext)
    again = fit_predictor(model, inputs, observed, free=free, train=train)
    assert kept.params == again.params
    np.testing.assert_array_equal(kept.residuals, again.residuals)
    np.testing.assert_array_equal(kept.covariance, again.covariance)
    assert kept.message == again.message


def test_a_kept_output_is_returned_only_for_the_same_values_and_inputs():
    model = profile_model(COUPLED, finger=FINGER)
    finger = model.finger
    arrays = _data()
    given = {k: arrays[k] for k in ("normal_force", "speed", "contact_time")}
    with forward_cache.caching_forwards():
        first = forward_cache.forward("finger", finger, given)
        assert forward_cache.forward("finger", finger, given) is first
        assert not first.flags.writeable
        moved = finger.with_params(load_index=finger["load_index"] * 1.001)
        other = forward_cache.forward("finger", moved, given)
        assert other is not first
        np.testing.assert_array_equal(other, moved.forward(**given))
        copied = {**given, "speed": given["speed"].copy()}  # equal values, another array
        assert forward_cache.forward("finger", finger, copied) is not first
        scalar = {**given, "speed": 0.05}
        a = forward_cache.forward("finger", finger, scalar)
        assert forward_cache.forward("finger", finger, {**given, "speed": 0.05}) is a
        assert forward_cache.forward("finger", finger, {**given, "speed": 0.06}) is not a
    outside = forward_cache.forward("finger", finger, given)
    assert outside is not first and outside.flags.writeable
    np.testing.assert_array_equal(outside, first)
