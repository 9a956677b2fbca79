"""Finger friction predictor (thesis sections 1.4.2 and 2.9.2.2)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hcard.physics import Predictor, PredictorError
from hcard_builtins.physics.finger import EXPLORATION_SPEED_RANGE, PRESETS, FingerFriction


@pytest.fixture(scope="module")
def finger() -> FingerFriction:
    return FingerFriction()


def fitted_power_law(model: FingerFriction, **state: float) -> tuple[float, float]:
    """(k, n) of a least-squares fit of log F_l against log Fn over 0.1-5 N."""
    normal = np.logspace(-1, math.log10(5.0), 25)
    lateral = model.forward(normal_force=normal, **state)
    n, log_k = np.polyfit(np.log(normal), np.log(lateral), 1)
    return math.exp(log_k), n


# -- load: F_l = k Fn^n (Eqs. 1.7, 2.35) ---------------------------------------------------
def test_interface():
    assert issubclass(FingerFriction, Predictor)
    assert FingerFriction.name == "finger-friction"
    assert FingerFriction.output.name == "lateral_force"
    assert FingerFriction.output.unit == "N"
    assert FingerFriction.inverse_input == "normal_force"
    assert [v.name for v in FingerFriction.inputs] == ["normal_force", "speed", "contact_time"]
    assert all(p.source for p in FingerFriction.parameters)


def test_power_law_exponent_is_recovered_from_the_forward_map(finger):
    k, n = fitted_power_law(finger)
    assert n == pytest.approx(0.91, abs=1e-9)
    assert k == pytest.approx(0.79, rel=1e-9)  # occluded, at the peak speed
    for index in (2.0 / 3.0, 0.8, 1.0):
        _, n = fitted_power_law(finger.with_params(load_index=index), speed=0.1, contact_time=5.0)
        assert n == pytest.approx(index, abs=1e-9)


@pytest.mark.parametrize(
    ("preset", "k_f", "n"), [("fig-2.32-cycle-1", 0.49, 1.05), ("fig-2.32-cycle-10", 0.52, 0.91)]
)
def test_fig_2_32_fits(preset, k_f, n):
    # Section 2.9.2.2: fitted at 40 mm/s, the default speed and the peak of g(U).
    model = FingerFriction.preset(preset)
    fitted_k, fitted_n = fitted_power_law(model, speed=0.040, contact_time=0.0)
    assert fitted_k == pytest.approx(k_f, rel=1e-9)
    assert fitted_n == pytest.approx(n, abs=1e-9)


def test_coefficient_falls_with_load_when_n_below_one(finger):
    # Eq. 1.8: mu = k Fn^(n - 1).
    mu = finger.friction_coefficient(normal_force=[0.1, 0.5, 1.0, 2.0])
    assert np.all(np.diff(mu) < 0)
    assert mu[2] == pytest.approx(0.79)
    assert mu[0] / mu[2] == pytest.approx(0.1 ** (0.91 - 1))
    coulomb = finger.with_params(load_index=1.0)
    np.testing.assert_allclose(coulomb.friction_coefficient(normal_force=[0.1, 2.0]), 0.79)


def test_load_index_outside_its_range_is_refused():
    with pytest.raises(PredictorError, match="load_index"):
        FingerFriction(load_index=0.5)
    with pytest.raises(PredictorError, match="load_index"):
        FingerFriction(load_index=1.5)


# -- speed: a maximum in the exploration range (Fig. 1.12) ---------------------------------
def test_speed_maximum_lies_inside_the_exploration_range(finger):
    low, high = EXPLORATION_SPEED_RANGE
    assert (low, high) == (0.010, 0.120)
    speeds = np.logspace(-4, 0, 4001)  # 0.1 mm/s to 1 m/s
    lateral = finger.forward(normal_force=0.5, speed=speeds)
    best = speeds[np.argmax(lateral)]
    assert low < best < high
    assert best == pytest.approx(0.040, rel=0.01)
    # A real maximum: lower on both sides, inside and outside the range.
    at_edges = finger.speed_factor([low, high])
    np.testing.assert_allclose(at_edges, [0.7 + 0.3 * 0.5 / 1.0625, 0.7 + 0.3 * 6 / 10])
    assert np.all(at_edges < 1.0)
    assert finger.speed_factor(0.0) == pytest.approx(0.7)
    assert finger.speed_factor(100.0) == pytest.approx(0.7, abs=1e-3)
    rising = speeds < best
    assert np.all(np.diff(lateral[rising]) > 0)
    assert np.all(np.diff(lateral[~rising]) < 0)


def test_speed_peak_and_depth_are_parameters(finger):
    moved = finger.with_params(peak_speed=0.1, speed_sensitivity=0.5)
    speeds = np.logspace(-3, 0, 3001)
    assert speeds[np.argmax(moved.speed_factor(speeds))] == pytest.approx(0.1, rel=0.01)
    assert moved.speed_factor(0.0) == pytest.approx(0.5)
    flat = finger.with_params(speed_sensitivity=0.0)
    np.testing.assert_allclose(flat.speed_factor(speeds), 1.0)


# -- occlusion: 0.36 -> 0.79 (Fig. 1.11) ---------------------------------------------------
def test_occlusion_rises_from_0_36_to_0_79(finger):
    # At Fn = 1 N and the peak speed the lateral force is the friction coefficient.
    state = {"normal_force": 1.0, "speed": finger["peak_speed"]}
    assert finger.forward(contact_time=0.0, **state) == pytest.approx(0.36)
    assert finger.forward(contact_time=math.inf, **state) == pytest.approx(0.79)
    assert finger.forward(contact_time=200.0, **state) == pytest.approx(0.79, abs=1e-4)
    # One time constant: 63 % of the way.
    assert finger.forward(contact_time=20.0, **state) == pytest.approx(
        0.79 - 0.43 / math.e, rel=1e-12
    )
    times = np.linspace(0, 120, 241)
    curve = finger.forward(contact_time=times, **state)
    assert np.all(np.diff(curve) > 0)
    # The documented time constant, fitted from the forward map's approach to the plateau.
    slope, intercept = np.polyfit(times, np.log(0.79 - curve), 1)
    assert -1.0 / slope == pytest.approx(20.0, rel=1e-6)
    assert math.exp(intercept) == pytest.approx(0.79 - 0.36, rel=1e-6)


def test_occlusion_time_is_a_parameter_and_decrease_is_allowed(finger):
    fast = finger.with_params(occlusion_time=5.0)
    assert fast.occlusion(5.0) == pytest.approx(0.79 - 0.43 / math.e)
    porous = finger.with_params(friction_initial=0.8, friction_occluded=0.5)
    values = porous.occlusion([0.0, 20.0, math.inf])
    assert values[0] == pytest.approx(0.8)
    assert values[2] == pytest.approx(0.5)
    assert values[1] < values[0]


def test_presets_give_the_thesis_forces():
    """Each preset against the thesis' numbers, the force written out here:
    F_l = mu(t) g(U) Fn^n with mu(t) = mu_occ - (mu_occ - mu_0) exp(-t / 20 s) and
    g(U) = 1 - 0.3 + 0.3 * 2 (U/40 mm/s) / (1 + (U/40 mm/s)^2)."""
    thesis = {
        # Smith and Scott [46] (Fig. 1.11): 0.36 -> 0.79; n = 0.91 (Fig. 2.32, 10th cycle).
        "occlusion-smith-scott": (0.36, 0.79, 0.91),
        # Section 2.9.2.2, Fig. 2.32: k_f = 0.49, n = 1.05 (1st cycle); 0.52, 0.91 (10th).
        "fig-2.32-cycle-1": (0.49, 0.49, 1.05),
        "fig-2.32-cycle-10": (0.52, 0.52, 0.91),
    }
    assert set(PRESETS) == set(thesis)
    fn = np.array([0.2, 0.5, 1.0, 2.0])[:, None, None]
    speed = np.array([0.01, 0.04, 0.12])[None, :, None]
    time = np.array([0.0, 20.0, 90.0])[None, None, :]
    ratio = speed / 0.040
    g = 0.7 + 0.3 * 2 * ratio / (1 + ratio**2)
    for name, (mu_0, mu_occ, n) in thesis.items():
        mu = mu_occ - (mu_occ - mu_0) * np.exp(-time / 20.0)
        expected = mu * g * fn**n
        got = FingerFriction.preset(name).forward(normal_force=fn, speed=speed, contact_time=time)
        np.testing.assert_allclose(got, expected, rtol=1e-12)
    # The default finger is the Smith-Scott occlusion preset.
    got = FingerFriction().forward(normal_force=fn, speed=speed, contact_time=time)
    mu_0, mu_occ, n = thesis["occlusion-smith-scott"]
    np.testing.assert_allclose(
        got, (mu_occ - (mu_occ - mu_0) * np.exp(-time / 20.0)) * g * fn**n, rtol=1e-12
    )
    with pytest.raises(PredictorError, match="preset"):
        FingerFriction.preset("nope")


# -- vectorised forward, inverse, profiles ---------------------------------------------------
def test_forward_broadcasts(finger):
    normal = np.array([0.2, 0.5, 1.0])[:, None, None]
    speed = np.array([0.01, 0.04, 0.12])[None, :, None]
    time = np.array([0.0, 10.0, math.inf])[None, None, :]
    lateral = finger.forward(normal_force=normal, speed=speed, contact_time=time)
    assert lateral.shape == (3, 3, 3)
    expected = finger.occlusion(time) * finger.speed_factor(speed) * normal**0.91
    np.testing.assert_allclose(lateral, expected, rtol=1e-14)


def test_inverse_gives_the_normal_force(finger):
    normal = np.array([0.05, 0.3, 1.0, 4.0])
    state = {"speed": 0.08, "contact_time": 7.0}
    lateral = finger.forward(normal_force=normal, **state)
    np.testing.assert_allclose(finger.inverse(lateral, **state), normal, rtol=1e-12)
    assert finger.inverse(0.0) == 0.0


def test_profile_round_trip(finger):
    changed = finger.with_params(load_index=0.75, occlusion_time=12.0)
    loaded = FingerFriction.from_profile(json.loads(json.dumps(changed.to_profile())))
    assert loaded.params == changed.params
    assert loaded.forward(normal_force=0.7, contact_time=3.0) == pytest.approx(
        changed.forward(normal_force=0.7, contact_time=3.0)
    )


# -- bad inputs ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("inputs", "name"),
    [
        ({"normal_force": -0.1}, "normal_force"),
        ({"normal_force": math.nan}, "normal_force"),
        ({"normal_force": math.inf}, "normal_force"),
        ({"normal_force": 0.5, "speed": -0.02}, "speed"),
        ({"normal_force": 0.5, "speed": math.nan}, "speed"),
        ({"normal_force": 0.5, "contact_time": -1.0}, "contact_time"),
        ({"normal_force": 0.5, "contact_time": math.nan}, "contact_time"),
    ],
)
def test_bad_inputs_are_refused(finger, inputs, name):
    with pytest.raises(PredictorError, match=name):
        finger.forward(**inputs)


def test_bad_targets_and_missing_inputs_are_refused(finger):
    with pytest.raises(PredictorError, match="target"):
        finger.inverse(-0.1)
    with pytest.raises(PredictorError, match="target"):
        finger.inverse(math.nan)
    with pytest.raises(PredictorError, match="normal_force"):
        finger.forward(speed=0.05)
    with pytest.raises(PredictorError, match="normal_force"):
        finger.friction_coefficient(normal_force=0.0)
