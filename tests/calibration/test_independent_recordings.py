"""The loop on recordings it was not built from, and the generator against
the thesis.

The recordings come from ``independent_recordings.py`` (effects written from the thesis
formulas, not from the effect plugins). The generator's own physics is checked here against the
thesis numbers it cites, by a different computation (closed forms, regressions on the generated
forces); the loop is then asked to name the hidden effect, or none, on a few scenarios x 2 seeds.
``bench/bench_calibration_hit_rates.py`` runs the whole set.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.constants

from hcard.calibration.loop import calibrate
from hcard.calibration.results import NO_EFFECT, NOT_EXPLAINED
from hcard.plugins.registry import get_registry
from tests.helpers import independent_recordings as ir

SMALL = ir.Protocol(sessions=2, strokes_per_session=4, stroke_s=0.6)
"""A shorter protocol for the loop tests (2 sessions x 4 strokes of 0.6 s, 9 s at 1 kHz)."""

QUIET = ir.Noise(0.0, 0.0)


# -- the generator against the thesis ---------------------------------------------------------
def test_occlusion_rises_from_0_36_to_0_79_as_fig_1_11() -> None:
    assert ir.occlusion_mu0(np.array([0.0]))[0] == pytest.approx(0.36, abs=1e-12)
    assert ir.occlusion_mu0(np.array([1e4]))[0] == pytest.approx(0.79, abs=1e-9)
    # in a recording: where the plate does not vibrate (mu' = 1, Eq. 2.33 at Psi = inf) the
    # measured fl / fn is mu0 itself; compare with the first-order rise over accumulated contact
    m = ir.generate(ir.Scenario("uv", ("occlusion",)), 3, noise=QUIET)
    contact = m.normal_force > 0
    still = contact & (m.amplitude == 0)
    dt = float(m.t[1] - m.t[0])
    accumulated = np.cumsum(contact) * dt
    expected = 0.36 + 0.43 * (1 - np.exp(-accumulated / 20.0))
    measured = np.abs(m.lateral_force[still]) / m.normal_force[still]
    assert measured == pytest.approx(expected[still], rel=1e-9)
    # the rise is in the data: 16 s of contact (0.8 tau_o) climbs 55 % of the way to 0.79
    assert measured.min() < 0.37 and measured.max() > 0.59
    assert ir.occlusion_mu0(np.array([60.0]))[0] == pytest.approx(
        0.79 - 0.43 * math.exp(-3), rel=1e-12
    )


def test_load_index_reproduces_eq_2_35() -> None:
    m = ir.generate(ir.Scenario("uv", ("load-index",)), 4, noise=QUIET)
    still = (m.normal_force > 0) & (m.amplitude == 0)
    slope, intercept = np.polyfit(
        np.log(m.normal_force[still]), np.log(np.abs(m.lateral_force[still])), 1
    )
    assert slope == pytest.approx(0.8, abs=1e-9)  # n of Eq. 2.35
    assert math.exp(intercept) == pytest.approx(0.5, rel=1e-9)  # k_f
    # Fig. 2.32's fit (k_f = 0.52, n = 0.91) through the generator's law
    assert ir.load_index_force(np.array([2.0]), 0.52, 0.91)[0] == pytest.approx(
        0.52 * 2.0**0.91, rel=1e-12
    )


def test_ultrasonic_reduction_is_eq_2_33_with_eq_2_30() -> None:
    m = ir.generate(ir.Scenario("uv"), 5, noise=QUIET)
    moving = (m.normal_force > 0) & (m.amplitude > 0)
    psi = np.abs(m.speed[moving]) / (m.amplitude[moving] * 30e3 * 0.5 * 1.33)
    expected = 0.5 * m.normal_force[moving] * (1 - np.exp(-psi / 2.38))
    assert np.abs(m.lateral_force[moving]) == pytest.approx(expected, rel=1e-9)
    # the lateral force is signed by the direction of motion
    assert np.all(np.sign(m.lateral_force[moving]) == np.sign(m.speed[moving]))


def test_speed_effect_gives_fig_2_30s_fourfold_reduction_ratio() -> None:
    def reduction(speed: float) -> float:
        # Eq. 2.33 written here: 1 - mu' = exp(-Psi/Psi*), Psi = U / (w f mu0 (1 + nu))
        base = math.exp(-speed / (3e-6 * 30e3 * 0.5 * 1.33) / 2.38)
        return float(ir.speed_scaled_reduction(np.array([base]), np.array([speed]))[0])

    assert reduction(0.025) / reduction(0.100) == pytest.approx(4.0, rel=1e-9)
    assert ir.speed_exponent() < 0  # the reduction falls with speed (Fig. 2.21e)
    m = ir.generate(ir.Scenario("uv", ("speed",)), 8, noise=QUIET)
    plain = ir.generate(ir.Scenario("uv"), 8, noise=QUIET)
    sliding = (m.normal_force > 0) & (m.amplitude > 0)
    fast = sliding & (np.abs(m.speed) == 0.1)
    # faster than the 25 mm/s reference: less reduction, more friction than without the effect
    assert np.all(np.abs(m.lateral_force[fast]) > np.abs(plain.lateral_force[fast]))


def _effective_voltage(m) -> np.ndarray:
    """|v_e| from the friction of an EV recording: Eq. 3.13 and Eq. 3.12 solved for v."""
    coefficient = ir.EPS0 * ir.EV_AREA / (
        2 * (200e-6 / 1560 + 90e-6 / 3.35) * (200e-6 + 90e-6)
    )
    fe = np.abs(m.lateral_force) / 0.5 - m.normal_force
    return np.sqrt(np.maximum(fe, 0.0) / coefficient)


def test_charge_leakage_decays_with_tau_d_and_restarts_at_touch_down() -> None:
    m = ir.generate(ir.Scenario("ev", ("charge-leakage",)), 6, noise=QUIET)
    contact = m.normal_force > 0
    ve = _effective_voltage(m)
    dt = float(m.t[1] - m.t[0])
    # inside a contact, between voltage changes, v_e decays as exp(-t / 7.7 ms) (Eq. 3.22)
    steady = contact[1:] & contact[:-1] & (m.voltage[1:] == m.voltage[:-1])
    steady &= ve[:-1] > 50.0
    ratio = ve[1:][steady] / ve[:-1][steady]
    assert ratio == pytest.approx(math.exp(-dt / 7.7e-3), rel=1e-6)
    # at every touch-down the skin is uncharged: the force sees the whole applied voltage
    touch = np.flatnonzero(np.diff(contact.astype(int), prepend=0) == 1)
    assert ve[touch] == pytest.approx(np.abs(m.voltage[touch]), rel=1e-6)
    # a polarity flip inside a contact doubles the step: |v_e| just after it exceeds |v|
    flips = np.flatnonzero(contact[1:] & contact[:-1] & (m.voltage[1:] == -m.voltage[:-1])) + 1
    assert np.all(ve[flips] > np.abs(m.voltage[flips]))


def test_first_order_lag_is_the_exact_step_response() -> None:
    dt, tau = 1e-3, 15e-3
    command = np.ones(100)
    command[0] = 0.0  # the step at sample 1
    response = ir.first_order_lag(command, dt, tau)
    k = np.arange(100)
    expected = np.where(k >= 2, 1 - np.exp(-(k - 1) * dt / tau), 0.0)
    assert response == pytest.approx(expected, abs=1e-12)


def test_air_layer_is_eq_3_17() -> None:
    force = ir.electrostatic_force(np.array([1000.0]), np.array([25e-6]))[0]
    expected = scipy.constants.epsilon_0 * ir.EV_AREA * 1e6 / (
        2 * (200e-6 / 1560 + 25e-6 + 90e-6 / 3.35) * (200e-6 + 25e-6 + 90e-6)
    )
    assert force == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("seed", [1, 2])
def test_noise_white_and_ar1(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for noise, lag1 in ((ir.WHITE, 0.0), (ir.COLOURED, 0.9)):
        e = ir.sensor_noise(noise, 100_000, rng)
        assert np.std(e) == pytest.approx(1.5e-3, rel=0.05)
        assert np.corrcoef(e[1:], e[:-1])[0, 1] == pytest.approx(lag1, abs=0.02)


def test_nuisances_reach_the_recording() -> None:
    scenario = ir.Scenario("uv")
    clean = ir.generate(scenario, 7)
    messy = ir.generate(scenario, 7, nuisances=ir.ALL_NUISANCES)
    assert clean.stroke is None
    assert len(messy) == len(clean) - round(0.02 * len(clean))
    # the stroke column claims a stroke for lifted samples too
    lifted = messy.normal_force < 0.01
    assert lifted.sum() > 1000 and np.all(messy.stroke[lifted] >= 0)
    # the lateral zero drifts from 3 to 6 mN; the lifted samples show it
    early = lifted & (messy.t < 5)
    late = lifted & (messy.t > messy.t[-1] - 5)
    assert np.mean(messy.lateral_force[late]) - np.mean(messy.lateral_force[early]) > 2e-3
    data = ir.calibration_data(scenario, 7, nuisances=ir.ALL_NUISANCES, protocol=SMALL)
    assert any("stroke" in w for w in data.warnings)


def test_bad_scenarios_are_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"Scenario\.effects"):
        ir.Scenario("uv", ("charge-leakage",))
    with pytest.raises(ValueError, match=r"Scenario\.device"):
        ir.Scenario("pneumatic")
    with pytest.raises(ValueError, match=r"Noise\.ar1"):
        ir.Noise(1e-3, 1.0)
    with pytest.raises(ValueError, match=r"Protocol\.forces_n"):
        ir.Protocol(forces_n=())


# -- the loop on them -------------------------------------------------------------------------
def _loop(scenario: ir.Scenario, seed: int, noise: ir.Noise = ir.WHITE,
          nuisances: ir.Nuisances = ir.NO_NUISANCE, protocol: ir.Protocol = SMALL):
    registry = get_registry()
    data = ir.calibration_data(scenario, seed, noise=noise, nuisances=nuisances,
                               protocol=protocol)
    return calibrate(
        data,
        registry.get("predictor", ir.BASE_MODEL[scenario.device]),
        list(registry.calibration_effects.values()),
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_clean_white_noise_needs_no_effect(seed: int) -> None:
    result = _loop(ir.Scenario("uv"), seed)
    assert result.effects_added == ()
    assert result.verdict == NO_EFFECT, result.summary


@pytest.mark.parametrize("seed", [1, 2])
def test_clean_coloured_noise_needs_no_effect(seed: int) -> None:
    """Coloured sensor noise on clean data is not structure."""
    result = _loop(ir.Scenario("uv"), seed, noise=ir.COLOURED)
    assert result.effects_added == ()
    assert result.verdict == NO_EFFECT, result.summary


@pytest.mark.parametrize("seed", [1, 2])
def test_occlusion_on_mu0_is_named_through_the_nuisances(seed: int) -> None:
    result = _loop(ir.Scenario("uv", ("occlusion",)), seed, nuisances=ir.ALL_NUISANCES)
    assert result.effects_added == ("occlusion-drift",), result.summary
    # from well above the sensor noise (1.5 mN) down to it, through the drifting zero, the
    # stroke column carried through the lifts and the dropped rows
    assert result.before.test_rmse > 2 * ir.WHITE.sigma_n
    assert result.after.test_rmse < 1.15 * ir.WHITE.sigma_n


@pytest.mark.parametrize("seed", [1, 2])
def test_load_index_is_named(seed: int) -> None:
    result = _loop(ir.Scenario("uv", ("load-index",)), seed)
    assert result.effects_added == ("load-index",), result.summary
    fitted, sigma, _unit = result.effect_parameters("load-index")["load_index"]
    assert fitted == pytest.approx(ir.LOAD_INDEX, abs=max(0.05, 3 * sigma))


def test_direction_seen_through_the_stroke_count_is_not_credited_to_skin_recovery() -> None:
    """Friction 20 % higher towards -x, back-and-forth strokes that start each session the
    same way: the stroke count after a rest carries the direction, and skin-recovery cut the
    held-out error by more than 5 % (named in 2 of 8 bench runs, by a swap). With the
    direction's structure taken out it explains nothing: no effect, structure reported
    against the direction."""
    result = _loop(ir.Scenario("uv", ("direction",)), 1, protocol=ir.Protocol())
    assert result.effects_added == (), result.summary
    assert result.verdict == NOT_EXPLAINED
    assert "direction" in [item[0] for item in result.structure.regressors]


def test_a_speed_law_anchored_elsewhere_is_named_with_its_anchor() -> None:
    """The hidden law is (U / 25 mm/s)^a; with its anchor held at 20 mm/s the effect missed
    and a wrong load index was added (8 of 8 bench runs). Fitted, the anchor comes back."""
    result = _loop(ir.Scenario("uv", ("speed",)), 1, protocol=ir.Protocol())
    assert result.effects_added == ("ultrasonic-speed",), result.summary
    anchor, _sigma, unit = result.effect_parameters("ultrasonic-speed")["reference_speed"]
    assert unit == "m/s"
    assert anchor == pytest.approx(ir.SPEED_REFERENCE_M_S, rel=0.05)
