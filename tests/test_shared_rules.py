"""Spec rules implemented once in the core and used by the device, simulation and conformance:
each shared function against the rule's text written out, and its users through it."""

from __future__ import annotations

import numpy as np
import pytest

from hcard.render.synthesis import channel_targets
from hcard.v1 import card_pb2 as pb
from hcard_device.sim.clip import texture_extremes


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
