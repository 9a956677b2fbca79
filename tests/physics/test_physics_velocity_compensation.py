"""Velocity compensation over the whole range a device plays, and the friction reported at any
speed.

The friction the commands give is checked against computations written here from the
equations, not against the code under test:

- the spring-slider of section 2.6 (Eqs. 2.19-2.28) by plain time stepping: the preload ``h``
  from the mean reaction found by root finding on sampled sinusoids (Eq. 2.28 as an average,
  not its closed form), then the lateral spring stepped through stick (``dx = U dt``) and slip
  (``kl x`` capped at ``mu0 F_reac``) and unloaded out of contact (Eq. 2.26);
- Eqs. 2.30 and 2.33 written out for the dimensionless group.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.optimize import brentq

import hcard
from hcard import build
from hcard.cli.main import cli
from hcard.physics import PredictorError
from hcard.physics.actuation import actuate
from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS, DeviceLimits
from hcard.physics.profile import DeviceProfile
from hcard.track import straight_stroke, track_to_csv
from hcard_builtins.physics.ultrasonic import SpringSlider

KN, KL, MU0 = 3.9e6, 1.5e6, 0.5  # Fig. 2.25 (spring-slider defaults)
PLATE = COUPLED_STIMULATOR_LIMITS.plate_frequency  # 38,220 Hz, section 4.2.1
FN = 0.5
NU, PSI_STAR = 0.33, 2.38  # Table 2.3; Fig. 2.24 (FE)
TOLERANCE = 0.005
"""Stated tolerance: rendered (time-stepped) relative friction within 0.005 of the target."""


def stepped_friction(amplitude: float, speed: float, *, steps: int = 20_000,
                     periods: int = 3) -> float:
    """``mu'`` of the massless spring-slider (Eqs. 2.19-2.28) by time stepping, at FN."""
    return stepped_friction_at(amplitude, speed, FN, steps=steps, periods=periods)


def stepped_friction_at(amplitude: float, speed: float, normal_force: float, *,
                        steps: int = 20_000, periods: int = 3) -> float:
    """``mu'`` of the massless spring-slider (Eqs. 2.19-2.28) by time stepping."""
    half = amplitude / 2
    if half <= normal_force / KN:  # Eq. 2.20: never loses contact, slips throughout
        return 1.0
    phase = 2 * math.pi * (np.arange(steps) + 0.5) / steps

    def excess(h: float) -> float:
        return float(np.maximum(KN * (half * np.sin(phase) + h), 0.0).mean()) - normal_force

    h = brentq(excess, -half, normal_force / KN, xtol=1e-18, rtol=1e-14)
    cap = MU0 * np.maximum(KN * (half * np.sin(phase) + h), 0.0) / KL  # compression cap, m
    step = speed / PLATE / steps
    compression = np.zeros(steps)
    x = 0.0
    for _ in range(periods):
        for k in range(steps):
            x = 0.0 if cap[k] <= 0 else min(x + step, cap[k])
            compression[k] = x
    return float(KL * compression.mean() / (MU0 * normal_force))


def eq_2_33(amplitude: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Eqs. 2.30 and 2.33 at the chapter-4 plate frequency (FE Psi* = 2.38)."""
    with np.errstate(divide="ignore"):
        psi = np.asarray(speed) / (np.asarray(amplitude) * PLATE * MU0 * (1 + NU))
    return np.where(np.asarray(amplitude) > 0, 1 - np.exp(-psi / PSI_STAR), 1.0)


def spring_slider_device(max_amplitude: float = 20e-6) -> DeviceProfile:
    limits = DeviceLimits(max_amplitude, 0.0, 250e-6, 440.0, PLATE)
    return DeviceProfile(SpringSlider(normal_stiffness=KN, lateral_stiffness=KL, mu0=MU0), limits)


SPEEDS = (5e-3, 20e-3, 50e-3, 100e-3)
TARGETS = (0.2, 0.3, 0.5, 0.8)


def test_spring_slider_compensation_lands_on_the_target_at_every_speed():
    device = spring_slider_device()
    speed, target = np.meshgrid(SPEEDS, TARGETS, indexing="ij")
    commands = actuate(device, target, 1.0, speed, FN)
    assert not commands.clipped, commands.summary()
    felt = np.vectorize(stepped_friction)(commands.amplitude, speed)
    # mu' drops at the critical amplitude 2 Fn/kn (Eq. 2.20) from 1 straight to the value just
    # above it (0.29 at 5 mm/s, 0.798 at 20 mm/s): targets in that gap have no amplitude.
    critical = 2 * FN / KN
    gap = np.array([stepped_friction(critical * (1 + 1e-6), u) for u in SPEEDS])[:, None]
    assert 0.25 < gap[0, 0] < 0.3 and 0.79 < gap[1, 0] < 0.8
    reachable = target <= gap
    assert int((~reachable).sum()) == 4  # 0.3, 0.5, 0.8 at 5 mm/s; 0.8 at 20 mm/s
    # Every reachable target lands within the stated tolerance, sub-um amplitudes included.
    np.testing.assert_allclose(felt[reachable], target[reachable], atol=TOLERANCE)
    assert commands.amplitude[reachable].min() < 0.5e-6
    assert not commands.uv_out_of_range.any()  # the spring-slider states no amplitude bound
    # The reported friction is the time-stepped one everywhere, unreachable frames included.
    np.testing.assert_allclose(commands.uv, felt, atol=TOLERANCE)
    assert commands.uv_range.unreachable == 4
    # An unreachable target gets the nearer side of the gap: no vibration or just above w_c.
    nearest = np.minimum(1 - target, np.abs(gap - target))[~reachable]
    assert commands.uv_range.worst_unreachable == pytest.approx(nearest.max(), abs=TOLERANCE)
    np.testing.assert_allclose(felt[~reachable], np.where(
        1 - target < np.abs(gap - target), 1.0, gap)[~reachable], atol=TOLERANCE)
    assert any("reaches at no amplitude" in line for line in commands.warnings)


def test_dimensionless_group_amplitudes_below_1_um_are_flagged():
    device = DeviceProfile.coupled_stimulator()
    speed, target = np.meshgrid(SPEEDS, TARGETS, indexing="ij")
    commands = actuate(device, target, 1.0, speed, FN)
    # The amplitude Eqs. 2.30/2.33 give, written out: w = U / (Psi f mu0 (1 + nu)).
    expected = speed / (-PSI_STAR * np.log(1 - target) * PLATE * MU0 * (1 + NU))
    below = expected < 1e-6  # the range the thesis states for Eq. 2.33 (sections 2.7.1, 2.10)
    assert 4 <= below.sum() < below.size
    np.testing.assert_array_equal(commands.uv_out_of_range, below)
    assert commands.uv_range.below_amplitude_range == int(below.sum())
    assert commands.uv_range.amplitude_minimum == 1e-6
    assert any("below 1 um" in line and "2.7.1" in line for line in commands.warnings)
    assert "below 1 um" in commands.summary()
    # Where it is flagged the closed form is off the spring-slider by far more than within
    # range: the flag marks the frames whose reported friction is not to be trusted.
    felt = np.vectorize(stepped_friction)(commands.amplitude, speed)
    clipped = commands.amplitude >= COUPLED_STIMULATOR_LIMITS.max_amplitude
    flagged_error = np.abs(felt - commands.uv)[below & ~clipped]
    assert flagged_error.max() > 0.15


# ------------------------------------------------------------- friction below the speed floor


def test_friction_below_the_speed_floor_is_that_of_the_actual_speed():
    device = DeviceProfile.coupled_stimulator()
    speed = np.array([0.0, 1e-3, 2e-3, 5e-3, 20e-3])
    commands = actuate(device, 0.5, 1.0, speed, FN)
    # The amplitude is chosen at the 5 mm/s floor for the slow fingers (Eq. 2.33 inverted
    # by hand), and at the finger speed above it.
    chosen_at = np.maximum(speed, 5e-3)
    amplitude = chosen_at / (-PSI_STAR * math.log(0.5) * PLATE * MU0 * (1 + NU))
    np.testing.assert_allclose(commands.amplitude, amplitude, rtol=1e-9)
    # The friction reported is Eq. 2.33 at the actual speed: 0 at rest, 1 - 0.5^(U/5 mm/s).
    felt = eq_2_33(commands.amplitude, speed)
    np.testing.assert_allclose(commands.uv, felt, atol=1e-12)
    np.testing.assert_allclose(commands.uv[:3], [0.0, 1 - 0.5**0.2, 1 - 0.5**0.4], atol=1e-12)
    assert commands.uv[2] == pytest.approx(0.242, abs=1e-3)
    np.testing.assert_allclose(commands.uv[3:], 0.5, atol=1e-12)
    assert commands.uv_range.below_speed_floor == 3
    assert commands.uv_range.worst_speed_shortfall == pytest.approx(0.5, abs=1e-12)
    assert any("slower than the speed floor" in line for line in commands.warnings)


def test_spring_slider_friction_below_the_floor_against_time_stepping():
    device = spring_slider_device()
    speed = np.array([1e-3, 3e-3])
    commands = actuate(device, 0.2, 1.0, speed, FN)
    # Amplitude of the floor (the 5 mm/s one for 0.2), friction of the slower finger.
    floor = float(actuate(device, 0.2, 1.0, 5e-3, FN).amplitude)
    np.testing.assert_allclose(commands.amplitude, floor, rtol=1e-12)
    felt = [stepped_friction(floor, u) for u in speed]
    np.testing.assert_allclose(commands.uv, felt, atol=TOLERANCE)
    assert np.all(commands.uv < 0.2 - 0.05)  # slower: less friction than the target


def test_spring_slider_inverse_refuses_what_it_cannot_solve():
    slider = SpringSlider()
    with pytest.raises(PredictorError, match="target relative_friction must be in"):
        slider.inverse(0.0, speed=0.02, frequency=PLATE, normal_force=FN)
    with pytest.raises(PredictorError, match="speed and frequency must be > 0"):
        slider.inverse(0.5, speed=0.0, frequency=PLATE, normal_force=FN)
    # mu' = 1 needs no vibration, even at rest.
    assert float(slider.inverse(1.0, speed=0.0, frequency=PLATE, normal_force=FN)) == 0.0


def test_clipping_is_flagged_per_frame_whatever_the_speed():
    device = DeviceProfile.coupled_stimulator()
    # uv = 0.05 needs more than 2.5 um at 20 mm/s (Eq. 2.33 by hand: 7.3 um); at rest the
    # amplitude of the floor (1.8 um) fits and the resting finger feels mu' = 0 (Psi = 0).
    speed = np.array([0.0, 20e-3, 20e-3])
    target = np.array([0.05, 0.05, 0.5])
    commands = actuate(device, target, [1.0, 1.0, 1.1], speed, FN)  # 0.05 N: 1330 V
    needed = np.maximum(speed, 5e-3) / (-PSI_STAR * np.log(1 - target) * PLATE * MU0 * (1 + NU))
    np.testing.assert_array_equal(commands.uv_clipped, needed > 2.5e-6)
    assert commands.uv_clipped.tolist() == [False, True, False]
    assert commands.uv[0] == 0.0 and commands.uv[1] > 0.05
    assert commands.ev_clipped.tolist() == [False, False, False]
    assert int(commands.uv_clipped.sum()) == commands.uv_clipping.clipped


def test_the_cli_shows_the_flag(tmp_path):
    """``hcard render --profile`` prints the out-of-range frames and the speed-floor shortfall."""
    grating = build.texture(
        0.75, [build.spatial(0.5, 0.15)], channel="uv", locking="position", name="grating"
    )
    card_path, track_path, profile_path = (
        tmp_path / "grating.hcard", tmp_path / "slow.csv", tmp_path / "device.json"
    )
    hcard.save(build.card(40.0, 10.0, taxtel_mm=10.0, textures=[grating]), card_path)
    # 10 mm/s: targets 0.6-0.9 need 0.1-0.5 um by Eq. 2.33, all below the 1 um of its range.
    track_path.write_text(track_to_csv(straight_stroke((2.0, 5.0), (10.0, 0.0), 1.0)))
    DeviceProfile.coupled_stimulator().save(profile_path)
    result = CliRunner().invoke(cli, [
        "render", str(card_path), "--track", str(track_path), "-o", str(tmp_path / "f.csv"),
        "--profile", str(profile_path),
    ])
    assert result.exit_code == 0, result.output
    flagged = [line for line in result.output.splitlines() if "below 1 um" in line]
    assert len(flagged) == 1 and "outside the UV model's range" in flagged[0]


def test_a_lifted_finger_needs_no_vibration_on_the_spring_slider():
    # Fn -> 0: the slider slips throughout, mu' -> 1 (time-stepped at 1e-4 N), so Fn = 0 gets
    # no vibration, mu' = 1, and is not reported as an unreachable target.
    assert stepped_friction_at(2e-6, 20e-3, 1e-4) == pytest.approx(1.0, abs=1e-3)
    device = spring_slider_device()
    commands = actuate(device, [0.5, 0.5], 1.0, 20e-3, [0.0, FN])
    assert commands.amplitude[0] == 0.0 and commands.uv[0] == 1.0
    assert commands.amplitude[1] > 0 and commands.uv[1] == pytest.approx(0.5, abs=1e-6)
    assert commands.uv_range.unreachable == 0 and not commands.warnings
