"""Calibration effects: each built-in effect, hidden in synthetic data, is
explained by the augmented model and flagged by the residual analysis of the base fit."""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from hcard.calibration.fit import fit_predictor
from hcard.calibration.residuals import analyse_residuals
from hcard.calibration.time_series import high_pass, low_pass, recent_change, time_since_change
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect, augment
from hcard_builtins.effects import (
    ActuatorBandwidth,
    AirLayer,
    ChargeLeakage,
    FingerGeometry,
    LoadIndex,
    OcclusionDrift,
    SkinRecovery,
    SqueezeFilmShare,
    UltrasonicSpeed,
    hcard_calibration_effects,
)
from hcard_builtins.physics.electrovibration import Kaczmarek
from hcard_builtins.physics.finger import FingerFriction
from hcard_builtins.physics.ultrasonic import DimensionlessGroup

N = 3000
SEGMENT = 40  # samples per piecewise-constant amplitude or voltage level


def recording(rate_hz: float, seed: int) -> dict[str, np.ndarray]:
    """Tribometer-like inputs in SI units, in time order, sampled at ``rate_hz``."""
    rng = np.random.default_rng(seed)
    segments = N // SEGMENT
    amplitude = np.repeat(rng.uniform(0.0, 3e-6, segments), SEGMENT)  # m peak-to-peak
    polarity = np.where(np.arange(segments) % 2 == 0, 1.0, -1.0)
    # V, square-wave drive (section 3.6.3), switching half a segment after the amplitude steps
    voltage = np.roll(np.repeat(150.0 * polarity, SEGMENT), SEGMENT // 2)
    return {
        "time": np.arange(N) / rate_hz,  # s
        "occlusion_time": np.arange(N) / rate_hz,  # s: the finger never lifts here
        "amplitude": amplitude,
        "voltage": voltage,
        "speed": rng.uniform(0.01, 0.1, N),  # m/s
        "normal_force": rng.uniform(0.2, 1.5, N),  # N
        # strokes of 0.2 s in sessions of 5, the finger resting between sessions
        "stroke": ((np.arange(N) // 200) % 5).astype(float),
        "pressure": np.repeat(rng.uniform(0.3, 1.0, segments), SEGMENT) * 101_325.0,  # Pa
    }


def regressors(data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every regressor the analysis sees, named as in :mod:`hcard.physics.effects`."""
    t = data["time"]
    return {
        "normal_force": data["normal_force"],
        "speed": data["speed"],
        "amplitude": data["amplitude"],
        "voltage": data["voltage"],
        "pressure": data["pressure"],
        "stroke": data["stroke"],
        "time": t,
        "occlusion_time": data["occlusion_time"],
        "amplitude_history": recent_change(data["amplitude"], t, 0.01),
        "voltage_history": time_since_change(data["voltage"], t),
    }


@dataclass(frozen=True)
class Case:
    """One effect hidden in synthetic data: base model, true effect parameters, noise."""

    effect: Effect
    base: Callable[[], Predictor]
    base_free: tuple[str, ...]
    truth: dict[str, float]
    noise: float  # standard deviation of the added noise, output unit
    rate_hz: float


CASES = [
    Case(
        LoadIndex(),
        lambda: FingerFriction(load_index=1.0),
        ("friction_occluded",),
        {"load_index": 0.75},
        0.005,
        1000.0,
    ),
    Case(
        OcclusionDrift(),
        lambda: FingerFriction(load_index=1.0),
        ("friction_occluded",),
        {"gain": 0.6, "time_constant": 15.0},
        0.005,
        50.0,
    ),
    Case(
        ActuatorBandwidth(),
        DimensionlessGroup,
        ("psi_star",),
        {"time_constant": 5e-3},
        0.01,
        1000.0,
    ),
    Case(ChargeLeakage(), Kaczmarek, ("area",), {"time_constant": 10e-3}, 2e-5, 1000.0),
    Case(AirLayer(), Kaczmarek, ("area",), {"air_gap": 10e-6}, 2e-5, 1000.0),
    Case(FingerGeometry(), Kaczmarek, ("area",), {"area_index": 0.9}, 2e-5, 1000.0),
    Case(
        UltrasonicSpeed(), DimensionlessGroup, ("psi_star",), {"speed_exponent": -0.8}, 0.01, 1000.0
    ),
    Case(
        SqueezeFilmShare(),
        DimensionlessGroup,
        ("psi_star",),
        {"share": 0.6},
        0.01,
        1000.0,
    ),
    Case(
        SkinRecovery(),
        lambda: FingerFriction(load_index=1.0),
        ("friction_occluded",),
        {"depth": 0.4, "strokes": 1.5},
        0.005,
        1000.0,
    ),
]


def held_out(n: int) -> np.ndarray:
    """The last fifth of the recording: a time block, never random samples."""
    return np.arange(n) >= (4 * n) // 5


@pytest.mark.parametrize("case", CASES, ids=[c.effect.name for c in CASES])
def test_effect_is_found_and_explains_the_residual(case: Case) -> None:
    data = recording(case.rate_hz, seed=11)
    base = case.base()
    effect = case.effect
    prefix = f"{effect.name}."
    truth = augment(base, [effect]).with_params(**{prefix + k: v for k, v in case.truth.items()})
    inputs = {k: v for k, v in data.items() if k in {var.name for var in truth.inputs}}
    clean = truth.forward(**inputs)
    observed = clean + np.random.default_rng(12).normal(0.0, case.noise, N)
    test = held_out(N)

    base_inputs = {k: v for k, v in inputs.items() if k in {var.name for var in base.inputs}}
    before = fit_predictor(base, base_inputs, observed, free=case.base_free, test=test)
    model = augment(base, [effect])
    free = (*case.base_free, *(prefix + p.name for p in effect.parameters))
    after = fit_predictor(model, inputs, observed, free=free, test=test)

    assert before.test_rmse is not None and after.test_rmse is not None
    assert after.test_rmse <= 0.5 * before.test_rmse
    assert after.test_rmse == pytest.approx(case.noise, rel=0.15)
    for name, value in case.truth.items():
        sigma = after.uncertainties[prefix + name]
        assert math.isfinite(sigma) and sigma > 0
        assert abs(after.params[prefix + name] - value) < 3 * sigma

    report = analyse_residuals(before.residuals, regressors(data))
    strongest = max(s.eta2 for s in report.regressors.values())
    # in this continuous contact the occlusion time is the time: the two tie
    tied = {name for name, s in report.regressors.items()
            if s.eta2 == pytest.approx(strongest, rel=1e-9)}
    assert effect.signature[0] in tied
    assert report.structured()[0][0] in tied


def test_hook_returns_every_effect_with_unique_names() -> None:
    effects = hcard_calibration_effects()
    names = [e.name for e in effects]
    assert names == [
        "load-index",
        "occlusion-drift",
        "actuator-bandwidth",
        "charge-leakage",
        "ultrasonic-speed",
        "air-layer",
        "skin-recovery",
        "squeeze-film-share",
        "finger-geometry",
    ]
    assert len(set(names)) == len(names)
    for effect in effects:
        assert effect.kind == "calibration-effect"
        assert effect.description and effect.reason and effect.signature
        assert effect.parameters and all(p.source for p in effect.parameters)


@pytest.mark.parametrize(
    "base", [FingerFriction(), DimensionlessGroup(), Kaczmarek()], ids=lambda b: b.name
)
def test_augment_without_effects_is_the_base_exactly(base: Predictor) -> None:
    data = recording(1000.0, seed=3)
    inputs = {k: v for k, v in data.items() if k in {var.name for var in base.inputs}}
    same = augment(base, [])
    assert same.params == base.params
    assert np.array_equal(same.forward(**inputs), base.forward(**inputs))
    assert same.inverse_input == base.inverse_input


def test_augmented_parameters_are_prefixed_and_effects_at_neutral_values_vanish() -> None:
    base = FingerFriction(load_index=1.0)
    model = augment(base, [LoadIndex(), OcclusionDrift()])
    names = [p.name for p in model.parameters]
    assert names[: len(base.parameters)] == [p.name for p in base.parameters]
    assert names[len(base.parameters) :] == [
        "load-index.load_index",
        "occlusion-drift.gain",
        "occlusion-drift.time_constant",
        "occlusion-drift.psi_share",
    ]
    assert [v.name for v in model.inputs] == [
        "normal_force", "speed", "contact_time", "occlusion_time"]
    neutral = model.with_params(**{"load-index.load_index": 1.0, "occlusion-drift.gain": 0.0})
    force = np.array([0.2, 0.5, 1.4])
    assert np.allclose(
        neutral.forward(normal_force=force, occlusion_time=[0.0, 5.0, 50.0]),
        base.forward(normal_force=force),
    )
    assert model.inverse_input is None
    fitted = model.with_params(**{"load-index.load_index": 0.8})
    assert fitted["load-index.load_index"] == 0.8
    assert fitted.params["friction_occluded"] == base["friction_occluded"]


def test_an_augmented_predictor_survives_pickling_with_its_values_and_outputs() -> None:
    """A device profile with a fitted effect crosses to the served device's card-check worker
    process and back by pickle; the augmented class is made at run time."""
    model = augment(FingerFriction(load_index=1.0), [LoadIndex(), OcclusionDrift()]).with_params(
        **{"load-index.load_index": 0.8, "occlusion-drift.gain": 0.3})
    again = pickle.loads(pickle.dumps(model))
    assert type(again).__name__ == "Augmented_FingerFriction"
    assert again.params == model.params
    force, occluded = np.array([0.2, 0.5, 1.4]), np.array([0.0, 5.0, 50.0])
    expected = model.forward(normal_force=force, occlusion_time=occluded)
    assert np.array_equal(again.forward(normal_force=force, occlusion_time=occluded), expected)
    assert not np.allclose(expected, FingerFriction(load_index=1.0).forward(normal_force=force))


def test_finger_geometry_at_neutral_value_is_the_base_exactly() -> None:
    data = recording(1000.0, seed=5)
    base = Kaczmarek()
    model = augment(base, [FingerGeometry()])
    inputs = {"voltage": data["voltage"], "normal_force": data["normal_force"]}
    neutral = model.with_params(**{"finger-geometry.area_index": 0.0})
    assert np.array_equal(neutral.forward(**inputs), base.forward(voltage=data["voltage"]))
    # At 1 N the factor is 1 for any load index: the base's area is the area at 1 N.
    at_1n = model.forward(voltage=data["voltage"], normal_force=1.0)
    assert np.allclose(at_1n, base.forward(voltage=data["voltage"]), rtol=1e-12)
    # The pad carries more force the harder it is pressed, up to fully flat.
    force = np.array([0.2, 0.5, 1.0, 1.5, 20.0, 40.0])
    factor = model.forward(voltage=100.0, normal_force=force) / base.forward(voltage=100.0)
    assert np.all(np.diff(factor[:5]) > 0) and factor[4] == factor[5]


def test_augment_refuses_repeated_effects_and_missing_inputs() -> None:
    with pytest.raises(PredictorError, match="repeat"):
        augment(FingerFriction(), [LoadIndex(), LoadIndex()])
    with pytest.raises(PredictorError, match="needs input"):
        augment(FingerFriction(), [ChargeLeakage()])


def test_first_order_filters_step_response() -> None:
    t = np.arange(100) * 1e-3  # s
    step = np.where(np.arange(100) >= 10, 2.0, 0.0)
    tau = 5e-3
    e = high_pass(step, t, tau)
    y = low_pass(step, t, tau)
    after = t[10:] - t[10] + 0.5e-3  # the step is taken midway between samples 9 and 10
    assert np.allclose(e[10:], 2.0 * np.exp(-after / tau))
    assert np.allclose(y + e, step)
    assert np.allclose(e[:10], 0.0)
    # A non-uniform time axis gives the same response at the shared instants.
    keep = np.ones(100, dtype=bool)
    keep[[30, 31, 55]] = False
    assert np.allclose(high_pass(step[keep], t[keep], tau), e[keep])
    # Without a time axis the filters are the identity (steady state).
    assert np.array_equal(high_pass(step, 0.0, tau), step)
    assert np.array_equal(low_pass(step, 0.0, tau), step)
    # Limits: a very short time constant passes everything through the low-pass (the effect
    # is off), a very long one everything through the high-pass.
    assert np.allclose(low_pass(step, t, 1e-7), step)
    assert np.allclose(high_pass(step, t, 1e7), step, atol=1e-3)
    with pytest.raises(PredictorError, match="repeated time"):
        high_pass(step, np.repeat(t[:50], 2), tau)
    # Where time decreases a new recording starts, from rest.
    twice = high_pass(np.concatenate([step, step]), np.concatenate([t, t]), tau)
    assert np.allclose(twice, np.concatenate([e, e]))


def test_history_regressors() -> None:
    t = np.arange(6) * 0.5
    x = np.array([1.0, 1.0, 3.0, 3.0, 3.0, 2.0])
    assert np.allclose(time_since_change(x, t), [0.0, 0.5, 0.0, 0.5, 1.0, 0.0])
    assert np.allclose(recent_change(x, t, 0.5), [1.0, 0.0, 2.0, 0.0, 0.0, -1.0])


@pytest.mark.parametrize("case", CASES, ids=[c.effect.name for c in CASES])
def test_an_effect_at_its_neutral_values_is_the_base(case: Case) -> None:
    """The loop restarts a candidate fit from the neutral values, so they must give the base
    exactly (tests/calibration/test_effect_forms_neutral.py: on several protocols)."""
    effect = case.effect
    assert set(effect.neutral) <= {p.name for p in effect.parameters}
    data = recording(case.rate_hz, seed=5)
    base = case.base()
    model = augment(base, [effect]).with_params(
        **{f"{effect.name}.{k}": v for k, v in effect.neutral.items()}
    )
    inputs = {k: v for k, v in data.items() if k in {var.name for var in model.inputs}}
    base_inputs = {k: v for k, v in inputs.items() if k in {var.name for var in base.inputs}}
    assert np.allclose(model.forward(**inputs), base.forward(**base_inputs), rtol=1e-12, atol=0)
