"""A device profile as the model the loop fits (hcard.calibration.device_model, K14-K15):
against the thesis formulas computed here, with effects on their channels, with the finger
model, and fitted to tribometer recordings of the independent simulator."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.constants

from hcard.calibration.dataset import prepare
from hcard.calibration.device_model import FINGER_PREFIX, fitted_profile, profile_model
from hcard.calibration.loop import calibrate
from hcard.calibration.observation import lateral_force_model
from hcard.calibration.results import EXPLAINED
from hcard.physics.effects import augment
from hcard.physics.profile import DeviceProfile
from hcard.plugins.registry import get_registry
from hcard_device.sim.tribometer import Protocol, synthesize

EPS0 = scipy.constants.epsilon_0
COUPLED = DeviceProfile.coupled_stimulator()
LIBRARY = get_registry().calibration_effects
FINGER = get_registry().get("predictor", "finger-friction")


def thesis_total(amplitude, voltage, speed, fn, *, psi_star=2.38, area=1e-4, gain=1.0,
                 envelope=True):
    """Eq. 2.30-2.33 times Eq. 4.1 with Eq. 3.12, computed here from the formulas."""
    with np.errstate(divide="ignore"):
        psi = speed / (amplitude * 38_220.0 * 0.5 * (1 + 0.33))
    uv = np.where(amplitude > 0, 1.0 - np.exp(-psi / psi_star), 1.0)
    v = gain * voltage / (math.sqrt(2.0) if envelope else 1.0)
    d_e = 200e-6 / 1560.0 + 90e-6 / 3.35
    force = EPS0 * area * v**2 / (2 * d_e * (200e-6 + 90e-6))
    return uv * (1.0 + force / fn)


def test_the_profile_model_is_eq_4_1_of_its_channels():
    model = profile_model(COUPLED)
    amplitude = np.array([0.0, 1e-6, 2e-6, 0.5e-6])
    voltage = np.array([0.0, 500.0, 1500.0, 2000.0])
    speed, fn = np.array([0.02, 0.05, 0.1, 0.15]), np.array([0.3, 0.5, 1.0, 0.2])
    got = model.forward(amplitude=amplitude, voltage=voltage, speed=speed, normal_force=fn,
                        frequency=38_220.0)
    expected = thesis_total(amplitude, voltage, speed, fn, gain=COUPLED.carrier_gain)
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    instantaneous = profile_model(COUPLED, envelope=False)
    got = instantaneous.forward(amplitude=amplitude, voltage=voltage, speed=speed,
                                normal_force=fn)
    np.testing.assert_allclose(got, thesis_total(amplitude, voltage, speed, fn,
                                                 envelope=False), rtol=1e-9)
    assert set(model.calibrated) == {"uv_mu0", "uv_psi_star", "ev_area"}


def test_effects_go_to_their_channels_and_come_back_as_a_profile():
    model = augment(profile_model(COUPLED), [LIBRARY["air-layer"], LIBRARY["load-index"]])
    names = [p.name for p in model.parameters]
    assert "air-layer.air_gap" in names and "load-index.load_index" in names
    fitted = model.with_params(**{"air-layer.air_gap": 6e-6, "load-index.load_index": 0.8,
                                  "ev_area": 8e-5})
    profile = fitted_profile(fitted)
    assert [(f.name, f.channel) for f in profile.effects] == [("air-layer", "ev"),
                                                               ("load-index", "finger")]
    assert profile.predictor["ev_area"] == pytest.approx(8e-5)
    # the model's total is the profile's relative friction times the finger effect: Eq. 2.35
    # on the reaction force R = Fn + F_e = Fn ev (Eq. 3.1), not on Fn alone
    voltage, fn = np.array([800.0, 1600.0]), np.array([0.3, 0.9])
    uv, ev = profile.forward(0.0, voltage, 0.05, fn)
    assert np.all(ev > 1.01)
    total = fitted.forward(amplitude=0.0, voltage=voltage, speed=0.05, normal_force=fn)
    np.testing.assert_allclose(total, uv * ev * (fn * ev) ** (0.8 - 1.0), rtol=1e-9)


def test_what_a_profile_model_refuses():
    model = profile_model(COUPLED)
    why = LIBRARY["charge-leakage"].applies_to(model)
    assert why is not None and "carrier envelope" in why
    assert LIBRARY["charge-leakage"].applies_to(profile_model(COUPLED, envelope=False)) is None
    ev_only = DeviceProfile(get_registry().get("predictor", "ev-kaczmarek"), COUPLED.limits)
    assert "does not render" in LIBRARY["ultrasonic-speed"].applies_to(profile_model(ev_only))


def test_with_a_finger_model_the_output_is_the_lateral_force():
    model = profile_model(COUPLED, finger=FINGER)
    assert model.output.name == "lateral_force"
    assert "uv_mu0" not in model.calibrated
    assert f"{FINGER_PREFIX}load_index" in model.calibrated
    inputs = {"amplitude": 1e-6, "voltage": 1200.0, "speed": 0.05, "normal_force": 0.4,
              "contact_time": 2.0}
    relative = profile_model(COUPLED).forward(**{k: v for k, v in inputs.items()
                                                if k != "contact_time"})
    bare = FINGER.forward(normal_force=0.4, speed=0.05, contact_time=2.0)
    assert model.forward(**inputs) == pytest.approx(float(relative * bare), rel=1e-12)
    wrapped = lateral_force_model(model)
    assert [p.name for p in wrapped.parameters][-1] == "force_offset"
    assert "friction_coefficient" not in [p.name for p in wrapped.parameters]


@pytest.mark.parametrize(("air_gap", "seed"), [(8e-6, 1), (15e-6, 2)])
def test_the_loop_finds_an_air_layer_in_tribometer_recordings(air_gap, seed):
    # Independent data: the tribometer simulator's EV force is AirLayer (Eq. 3.17) of the
    # instantaneous voltage; the device profile is calibrated on it with its channels.
    recordings = synthesize(
        "ev", {"air-layer": {"air_gap": air_gap}},
        protocol=Protocol(duration_s=30.0, voltage_range_v=(400.0, 2000.0),
                          force_range_n=(0.1, 1.5)),
        lateral_noise_n=2e-3, normal_noise_n=2e-3, drift_n=2e-3, seed=seed)
    data = prepare(recordings)
    base = profile_model(COUPLED, envelope=False)
    result = calibrate(data, base, [LIBRARY[n] for n in ("air-layer", "load-index",
                                                         "occlusion-drift", "skin-recovery")])
    assert result.verdict == EXPLAINED and result.effects_added == ("air-layer",)
    value = result.after.fit.params["air-layer.air_gap"]
    sigma = result.after.fit.uncertainties["air-layer.air_gap"]
    assert abs(value - air_gap) < max(4 * sigma, 0.1 * air_gap)
    assert result.after.test_rmse < 0.5 * result.before.test_rmse
