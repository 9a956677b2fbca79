"""Device profiles and model-based rendering: target relative friction per
channel to plate amplitude and EV voltage envelope, clipped and reported, velocity compensated."""

from __future__ import annotations

import json
import math
from typing import ClassVar

import numpy as np
import pytest

from hcard import build
from hcard.physics import Predictor, PredictorError, Variable
from hcard.physics.actuation import actuate, actuate_frames
from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS, DeviceLimits
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_error import ProfileError
from hcard.physics.profile_format import PROFILE_FORMAT
from hcard.quantities import EPSILON_0
from hcard.render import render
from hcard.track import straight_stroke
from hcard_builtins.physics.electrovibration import ChargeLeakage, FingerGeometry, Kaczmarek
from hcard_builtins.physics.finger import FingerFriction
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from tests.helpers.cards import two_texture_card
from tests.physics.test_physics_velocity_compensation import (
    TOLERANCE,
    spring_slider_device,
    stepped_friction,
)

EPS0 = EPSILON_0  # the value the code uses whatever the SciPy (tests/card/test_quantities.py)
AREA, D_SC, EPS_SC, D_I, EPS_I = 1e-4, 200e-6, 1560.0, 90e-6, 3.35
K_EV = EPS0 * AREA / (2 * (D_SC / EPS_SC + D_I / EPS_I) * (D_SC + D_I))
"""Eq. 3.12 written out: F_e / v^2 for the section 3.6 film, N/V^2."""
MU0, NU, PSI_STAR, PLATE, CARRIER = 0.5, 0.33, 2.38, 38_220.0, 440.0
FN = 0.5


def mu_closed_form(w, speed):
    """Eqs. 2.30 and 2.33 at the chapter-4 plate frequency."""
    psi = np.asarray(speed) / (np.asarray(w) * PLATE * MU0 * (1 + NU))
    return 1 - np.exp(-psi / PSI_STAR)


def amplitude_closed_form(target, speed):
    psi = -PSI_STAR * np.log(1 - np.asarray(target))
    return np.asarray(speed) / (psi * PLATE * MU0 * (1 + NU))


@pytest.fixture()
def stimulator() -> DeviceProfile:
    return DeviceProfile.coupled_stimulator()


# ------------------------------------------------------------------ velocity compensation


def _uv_card():
    # 0.35-0.75: inside what the spring-slider reaches at 20 mm/s (above 0.798 mu' jumps to 1
    # at the critical amplitude, tests/physics/test_physics_velocity_compensation.py).
    grating = build.texture(
        0.55, [build.spatial(0.5, 0.2)], channel="uv", locking="position", name="grating"
    )
    return build.card(40.0, 10.0, taxtel_mm=10.0, textures=[grating])


def test_velocity_compensation_renders_the_same_card_at_20_and_100_mm_s():
    """The card's UV grating, played through a spring-slider device at 20 and 100 mm/s, is felt
    as its targets at both speeds: checked by time stepping the spring-slider (Eqs. 2.19-2.28)
    in the test, an independent path from the model's closed-form contact integral."""
    device = spring_slider_device()
    card = _uv_card()
    rendered = {}
    for speed_mm_s in (20.0, 100.0):
        duration = 30.0 / speed_mm_s  # the same 30 mm of the card
        frames = render(card, straight_stroke((2.0, 5.0), (speed_mm_s, 0.0), duration))
        speed = speed_mm_s * 1e-3
        assert frames.uv.min() < 0.4 and frames.uv.max() > 0.7  # a real grating
        # Twelve frames across the grating's range (the numerical inverse costs ~1 ms a frame),
        # felt by the time-stepped slider.
        order = np.argsort(frames.uv)
        picked = order[np.linspace(0, order.size - 1, 12).astype(int)]
        commands = actuate(device, frames.uv[picked], 1.0, speed, FN)
        assert not commands.clipped and not commands.warnings, commands.summary()
        felt = [stepped_friction(float(w), speed) for w in commands.amplitude]
        np.testing.assert_allclose(felt, frames.uv[picked], atol=TOLERANCE)
        rendered[speed_mm_s] = (frames.uv[picked], commands)

    targets, commands_20 = rendered[20.0]
    commands_100 = rendered[100.0][1]
    # Five times faster needs more vibration (the spring-slider's own group, Eq. 2.29, has U / w).
    assert commands_100.amplitude.max() > 3 * commands_20.amplitude.max()
    # Uncompensated: the 20 mm/s amplitudes played to a finger at 100 mm/s feel different.
    uncompensated = [stepped_friction(float(w), 0.100) for w in commands_20.amplitude]
    assert np.max(np.abs(np.array(uncompensated) - targets)) > 0.1


def test_neutral_targets_get_no_vibration_and_no_voltage(stimulator):
    commands = actuate(stimulator, [0.5, 1.0], 1.0, 0.03, FN)
    assert commands.amplitude[0] > 0 and commands.amplitude[1] == 0.0
    assert commands.voltage.tolist() == [0.0, 0.0]
    np.testing.assert_allclose(commands.uv[1], 1.0)


def test_a_resting_finger_gets_the_amplitude_of_the_speed_floor(stimulator):
    commands = actuate(stimulator, 0.5, 1.0, [0.0, 0.002, 0.005], FN)
    assert commands.amplitude[0] == commands.amplitude[1] == commands.amplitude[2] > 0
    # The friction reported is the one at the actual speed (Eqs. 2.30, 2.33 written out):
    # a resting finger under vibration has Psi = 0 and mu' = 0; at 2 mm/s 1 - 0.5^0.4 = 0.242.
    np.testing.assert_allclose(
        commands.uv, mu_closed_form(commands.amplitude, [0.0, 0.002, 0.005]), atol=1e-12
    )
    np.testing.assert_allclose(commands.uv, [0.0, 1 - 0.5**0.4, 0.5], atol=1e-12)


# ------------------------------------------------------------------------------ EV channel


def test_voltage_envelope_accounts_for_the_sin2_carrier_mean(stimulator):
    ev = np.array([1.0, 1.05, 1.2])
    commands = actuate(stimulator, 1.0, ev, 0.02, FN)
    force = (ev - 1) * FN
    # <(V sin)^2> = V^2 / 2: V = sqrt(2 F / K).
    np.testing.assert_allclose(commands.voltage, np.sqrt(2 * force / K_EV), rtol=1e-12)
    np.testing.assert_allclose(commands.ev, ev, rtol=1e-12)
    t = np.arange(0, 0.5, 1 / 44_000.0)
    drive = commands.voltage_waveform(t[:, None])
    np.testing.assert_allclose(drive[:, 2], commands.voltage[2] * np.sin(2 * np.pi * 440 * t))
    # Time average of the Eq. 3.12 force under that carrier: the target force.
    np.testing.assert_allclose(np.mean(K_EV * drive**2, axis=0), force, rtol=1e-3, atol=1e-12)


def test_voltage_envelope_with_charge_leakage_meets_the_target_in_the_time_domain():
    leakage = ChargeLeakage()  # tau_d(f) = 7.7 ms (f / 10 Hz)^-0.7 (Figs. 3.13, 3.16)
    profile = DeviceProfile.coupled_stimulator(leakage=leakage)
    omega_tau = 2 * math.pi * CARRIER * 7.7e-3 * (CARRIER / 10.0) ** -0.7
    gain = omega_tau / math.sqrt(1 + omega_tau**2)  # |H| of Eq. 3.22 at 440 Hz: 0.833
    assert profile.carrier_gain == pytest.approx(gain, rel=1e-12)
    assert gain == pytest.approx(0.833, abs=1e-3)
    commands = actuate(profile, 1.0, 1.15, 0.02, FN)  # 1.2 would need 2258 V > 2000 V
    expected = math.sqrt(2 * 0.075 / K_EV) / gain
    assert float(commands.voltage) == pytest.approx(expected, rel=1e-12)
    assert not commands.clipped
    # Run Eqs. 3.22-3.23 on the drive: the steady-state mean force is (ev - 1) Fn = 0.075 N.
    fs = 220_000.0
    t = np.arange(0, 0.3, 1 / fs)
    result = leakage.simulate(t, float(commands.voltage) * np.sin(2 * np.pi * CARRIER * t))
    steady = result.force[t >= 0.2][: round(44 * fs / CARRIER)]  # 44 whole periods
    assert float(np.mean(steady)) == pytest.approx(0.075, rel=0.01)


def test_a_frequency_dependent_ev_model_gets_the_carrier_frequency():
    """ChargeLeakage as the EV model (input frequency) equals Kaczmarek plus leakage."""
    as_model = DeviceProfile(ChargeLeakage(), COUPLED_STIMULATOR_LIMITS)
    with_leak = DeviceProfile(Kaczmarek(), COUPLED_STIMULATOR_LIMITS, leakage=ChargeLeakage())
    ev = np.linspace(1.0, 1.2, 5)
    np.testing.assert_allclose(
        actuate(as_model, 1.0, ev, 0.02, FN).voltage,
        actuate(with_leak, 1.0, ev, 0.02, FN).voltage,
        rtol=1e-12,
    )
    with pytest.raises(ProfileError, match="count the leak twice"):
        DeviceProfile(ChargeLeakage(), COUPLED_STIMULATOR_LIMITS, leakage=ChargeLeakage())


# -------------------------------------------------------------------------------- clipping


def test_clipping_is_reported_per_channel_with_the_worst_shortfall(stimulator):
    uv = np.array([0.9, 0.05, 0.5, 1.0])
    ev = np.array([1.0, 1.0, 1.1, 4.0])
    commands = actuate(stimulator, uv, ev, 0.100, FN)
    # UV: 0.05 at 100 mm/s needs 32 um; the plate stops at 2.5 um, where mu' = 0.484.
    assert amplitude_closed_form(0.05, 0.1) == pytest.approx(32.4e-6, rel=0.01)
    assert commands.amplitude[1] == 2.5e-6
    assert commands.uv_clipping.clipped == 1 and commands.uv_clipping.fraction == 0.25
    assert commands.uv_clipping.limit == "max_amplitude"
    reached = float(mu_closed_form(2.5e-6, 0.1))
    assert commands.uv_clipping.worst_shortfall == pytest.approx(reached - 0.05, rel=1e-9)
    assert reached == pytest.approx(0.484, abs=1e-3)
    # EV: 4.0 needs 1.5 N; 2000 V peak gives K (2000^2 / 2) = 0.113 N, ev = 1.226.
    assert commands.voltage[3] == 2000.0
    assert commands.ev_clipping.clipped == 1 and commands.ev_clipping.limit == "max_voltage"
    reached_ev = 1 + K_EV * 2000.0**2 / 2 / FN
    assert commands.ev_clipping.worst_shortfall == pytest.approx(4.0 - reached_ev, rel=1e-9)
    assert reached_ev == pytest.approx(1.226, abs=1e-3)
    # Unclipped frames render their targets.
    np.testing.assert_allclose(commands.friction[[0, 2]], (uv * ev)[[0, 2]], rtol=1e-9)
    assert "1 of 4 frames (25.0%) clipped by max_amplitude" in commands.summary()


def test_the_current_limit_caps_the_voltage():
    # 250 uA into 100 pF at 440 Hz: V = I / (2 pi f C) = 904.3 V.
    profile = DeviceProfile.coupled_stimulator(load_capacitance=100e-12)
    assert profile.voltage_limit == (pytest.approx(904.29, abs=0.01), "max_current")
    commands = actuate(profile, 1.0, [1.04, 1.2], 0.02, FN)
    assert commands.voltage[0] == pytest.approx(math.sqrt(2 * 0.02 / K_EV), rel=1e-12)  # 841 V
    assert commands.voltage[1] == pytest.approx(904.29, abs=0.01)
    assert commands.ev_clipping.clipped == 1 and commands.ev_clipping.limit == "max_current"


def test_the_load_capacitance_comes_from_the_ev_layers(stimulator):
    # Eq. 3.8: C_i = 33 pF in series with C_sc = 6.9 nF (section 3.6.1) is 32.8 pF, so the
    # 250 uA limit is far away at 440 Hz: the 2000 V limit binds.
    assert stimulator.load_capacitance == pytest.approx(32.8e-12, rel=0.01)
    assert stimulator.voltage_limit == (2000.0, "max_voltage")


def test_an_ev_model_without_layers_needs_a_load_capacitance():
    with pytest.raises(ProfileError, match=r"limits\.load_capacitance: missing"):
        DeviceProfile(FingerGeometry(), COUPLED_STIMULATOR_LIMITS)
    limits = DeviceLimits(2.5e-6, 2000.0, 250e-6, 440.0, 38_220.0, load_capacitance=1e-9)
    profile = DeviceProfile(FingerGeometry(), limits)
    # 250 uA into 1 nF at 440 Hz caps the peak at 90.4 V.
    assert profile.voltage_limit == (pytest.approx(90.43, abs=0.01), "max_current")


def test_single_channel_profiles_report_the_missing_channel():
    limits = COUPLED_STIMULATOR_LIMITS
    uv_only = actuate(DeviceProfile(DimensionlessGroup(), limits), [0.5, 0.8], [1.0, 1.3], 0.02, FN)
    assert uv_only.ev_clipping.clipped == 1 and uv_only.ev_clipping.limit == "no EV channel"
    assert uv_only.ev_clipping.worst_shortfall == pytest.approx(0.3)
    assert uv_only.voltage.tolist() == [0.0, 0.0] and uv_only.uv_clipping.clipped == 0
    ev_only = actuate(DeviceProfile(Kaczmarek(), limits), [0.5, 1.0], [1.0, 1.1], 0.02, FN)
    assert ev_only.uv_clipping.clipped == 1 and ev_only.uv_clipping.limit == "no UV channel"
    assert ev_only.amplitude.tolist() == [0.0, 0.0] and ev_only.ev_clipping.clipped == 0


def test_bipolar_card_frames_drive_both_channels(stimulator):
    frames = render(two_texture_card(), straight_stroke((1.0, 5.0), (40.0, 0.0), 0.45))
    assert frames.ev.max() > 1.3 and frames.uv.min() < 1.0
    # 2000 V on a 440 Hz carrier adds 0.113 N: ev up to 1.57 at 0.2 N (1.23 at 0.5 N).
    commands = actuate_frames(stimulator, frames, 0.04, 0.2)
    assert not commands.clipped, commands.summary()
    np.testing.assert_allclose(commands.friction, frames.friction, rtol=1e-9)
    assert np.all((commands.voltage > 0) == (frames.ev > 1))
    assert np.all((commands.amplitude > 0) == (frames.uv < 1))


# ---------------------------------------------------------------------------- bad inputs


@pytest.mark.parametrize(
    ("uv", "ev", "speed", "fn", "message"),
    [
        (1.2, 1.0, 0.02, FN, "uv: UV target"),
        (-0.1, 1.0, 0.02, FN, "uv: UV target"),
        (0.5, 0.9, 0.02, FN, "ev: EV target"),
        (0.5, 1.0, -0.02, FN, "speed"),
        (0.5, 1.0, 0.02, -1.0, "normal_force"),
        (math.nan, 1.0, 0.02, FN, "uv: all values must be finite"),
        ([0.5, 0.6], [1.0, 1.1, 1.2], 0.02, FN, "do not broadcast"),
    ],
)
def test_bad_targets_and_finger_states_are_errors(stimulator, uv, ev, speed, fn, message):
    with pytest.raises(PredictorError, match=message):
        actuate(stimulator, uv, ev, speed, fn)


def test_profiles_need_an_invertible_model_with_v2_force():
    with pytest.raises(ProfileError, match="neither channel"):
        DeviceProfile(FingerFriction(), COUPLED_STIMULATOR_LIMITS)

    class LinearForce(Predictor):
        name: ClassVar[str] = "linear-force"
        inputs: ClassVar[tuple[Variable, ...]] = (Variable("voltage", "V"),)
        output: ClassVar[Variable] = Variable("electrostatic_force", "N")
        inverse_input: ClassVar[str | None] = "voltage"

        def _forward(self, **inputs: np.ndarray) -> np.ndarray:
            return 1e-4 * inputs["voltage"]

    with pytest.raises(ProfileError, match="does not go as v\\^2"):
        DeviceProfile(LinearForce(), COUPLED_STIMULATOR_LIMITS)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("max_voltage", -1.0, "limits.max_voltage: must be a finite number >= 0 V"),
        ("carrier_frequency", 0.0, "limits.carrier_frequency: must be a finite number > 0 Hz"),
        ("max_current", math.inf, "limits.max_current"),
        ("max_amplitude", "2um", "limits.max_amplitude: must be a number"),
    ],
)
def test_bad_limits_name_the_field(field, value, message):
    values = {
        "max_amplitude": 2e-6, "max_voltage": 1000.0, "max_current": 1e-4,
        "carrier_frequency": 440.0, "plate_frequency": 38_220.0,
    }
    values[field] = value
    with pytest.raises(ProfileError, match=message):
        DeviceLimits(**values)


# ---------------------------------------------------------------------------------- files


def test_save_and_load_round_trip(tmp_path):
    profile = DeviceProfile(
        predictor=DeviceProfile.coupled_stimulator().predictor.with_params(uv_psi_star=1.8),
        limits=DeviceLimits(3e-6, 1500.0, 200e-6, 500.0, 40_000.0, load_capacitance=50e-12),
        leakage=ChargeLeakage(tau_d=6e-3),
        name="bench",
        description="a fitted bench device",
    )
    path = tmp_path / "bench.json"
    profile.save(path)
    assert [p.name for p in tmp_path.iterdir()] == ["bench.json"]  # no temporary file left
    raw = json.loads(path.read_text())
    assert raw["format"] == PROFILE_FORMAT and raw["predictor"]["model"] == "coupled"
    assert raw["limits"]["max_amplitude"] == {"value": 3e-6, "unit": "m"}
    loaded = DeviceProfile.load(path)
    assert loaded.predictor.params == profile.predictor.params
    assert loaded.leakage is not None and loaded.leakage.params == profile.leakage.params
    assert loaded.limits == profile.limits
    assert (loaded.name, loaded.description) == ("bench", "a fitted bench device")
    target = np.array([0.3, 0.7]), np.array([1.1, 1.3])
    a, b = actuate(profile, *target, 0.03, FN), actuate(loaded, *target, 0.03, FN)
    np.testing.assert_array_equal(a.amplitude, b.amplitude)
    np.testing.assert_array_equal(a.voltage, b.voltage)


def test_limits_accept_units_in_a_hand_written_profile(tmp_path):
    raw = DeviceProfile.coupled_stimulator().to_dict()
    raw["limits"]["max_amplitude"] = "2 um"
    raw["limits"]["max_voltage"] = {"value": 1.5, "unit": "kV"}
    raw["limits"]["max_current"] = 2.5e-4
    path = tmp_path / "hand.json"
    path.write_text(json.dumps(raw))
    limits = DeviceProfile.load(path).limits
    assert (limits.max_amplitude, limits.max_voltage, limits.max_current) == (
        pytest.approx(2e-6), pytest.approx(1500.0), 2.5e-4
    )


def _broken(raw: dict, change) -> dict:
    change(raw)
    return raw


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda r: r["limits"].pop("max_voltage"), "limits.max_voltage: missing"),
        (lambda r: r["limits"].update(max_amplitude="2 kHz"), "limits.max_amplitude: .*Hz"),
        (lambda r: r["limits"].update(plate_frequency=-5), "limits.plate_frequency"),
        (lambda r: r["limits"].update(speed=1), "limits.speed: unknown field"),
        (lambda r: r.update(format="other/1"), "format: expected"),
        (lambda r: r.pop("predictor"), "predictor: missing"),
        (lambda r: r["predictor"].update(model="nope"), "predictor.model: no predictor .*nope"),
        (
            lambda r: r["predictor"]["parameters"]["uv_psi_star"].update(value=-2),
            "predictor.*uv_psi_star",
        ),
        (lambda r: r["predictor"]["parameters"].update(uv_psi_star="x"), "uv_psi_star"),
    ],
)
def test_bad_profile_files_name_the_file_and_the_field(tmp_path, change, message):
    path = tmp_path / "device.json"
    raw = _broken(DeviceProfile.coupled_stimulator().to_dict(), change)
    path.write_text(json.dumps(raw))
    with pytest.raises(ProfileError, match=message) as caught:
        DeviceProfile.load(path)
    assert str(caught.value).startswith(str(path))


@pytest.mark.parametrize(
    ("content", "message"), [(None, "no such file"), ("{not json", "not valid JSON"),
                             ("[1, 2]", "must be a JSON object")]
)
def test_unreadable_profile_files(tmp_path, content, message):
    path = tmp_path / "device.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ProfileError, match=message):
        DeviceProfile.load(path)
