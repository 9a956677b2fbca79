"""The host-driven finger's physical speed comes from the host's sample times (FINGER
host_time_us), so transport jitter does not become friction noise in the simulated finger."""

from __future__ import annotations

import numpy as np
import pytest

from hcard_device.sim.finger import HOST_TIME_WRAP_S, HostFinger


def test_speed_is_timed_by_the_host_not_by_the_arrival():
    finger = HostFinger((80.0, 50.0))
    rng = np.random.default_rng(4)
    arrival = 0.0
    speeds = []
    for k in range(50):
        arrival += 0.01 + rng.uniform(-0.004, 0.004)  # 10 ms apart, with +-4 ms of jitter
        finger.update(arrival, 2.0 + 0.4 * k, 20.0, 0.5, True, host_t=0.01 * k)
        if k:
            speeds.append(finger.speed_m_s)
    np.testing.assert_allclose(speeds, 0.040, rtol=1e-9)  # 0.4 mm every 10 ms


def test_without_host_times_the_arrivals_time_the_move():
    finger = HostFinger((80.0, 50.0))
    finger.update(0.0, 2.0, 20.0, 0.5, True)
    finger.update(0.02, 3.0, 20.0, 0.5, True)
    assert finger.speed_m_s == pytest.approx(0.05)


def test_host_time_wraps_and_a_lift_stops_the_finger():
    finger = HostFinger((80.0, 50.0))
    finger.update(1.0, 2.0, 20.0, 0.5, True, host_t=HOST_TIME_WRAP_S - 0.005)
    finger.update(1.01, 2.4, 20.0, 0.5, True, host_t=0.005)  # 10 ms later, after the wrap
    assert finger.speed_m_s == pytest.approx(0.040)
    finger.update(1.02, 2.8, 20.0, 0.0, False, host_t=0.015)
    assert finger.speed_m_s == 0.0


def test_a_report_timed_ahead_of_the_frames_holds_from_its_time_on():
    """The served firmware times a FINGER at its arrival, ahead of the frames simulated so
    far: the frames before it keep the previous report, frame by frame."""
    finger = HostFinger((80.0, 50.0))
    finger.update(0.000, 2.0, 20.0, 0.5, True)
    finger.update(0.0105, 3.0, 20.0, 0.7, True)  # arrives between frames 105 and 106
    finger.update(0.0125, 4.0, 20.0, 0.0, False)  # lifts 2 ms later
    times = np.arange(100, 120) / 10_000  # frames of 0.1 ms, 10.0 to 11.9 ms
    truth = finger.state(times)
    before, after = times < 0.0105, times >= 0.0105
    np.testing.assert_array_equal(truth.x_mm, np.where(before, 2.0, 3.0))
    np.testing.assert_array_equal(truth.normal_force_n, np.where(before, 0.5, 0.7))
    np.testing.assert_allclose(truth.speed_m_s[after], 1.0 / 0.0105 * 1e-3)
    assert truth.speed_m_s[before].max() == 0.0  # the touch-down report had no speed
    np.testing.assert_allclose(truth.contact_time_s, times)  # one contact since 0 s
    later = finger.state(np.arange(120, 130) / 10_000)  # 12.0 to 12.9 ms: the lift at 12.5
    np.testing.assert_array_equal(later.contact, np.arange(120, 130) < 125)
    np.testing.assert_array_equal(later.normal_force_n[5:], 0.0)
    held = finger.state(np.arange(130, 140) / 10_000)  # nothing ahead: one state held
    assert held.held and not held.contact.any()
