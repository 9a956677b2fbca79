"""Spec rules implemented once in the core and used by the device, simulation and conformance:
each shared function against the rule's text written out, and its users through it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard.cli.render_cmd import finger_state
from hcard.physics.card_clipping import texture_extremes
from hcard.render.finger_speed import TouchSamples, predicted_speed
from hcard.render.synthesis import channel_targets
from hcard.render.touch import (
    empty_table,
    extend_table,
    has_velocity,
    speed_estimate,
    step_speed,
    velocity_estimate,
)
from hcard.track import make_track
from hcard.v1 import card_pb2 as pb
from hcard_conformance.device_checks.friction import track_speed
from hcard_conformance.metrics import sample_speeds
from hcard_conformance.vectors.tracks import contact_speeds
from hcard_device.sim.finger import HostFinger, TrackFinger


def _rule_r11(d_uv: float, d_ev: float, d_bi: float) -> tuple[float, float]:
    """spec/README.md R11, as written there."""
    def clamp(x: float, a: float, b: float) -> float:
        return min(max(x, a), b)
    m_uv, m_ev, m_bi = clamp(1 + d_uv, 0, 1), clamp(1 + d_ev, 1, 4), clamp(1 + d_bi, 0, 4)
    return m_uv * min(m_bi, 1), min(m_ev * max(m_bi, 1), 4)


def test_channel_targets_is_rule_r11_exactly():
    rng = np.random.default_rng(7)
    deviation = rng.uniform(-2.0, 4.0, size=(3, 500))
    deviation[:, :50] = 0.0  # groups a texture does not use
    before = deviation.copy()
    u, e = channel_targets(deviation)
    expected = np.array([_rule_r11(*column) for column in deviation.T])
    assert np.array_equal(u, expected[:, 0]) and np.array_equal(e, expected[:, 1])
    assert np.array_equal(deviation, before)  # the caller's array is not overwritten
    (u1,), (e1,) = channel_targets(np.array([-0.3, 0.5, 0.7]))
    assert (u1, e1) == pytest.approx((0.7, 1.5 * 1.7), abs=1e-15)


def _component(channel: int, amplitude: float) -> pb.Component:
    return pb.Component(domain=pb.DOMAIN_SPATIAL, frequency=1.0, amplitude=amplitude,
                        channel=channel)


def test_clip_report_extremes_follow_the_split():
    texture = pb.Texture(
        baseline=1.2, channel=pb.CHANNEL_BIPOLAR, locking=pb.LOCKING_POSITION,
        components=[_component(pb.CHANNEL_UV, 0.3), _component(pb.CHANNEL_EV, 0.5),
                    _component(pb.CHANNEL_UNSPECIFIED, 0.4)],
    )
    # troughs: UV 1 - 0.3, bipolar 1 + 0.2 - 0.4; crests: EV 1 + 0.5, bipolar 1 + 0.2 + 0.4
    assert texture_extremes(texture) == pytest.approx((0.7 * 0.8, 1.5 * 1.6), abs=1e-15)
    flat = pb.Texture(baseline=0.5, channel=pb.CHANNEL_UV, locking=pb.LOCKING_POSITION)
    assert texture_extremes(flat) == (0.5, 1.0)


def _track_samples(seed: int = 3, n: int = 40) -> tuple[np.ndarray, ...]:
    """Irregular touch samples: uneven intervals, accelerating motion, two contacts."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.005, 0.03, n))
    x = np.cumsum(rng.uniform(-2.0, 3.0, n)) + 50.0
    y = np.cumsum(rng.uniform(-1.0, 1.0, n)) + 30.0
    contact = np.ones(n, dtype=bool)
    contact[[0, 12, 13, 25]] = False
    return t, x, y, contact


def _rule_r4_velocity(t, x, y, contact) -> list[tuple[float, float]]:
    """spec/README.md R4, as written there: (p_i - p_(i-1)) / (t_i - t_(i-1)) if c_i and not
    d_i (a touch-down), else (0, 0)."""
    out = []
    for i in range(len(t)):
        touchdown = contact[i] and (i == 0 or not contact[i - 1])
        if contact[i] and not touchdown:
            dt = t[i] - t[i - 1]
            out.append(((x[i] - x[i - 1]) / dt, (y[i] - y[i - 1]) / dt))
        else:
            out.append((0.0, 0.0))
    return out


def test_velocity_and_speed_estimates_are_rule_r4():
    t, x, y, contact = _track_samples()
    expected = np.array(_rule_r4_velocity(t, x, y, contact))
    previous = np.concatenate(([False], contact[:-1]))
    displacement = np.stack((x - np.r_[0.0, x[:-1]], y - np.r_[0.0, y[:-1]]), axis=1)
    dt = t - np.r_[-np.inf, t[:-1]]
    velocity = velocity_estimate(displacement, dt, has_velocity(contact, previous))
    assert np.array_equal(velocity, expected)
    speed = speed_estimate(t, x, y, contact)
    np.testing.assert_allclose(speed, np.hypot(expected[:, 0], expected[:, 1]), rtol=1e-14)
    assert (speed[[0, 1, 12, 13, 14, 25, 26]] == 0).all() and (speed[[2, 15, 27]] > 0).all()
    for i in range(1, len(t)):
        moving = bool(contact[i] and contact[i - 1])
        assert step_speed(x[i] - x[i - 1], y[i] - y[i - 1], t[i] - t[i - 1], moving) == speed[i]


def test_the_renderer_table_and_the_simulated_fingers_use_rule_r4():
    t, x, y, contact = _track_samples()
    expected = np.array(_rule_r4_velocity(t, x, y, contact))
    table = extend_table(empty_table(), t, np.stack((x, y), axis=1), contact, 0.05)
    assert np.array_equal(table.velocity, expected)
    samples = TouchSamples(t, x, y, contact)
    speed, _, _ = samples.kinematics
    np.testing.assert_allclose(speed, np.hypot(expected[:, 0], expected[:, 1]), rtol=1e-14)

    host = HostFinger((200.0, 200.0))
    for i in range(3):
        host.update(t[i], x[i], y[i], 0.5, bool(contact[i]))
    segment = math.hypot(x[2] - x[1], y[2] - y[1]) / (t[2] - t[1]) * 1e-3
    assert host.speed_m_s == pytest.approx(segment, rel=1e-14)

    track = make_track(t, x, y, 0.5, contact)
    finger = TrackFinger(track, start_s=0.0, surface_mm=(200.0, 200.0))
    middle = (t[4] + t[5]) / 2 - t[0]  # in the segment from sample 4 to 5, in contact
    truth = finger.state(np.array([middle]))
    ends = math.hypot(x[5] - x[4], y[5] - y[4]) / (t[5] - t[4]) * 1e-3
    assert truth.speed_m_s[0] == pytest.approx(ends, rel=1e-14)
    assert track_speed(track, np.array([middle + t[0]]))[0] == pytest.approx(ends, rel=1e-14)


def _predicted_speed_written_out(t, x, y, contact, times, horizon_s) -> list[float]:
    """hcard.render.finger_speed.predicted_speed's docstring, written out sample by sample:
    the R4 speed of the latest sample at or before each time, extrapolated with the slope over
    two sensor periods (when the last three samples have an R4 estimate) from the middle of
    its interval over at most the horizon, never negative; 0 before the first sample."""
    r4 = [math.hypot(vx, vy) for vx, vy in _rule_r4_velocity(t, x, y, contact)]
    moving = [i > 0 and bool(contact[i] and contact[i - 1]) for i in range(len(t))]
    out = []
    for time in times:
        before = [i for i in range(len(t)) if t[i] <= time]
        if not before:
            out.append(0.0)
            continue
        i = before[-1]
        slope = ((r4[i] - r4[i - 2]) / (t[i] - t[i - 2])
                 if i >= 2 and moving[i] and moving[i - 1] and moving[i - 2] else 0.0)
        half = (t[i] - t[i - 1]) / 2 if i else 0.0
        out.append(max(r4[i] + slope * min(time - t[i] + half, horizon_s), 0.0))
    return out


def test_actuation_is_given_one_speed_estimate_by_the_command_line_and_the_device():
    """``hcard render --profile`` and the simulated device's firmware give actuation the same
    speed, :func:`hcard.render.finger_speed.predicted_speed`: what a device can know at each
    frame (the samples up to it), not the speed of the segment the frame falls in."""
    import hcard_device.sim.simulation as simulation

    t, x, y, contact = _track_samples()
    track = make_track(t, x, y, 0.5, contact)
    times = np.sort(np.r_[t, (t[:-1] + t[1:]) / 2, t[:-1] + 0.8 * np.diff(t), t[-1] + 0.02])
    horizon_s = 0.02
    speed_m_s, _ = finger_state(track, times, horizon_s)
    expected = _predicted_speed_written_out(t, x, y, contact, times, horizon_s)
    np.testing.assert_allclose(speed_m_s, np.array(expected) * 1e-3, rtol=1e-12, atol=1e-15)
    samples = TouchSamples.of_track(track)
    assert np.array_equal(speed_m_s, predicted_speed(samples, times, horizon_s) * 1e-3)
    assert simulation.predicted_speed is predicted_speed  # the device's is the same function

    # causal: moving the samples after a frame does not change the speed at that frame
    later = t > times[20]
    moved = make_track(t, np.where(later, x + 7.0, x), y, 0.5, contact)
    assert np.array_equal(finger_state(moved, times[:21], horizon_s)[0], speed_m_s[:21])


def test_the_conformance_speeds_are_rule_r4():
    t, x, y, contact = _track_samples()
    track = make_track(t, x, y, 0.5, contact)
    backward = np.hypot(np.diff(x), np.diff(y)) / np.diff(t)  # in contact or not
    np.testing.assert_allclose(sample_speeds(track), np.r_[backward[0], backward], rtol=1e-14)
    in_contact = contact[1:] & contact[:-1]
    np.testing.assert_allclose(contact_speeds(track), backward[in_contact], rtol=1e-14)
