"""The steps of :func:`hcard_device.sim.tribometer.synthesize`, each on a schedule written
here (the whole synthesis: test_tribometer.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hcard_device.sim.tribometer import (
    MIN_CONTACT_FORCE_N,
    REST_NOISE_LIMIT_N,
    _acting_drive,
    _lateral_force,
    _plan,
    _recorded_forces,
    _Schedule,
)

RATE_HZ = 1000.0


def schedule(n: int = 20) -> _Schedule:
    """``n`` samples at 1 kHz: lifted for the first 5, then sliding at 20 mm/s under 0.5 N,
    -x from sample 12; the amplitude steps from 0 to 2 um at sample 8; 300 V throughout."""
    t = np.arange(n) / RATE_HZ
    contact = np.arange(n) >= 5
    speed = np.where(contact, np.where(np.arange(n) >= 12, -0.02, 0.02), 0.0)
    return _Schedule(
        t=t,
        x=0.005 + np.cumsum(speed) / RATE_HZ,
        speed=speed,
        normal_force=np.where(contact, 0.5, 0.0),
        contact=contact,
        stroke=np.where(contact, 0, -1),
        amplitude=np.where(np.arange(n) >= 8, 2e-6, 0.0),
        voltage=np.full(n, 300.0),
    )


def test_the_plate_amplitude_follows_a_first_order_envelope() -> None:
    tau = 4e-3
    s = schedule()
    plan = _plan("uv", {"actuator-bandwidth": {"time_constant": tau}})
    amplitude, voltage = _acting_drive(plan, s, RATE_HZ)
    # zero-order hold: m samples after the step, 2 um (1 - exp(-m dt / tau))
    m = np.arange(12)
    assert amplitude[8:] == pytest.approx(2e-6 * (1.0 - np.exp(-m / (RATE_HZ * tau))),
                                          rel=1e-9, abs=1e-18)
    assert np.all(amplitude[:8] == 0.0) and np.all(voltage == 0.0)  # no electrodes on uv
    plain, _ = _acting_drive(_plan("uv", {}), s, RATE_HZ)
    assert np.array_equal(plain, s.amplitude)


def test_the_recorded_forces_carry_the_direction_the_zero_and_the_noise() -> None:
    s = schedule()
    lateral = np.where(s.contact, 0.2, 0.0)
    fl, fn = _recorded_forces(s, lateral, RATE_HZ, 0.0, 0.0, 0.0,
                              np.random.default_rng(1), np.random.default_rng(2))
    assert fl == pytest.approx(np.where(s.speed < 0, -1.0, 1.0) * lateral)  # rule MF3
    assert np.array_equal(fn, np.where(s.contact, 0.5, 0.0))
    # noise of 0.6 N: at least 11 mN in contact, within +-9 mN at rest
    fl, fn = _recorded_forces(s, lateral, RATE_HZ, 1e-3, 0.6, 0.0,
                              np.random.default_rng(1), np.random.default_rng(2))
    assert fn[s.contact].min() >= MIN_CONTACT_FORCE_N
    assert np.abs(fn[~s.contact]).max() <= REST_NOISE_LIMIT_N
    draws = np.random.default_rng(1).normal(size=(2, 20))  # lateral noise first, then normal
    signed = np.where(s.speed < 0, -1.0, 1.0) * lateral
    assert fl == pytest.approx(signed + 1e-3 * draws[0])
    assert fn[~s.contact] == pytest.approx(np.clip(0.6 * draws[1][~s.contact], -9e-3, 9e-3))


def test_a_worn_band_raises_the_friction_inside_it_and_none_is_felt_at_rest() -> None:
    s = schedule()
    inputs = {"speed": np.abs(s.speed), "normal_force": np.where(s.contact, 0.5, 1.0)}
    plan = _plan("uv", {"surface-patch": {"depth": 0.3, "x0": 0.0, "width": 0.02}})
    mu0 = plan.config.mu0
    lateral = _lateral_force(plan, s, inputs, np.full(20, 0.8), np.zeros(20))
    # x stays 4 mm or more inside the band [0, 20 mm]: the full depth, mu0 mu' Fn (1 + depth)
    assert lateral[s.contact] == pytest.approx(mu0 * 0.8 * 0.5 * 1.3)
    assert np.all(lateral[~s.contact] == 0.0)
    clean = _lateral_force(_plan("uv", {}), s, inputs, np.full(20, 0.8), np.full(20, 0.1))
    assert clean[s.contact] == pytest.approx(mu0 * 0.8 * 0.6)  # Eq. 4.1 with Eq. 3.1
