"""The simulated TX-1 against closed forms: the first-order envelope, the brake, the hardware
clamp, the watchdog, and the friction of thesis Eq. 2.33."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hcard.device.protocol import FaultBits

from acme_haptics.plate import TX1, AcmePlate, PlatePhysics, relative_friction

QUIET = PlatePhysics(amplitude_noise_m=0.0, force_noise_n=0.0)
DT = 1.0 / TX1.frame_rate_hz


def played(plate: AcmePlate, commands: np.ndarray, first: int = 0):
    plate.play(first, commands, np.zeros_like(commands))
    return plate.measure((first + len(commands) - 1) * DT)


def test_a_step_settles_as_one_minus_exp_minus_t_over_tau() -> None:
    plate = AcmePlate(physics=QUIET)
    m = played(plate, np.full(40, 2.0e-6))
    k = np.arange(1, 41)
    expected = 2.0e-6 * (1.0 - np.exp(-k * DT / QUIET.tau_s))  # ZOH: exact at frame ends
    np.testing.assert_allclose(m.amplitude_m, expected, rtol=1e-12)


def test_rise_time_is_tau_ln_9_and_bandwidth_follows() -> None:
    tau = 0.5e-3
    plate = AcmePlate(physics=replace(QUIET, tau_s=tau))
    m = played(plate, np.full(200, 1.0e-6))
    t10 = m.t_s[np.argmax(m.amplitude_m >= 0.1e-6)]
    t90 = m.t_s[np.argmax(m.amplitude_m >= 0.9e-6)]
    assert t90 - t10 == pytest.approx(tau * math.log(9), abs=DT)
    assert 1.0 / (2 * math.pi * tau) == pytest.approx(318.3, abs=0.1)  # the stated bandwidth


def test_a_lowered_command_is_met_in_one_frame_by_braking() -> None:
    plate = AcmePlate(physics=QUIET)
    played(plate, np.full(100, 3.0e-6))
    m = played(plate, np.full(5, 0.75e-6), first=100)
    assert m.amplitude_m[0] == pytest.approx(0.75e-6, rel=1e-9)
    free = AcmePlate(physics=replace(QUIET, brake_drive=0.0))
    played(free, np.full(100, 3.0e-6))
    m_free = played(free, np.full(5, 0.75e-6), first=100)
    a = math.exp(-DT / QUIET.tau_s)  # drive cut: free decay, a w
    settled = 3.0e-6 * (1 - math.exp(-100 * DT / QUIET.tau_s))
    assert m_free.amplitude_m[0] == pytest.approx(a * settled, rel=1e-6)


@pytest.mark.parametrize("command", [10e-6, math.inf, math.nan, -1e-6])
def test_the_hardware_clamp_holds_whatever_is_sent(command: float) -> None:
    plate = AcmePlate(physics=QUIET)
    m = played(plate, np.full(100, command))
    assert m.amplitude_m.max() <= TX1.max_amplitude_m * (1 + 1e-12)
    if command > TX1.max_amplitude_m:
        assert all(f & FaultBits.AMPLITUDE_LIMIT for f in m.faults)
        assert m.amplitude_m[-1] == pytest.approx(TX1.max_amplitude_m, rel=1e-9)
    else:
        assert m.amplitude_m.max() == 0.0


def test_the_watchdog_ramps_to_zero_after_frames_stop() -> None:
    plate = AcmePlate(physics=QUIET)
    played(plate, np.full(50, 2.0e-6))
    m = plate.measure(0.1)
    trip_s = 49 * DT + TX1.watchdog_s
    held = m.t_s < trip_s - DT / 2
    assert np.allclose(m.amplitude_m[held], 2.0e-6, rtol=1e-3)   # held for watchdog_s
    assert not any(f & FaultBits.WATCHDOG for f in m.faults[held])
    tripped = m.t_s > trip_s + DT / 2
    assert all(f & FaultBits.WATCHDOG for f in m.faults[tripped])
    off = m.t_s[np.argmax((m.amplitude_m < 50e-9) & tripped)] - trip_s
    assert 0 < off <= 2e-3                                         # a few tau of decay


def test_no_watchdog_before_the_first_frame() -> None:
    m = AcmePlate(physics=QUIET).measure(0.1)
    assert not any(m.faults) and m.amplitude_m.max() == 0.0


def test_relative_friction_is_eq_2_33_by_hand() -> None:
    # Psi = U / (w f mu0 (1 + nu)) = 0.1 / (2e-6 * 31500 * 0.55 * 1.33) = 2.16993...
    psi = 0.1 / (2e-6 * 31_500 * 0.55 * 1.33)
    assert psi == pytest.approx(2.16993, rel=1e-5)
    mu = relative_friction(np.array(2e-6), np.array(0.1), QUIET, 31_500)
    assert float(mu) == pytest.approx(1 - math.exp(-psi / 2.38), rel=1e-12)
    # at Psi = Psi* the friction has fallen by 1 - 1/e (Eq. 2.33's characteristic value)
    w_star = 0.1 / (2.38 * 31_500 * 0.55 * 1.33)
    assert float(relative_friction(np.array(w_star), np.array(0.1), QUIET, 31_500)) == \
        pytest.approx(1 - math.exp(-1), rel=1e-12)
    assert float(relative_friction(np.array(0.0), np.array(0.1), QUIET, 31_500)) == 1.0


def test_the_plate_and_the_published_profile_agree() -> None:
    """The plate's own Eq. 2.33 and hcard's dimensionless-group predictor (another
    implementation) give the same friction at the profile's parameters."""
    from acme_haptics.profile import Tx1Profile

    profile = Tx1Profile().profile()
    w = np.linspace(0.2e-6, 3e-6, 15)
    u = np.full_like(w, 0.06)
    uv, _ = profile.forward(w, np.zeros_like(w), u, np.full_like(w, 0.5))
    np.testing.assert_allclose(uv, relative_friction(w, u, QUIET, TX1.plate_frequency_hz),
                               rtol=1e-9)


def test_the_lateral_force_is_mu0_mu_prime_fn() -> None:
    plate = AcmePlate(physics=QUIET)
    for k in range(3):
        plate.touch(k * 0.01, 20.0 + 0.6 * k, 40.0, 0.5, True)   # 60 mm/s
    plate.play(0, np.full(400, 2.0e-6), np.zeros(400))
    m = plate.measure(399 * DT)
    mu = relative_friction(np.array(2.0e-6), np.array(0.06), QUIET, TX1.plate_frequency_hz)
    assert m.lateral_force_n[-1] == pytest.approx(0.55 * float(mu) * 0.5, rel=1e-6)
