"""Device profiles with effects (spec/device-profile.md): one format, effects on their channels,
rendering through them, and clear errors for bad and old files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hcard.physics.actuation import actuate
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_effects import FittedEffect, solve_decreasing
from hcard.physics.profile_error import ProfileError
from hcard.plugins.registry import get_registry
from hcard_builtins.physics.electrovibration import AirLayer

COUPLED = DeviceProfile.coupled_stimulator()
EFFECTS = get_registry().calibration_effects


def with_effects(profile: DeviceProfile, **effects: dict[str, float]) -> DeviceProfile:
    fitted = tuple(FittedEffect(EFFECTS[name.replace("_", "-")], values)
                   for name, values in effects.items())
    return profile.replace(effects=fitted)


def test_effects_go_to_the_channel_they_act_on():
    profile = with_effects(COUPLED, air_layer={"air_gap": 5e-6},
                           ultrasonic_speed={"speed_exponent": -0.5},
                           load_index={"load_index": 0.8})
    assert [f.channel for f in profile.effects] == ["ev", "uv", "finger"]
    assert [f.name for f in profile.effects_on("ev")] == ["air-layer"]
    assert profile.uv_channel is not profile.uv_model
    assert profile.ev_channel is not profile.ev_model


def test_air_layer_in_a_profile_is_eq_3_17_of_the_profile_layers():
    # Independent: the AirLayer predictor (Eq. 3.17) at the carrier-averaged voltage and the
    # gap d_a1 (1 N / Fn), against the profile's EV channel with the air-layer effect.
    profile = with_effects(COUPLED, air_layer={"air_gap": 8e-6})
    ev = profile.ev_model
    air = AirLayer(**{p.name: ev[p.name] for p in AirLayer.parameters if p.name in ev.params})
    voltage, force = np.array([500.0, 1000.0, 2000.0]), np.array([0.2, 0.5, 1.5])
    effective = profile.carrier_gain * voltage / math.sqrt(2.0)
    expected = air.forward(voltage=effective, air_gap=8e-6 / force)
    np.testing.assert_allclose(profile.force_for(voltage, force), expected, rtol=1e-9)


def test_finger_effects_leave_the_relative_friction_alone():
    profile = with_effects(COUPLED, load_index={"load_index": 0.7},
                           occlusion_drift={"gain": 1.0, "time_constant": 5.0})
    args = (np.array([0.0, 1e-6, 2e-6]), np.array([0.0, 800.0, 1500.0]), 0.05, 0.4)
    for got, want in zip(profile.forward(*args), COUPLED.forward(*args), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("exponent", [-0.8, -0.3, 0.4])
def test_uv_inverse_with_an_effect_solves_the_forward_map(exponent):
    profile = with_effects(COUPLED, ultrasonic_speed={"speed_exponent": exponent})
    target = np.array([0.2, 0.5, 0.8, 0.95])
    speed, force = np.array([0.02, 0.05, 0.1, 0.15]), 0.5
    amplitude = profile.amplitude_for(target, speed, force)
    # the effect caps the reduction at (U / 20 mm/s)^a: lower targets are out of reach
    reachable = target > 1.0 - np.minimum((speed / 0.02) ** exponent, 1.0)
    assert reachable.sum() >= 3
    np.testing.assert_allclose(profile.uv_for(amplitude, speed, force)[reachable],
                               target[reachable], atol=1e-9)
    assert np.all(amplitude[~reachable] == 8 * profile.limits.max_amplitude)
    assert actuate(profile, target, 1.0, speed, force).uv_clipping.clipped >= (~reachable).sum()
    # without the effect the closed form is used, and the bisection agrees with it
    closed = COUPLED.amplitude_for(target, speed, force)
    solved = solve_decreasing(lambda w: COUPLED.uv_for(w, speed, force), target, 1e-4)
    np.testing.assert_allclose(solved, closed, rtol=1e-9)


def test_ev_inverse_with_an_effect_renders_the_target_through_actuate():
    profile = with_effects(COUPLED, air_layer={"air_gap": 10e-6})
    ev_target = np.array([1.02, 1.05, 1.08])
    force = np.array([0.4, 0.6, 0.5])
    commands = actuate(profile, np.ones(3), ev_target, 0.05, force)
    np.testing.assert_allclose(commands.ev, ev_target, rtol=1e-9)
    plain = actuate(COUPLED, np.ones(3), ev_target, 0.05, force)
    assert np.all(commands.voltage > plain.voltage)  # the air layer needs more voltage
    # what the plain profile's voltages render on a finger with the air layer falls short
    short = profile.forward(0.0, plain.voltage, 0.05, force)[1]
    assert np.all(short < ev_target - 0.005)


def test_a_profile_clips_to_its_limits_whatever_the_effect_asks():
    profile = with_effects(COUPLED, air_layer={"air_gap": 100e-6})
    commands = actuate(profile, 1.0, 1.5, 0.05, 0.5)
    assert commands.voltage[()] == pytest.approx(profile.voltage_limit[0])
    assert commands.ev_clipping.clipped == 1


def test_round_trip_keeps_effects_uncertainties_and_calibration(tmp_path):
    fitted = FittedEffect(EFFECTS["air-layer"], {"air_gap": 7e-6}, {"air_gap": 3e-7})
    profile = COUPLED.replace(effects=(fitted,), observation={
        "output": "lateral_force", "parameters": {"force_offset": {"value": 1e-3, "unit": "N"}}},
        calibration={"verdict": "explained by added effects"})
    path = tmp_path / "profile.json"
    profile.save(path)
    again = DeviceProfile.load(path)
    assert again.to_dict() == profile.to_dict()
    assert again.effects[0].values == {"air_gap": 7e-6}
    assert again.effects[0].uncertainties == {"air_gap": 3e-7}
    assert json.loads(path.read_text())["effects"][0]["channel"] == "ev"


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda raw: raw["effects"].append({"name": "magic"}), "effects[1].name: unknown"),
        (lambda raw: raw["effects"][0].update(channel="uv"), "acts on 'ev'"),
        (lambda raw: raw["effects"][0]["parameters"]["air_gap"].update(value=-1.0),
         "outside its bounds"),
        (lambda raw: raw["effects"][0]["parameters"]["air_gap"].update(unit="um"),
         "air_gap.unit"),
        (lambda raw: raw.update(effects={}), "effects: must be a list"),
        (lambda raw: raw.update(observation={"output": "torque"}), "observation.output"),
        (lambda raw: raw.update(extra=1), "extra: unknown field"),
        (lambda raw: raw["effects"].append(raw["effects"][0]), "air-layer appear(s) twice"),
    ],
)
def test_bad_profiles_name_the_field(tmp_path, change, message):
    fitted = FittedEffect(EFFECTS["air-layer"], {"air_gap": 7e-6})
    raw = COUPLED.replace(effects=(fitted,)).to_dict()
    change(raw)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(raw))
    with pytest.raises(ProfileError) as info:
        DeviceProfile.load(path)
    assert "bad.json" in str(info.value) and message in str(info.value)


def test_an_effect_on_a_channel_the_model_lacks_is_refused():
    uv_only = DeviceProfile(get_registry().get("predictor", "dimensionless-group"),
                            COUPLED.limits.__class__(2.5e-6, 0.0, 1e-3, 440.0, 60750.0))
    with pytest.raises(ProfileError, match=r"act.* on the EV channel"):
        with_effects(uv_only, air_layer={"air_gap": 5e-6})


def test_a_profile_without_limits_describes_but_does_not_render():
    bare = DeviceProfile(get_registry().get("predictor", "ev-kaczmarek"), None)
    with pytest.raises(ProfileError, match="has no limits"):
        actuate(bare, 1.0, 1.2, 0.05, 0.5)
    finger = DeviceProfile(get_registry().get("predictor", "finger-friction"), None)
    assert finger.uv_model is None and finger.ev_model is None
