"""The host's finger samples are placed on the device clock by their host times (PO2, protocol
1.1): reports that arrive late and in bursts render as if they had arrived on time."""

from __future__ import annotations

import numpy as np
import pytest

from hcard import build
from hcard.track import straight_stroke
from hcard_device.sim import DeviceConfig, DeviceSimulation, SimBlock
from hcard_device.sim.finger import HOST_TIME_WRAP_S
from hcard_device.sim.host_clock import REANCHOR_GAP_S, HostClock

SPEED_MM_S = 20.0
SAMPLE_S = 0.01
TRANSPORT_S = 0.001


def test_the_fastest_report_fixes_the_offset():
    clock = HostClock()
    assert clock.device_time(5.030, 0.000) == pytest.approx(5.030)  # first: anchored, late
    assert clock.device_time(5.031, 0.010) == pytest.approx(5.031)  # faster: offset 5.021
    assert clock.device_time(5.100, 0.020) == pytest.approx(5.041)  # late again: host spacing
    assert clock.device_time(5.100, 0.030) == pytest.approx(5.051)  # same arrival, 10 ms apart


def test_host_time_wraps_and_a_pause_anchors_again():
    clock = HostClock()
    clock.device_time(1.000, HOST_TIME_WRAP_S - 0.005)
    assert clock.device_time(1.010, 0.005) == pytest.approx(1.010)  # 10 ms later, after the wrap
    # after a pause longer than the re-anchoring gap the (late) report sets a new offset
    late = clock.device_time(3.500, 0.005 + REANCHOR_GAP_S + 0.5)
    assert late == pytest.approx(3.500)


def test_a_host_time_that_does_not_advance_gives_arrival_times():
    clock = HostClock()
    clock.device_time(2.0, 0.0)
    assert clock.device_time(2.25, 0.0) == 2.25
    assert clock.device_time(2.5, 0.0) == 2.5


def grating_card():
    grating = build.texture(
        0.7, [build.spatial(1.5, 0.25, channel="uv")], channel="uv", locking="position",
        name="grating",
    )
    return build.card(80.0, 40.0, taxtel_mm=40.0, textures=[grating],
                      texture_index=[0, 0])


def play(delivery_s: np.ndarray, seconds: float) -> SimBlock:
    """Targets of a host finger sliding at SPEED_MM_S, sampled every SAMPLE_S (host clock
    starting at 7 s), each sample applied at ``delivery_s[k]`` (device clock)."""
    sim = DeviceSimulation(DeviceConfig.evita(), seed=3)
    sim.load_card(grating_card())
    sim.start()
    n_frames = int(seconds * sim.config.frame_rate_hz)
    frame_of = np.ceil(delivery_s * sim.config.frame_rate_hz - 1e-9).astype(int)
    blocks, frame = [], 0
    for arrival in [*np.unique(frame_of[frame_of < n_frames]), n_frames]:
        blocks.append(sim.step(arrival - frame))
        frame = arrival
        for k in np.flatnonzero(frame_of == arrival):
            host_t = 7.0 + k * SAMPLE_S
            sim.host_finger(sim.time_s, 10.0 + SPEED_MM_S * k * SAMPLE_S, 20.0, 0.5, True,
                            host_time_s=host_t)
            sim.feed_watchdog()
    return SimBlock.concatenate(blocks)


@pytest.mark.parametrize("burst", [5, 9])
def test_bursts_render_like_reports_that_arrive_on_time(burst):
    """Samples every 10 ms; on time each arrives 1 ms after it was taken; in bursts, ``burst``
    samples arrive together 1 ms after the last of them was taken (the renderer dead-reckons
    up to 100 ms, longer than a burst). The finger moves at constant speed, so the targets
    must agree frame by frame once the second burst is in."""
    n = 100
    taken = np.arange(n) * SAMPLE_S
    on_time = play(taken + TRANSPORT_S, 0.9)
    last_of_burst = np.minimum((np.arange(n) // burst + 1) * burst - 1, n - 1)
    bursty = play(taken[last_of_burst] + TRANSPORT_S, 0.9)
    # the first burst of a session is squeezed (the offset is learnt as it arrives); from
    # the second on the clocks are tied
    settled = on_time.t_s >= (2 * burst * SAMPLE_S + TRANSPORT_S)
    assert np.ptp(on_time.target_uv[settled]) > 0.3  # the grating is rendered
    # (the offset may grow by 50 ppm of host time between the bursts: 0.5 us per sample,
    # a few thousandths of friction on this grating, far under the 0.08 JND)
    np.testing.assert_allclose(bursty.target_uv[settled], on_time.target_uv[settled], atol=5e-3)


def test_the_on_time_targets_follow_the_grating_under_the_finger():
    """The reference of the burst test is itself right: frame by frame the target is the
    grating at the finger's position (independent evaluation of the texture formula)."""
    n = 100
    taken = np.arange(n) * SAMPLE_S
    block = play(taken + TRANSPORT_S, 0.9)
    t = block.t_s
    settled = t >= 0.02
    # the sample taken at k*10 ms is on the device clock 1 ms later: position at frame time
    x = 10.0 + SPEED_MM_S * (t - TRANSPORT_S)
    expected = 0.7 + 0.25 * np.cos(2 * np.pi * 1.5 * x)
    error = np.abs(block.target_uv[settled] - np.clip(expected[settled], 0.0, 1.0))
    assert np.percentile(error, 95) < 0.02


def stroke(sim: DeviceSimulation, x0: float, host_t0: float, n: int = 30) -> SimBlock:
    """START, a 30-sample host stroke at SPEED_MM_S from ``x0`` (host clock from
    ``host_t0``, each sample applied 1 ms after it was taken), STOP; the frames."""
    sim.start()
    blocks = []
    for k in range(n):
        blocks.append(sim.step(round(TRANSPORT_S * sim.config.frame_rate_hz)))
        sim.host_finger(sim.time_s, x0 + SPEED_MM_S * k * SAMPLE_S, 20.0, 0.5, True,
                        host_time_s=host_t0 + k * SAMPLE_S)
        sim.feed_watchdog()
        blocks.append(sim.step(round((SAMPLE_S - TRANSPORT_S) * sim.config.frame_rate_hz)))
    sim.stop()
    return SimBlock.concatenate(blocks)


def test_start_begins_a_session_whose_first_sample_is_a_touch_down():
    """PO4a: a device that stays powered renders a second stroke, which starts 40 mm to the
    right of where the first ended, exactly as a fresh device renders it; without it the
    renderer takes the gap for a move of 40 mm in 0.2 s and dead-reckons off the grating."""
    powered = DeviceSimulation(DeviceConfig.evita(), seed=3)
    powered.load_card(grating_card())
    stroke(powered, 10.0, 7.0)
    powered.step(2000)  # 0.2 s between the sessions
    second = stroke(powered, 56.0, 7.5)
    fresh = DeviceSimulation(DeviceConfig.evita(), seed=3)
    fresh.load_card(grating_card())
    alone = stroke(fresh, 56.0, 7.5)
    assert np.ptp(alone.target_uv) > 0.3
    np.testing.assert_allclose(second.target_uv, alone.target_uv, atol=1e-9)


def velocity_locked_card():
    """A 2.5 mm velocity-locked grating with a 250 Hz temporal component: both phases depend
    on the renderer's time line (odometer, time since touch-down), none on absolute position."""
    texture = build.texture(
        0.55,
        [build.spatial(0.4, 0.2, channel="uv"), build.temporal(250.0, 0.1, channel="uv")],
        channel="uv", locking="velocity", name="fine",
    )
    return build.card(80.0, 40.0, taxtel_mm=40.0, textures=[texture], texture_index=[0, 0])


def stroke_with_transport(first_delay_s: float, delay_s: float) -> SimBlock:
    """A host stroke at 100 mm/s, sampled every 20 ms (host clock from 7 s): sample 0 reaches
    the fresh device ``first_delay_s`` after it was taken, every later one ``delay_s``."""
    sim = DeviceSimulation(DeviceConfig.evita(), seed=3)
    sim.load_card(velocity_locked_card())
    sim.start()
    rate = sim.config.frame_rate_hz
    blocks, frame = [], 0
    for k in range(40):
        arrival = k * 0.02 + (first_delay_s if k == 0 else delay_s)
        due = round(arrival * rate)
        blocks.append(sim.step(due - frame))
        frame = due
        sim.host_finger(sim.time_s, 10.0 + 100.0 * k * 0.02, 20.0, 0.5, True,
                        host_time_s=7.0 + k * 0.02)
        sim.feed_watchdog()
    blocks.append(sim.step(round(0.8 * rate) - frame))
    return SimBlock.concatenate(blocks)


def test_a_clock_offset_learnt_mid_stroke_leaves_no_lead_on_the_host_time_line():
    """PO2 learns the clock offset from the fastest report: here sample 0 travelled 0.5 ms
    longer than the rest, so the offset falls by 0.5 ms when sample 1 arrives. The device must
    still render on the host's time line (what the echo age maps its reports to, PI3): its
    targets at device time T are the batch render of the same track at host time T - offset,
    the final offset. Rendering on the device's placements instead took the shortened first
    interval into the odometer and led by 0.5 ms for the rest of the stroke."""
    from hcard.render import render
    from hcard.track import make_track

    block = stroke_with_transport(0.0015, 0.0010)
    k = np.arange(40)
    track = make_track(k * 0.02, 10.0 + 100.0 * k * 0.02, np.full(40, 20.0), 0.5, True)
    golden = render(velocity_locked_card(), track)
    settled = (block.t_s >= 0.045) & (block.t_s <= 0.78)  # from the third sample on

    def error_at(lag_s: float) -> float:
        # the final offset: device time = host time - 7 s + 1 ms
        host_t = block.t_s[settled] - 0.001 + lag_s
        expected = np.interp(host_t, golden.t, golden.friction)
        return float(np.sqrt(np.mean((block.target_uv[settled] - expected) ** 2)))

    assert np.ptp(block.target_uv[settled]) > 0.5  # both components are rendered
    # dead reckoning at constant speed is exact: on the host time line the targets agree
    assert error_at(0.0) < 0.01
    # the comparison can fail: half a millisecond off the time line is far outside it
    assert error_at(0.0005) > 10 * error_at(0.0)


def test_the_internal_finger_takes_over_from_a_host_time_line_ahead_of_the_device():
    """The first host sample arrives late (its offset fixes the render time line), later ones
    travel faster, so the host's samples are rendered ahead of the device clock; then the
    touch source switches to the internal panel (CONTROL SET_TOUCH_SOURCE internal). The
    panel's samples are timed by the device clock, behind the host's last one: the switch
    starts a new render time line (a new finger), instead of the stream refusing the panel's
    samples as out of order and stopping a served device. The internal stroke then renders
    as it does on a device that never had a host finger."""
    late_s = 0.030
    switched = DeviceSimulation(DeviceConfig.evita(), seed=3)
    switched.load_card(grating_card())
    switched.start()
    for k in range(20):
        switched.step(round(SAMPLE_S * switched.config.frame_rate_hz))
        delay = late_s if k == 0 else TRANSPORT_S
        switched.host_finger(switched.time_s, 10.0 + SPEED_MM_S * k * SAMPLE_S, 20.0, 0.5, True,
                             host_time_s=7.0 + k * SAMPLE_S - delay)
        switched.feed_watchdog()
    assert switched._render_shift_s > 0.02  # the host's time line runs ahead of the device
    track = straight_stroke((20.0, 20.0), (SPEED_MM_S, 0.0), 1.0, rate_hz=200.0, normal_force_n=0.5,
                            t0=0.0)
    switched.use_internal_finger(track)
    fresh = DeviceSimulation(DeviceConfig.evita(), seed=3)
    fresh.load_card(grating_card())
    fresh.start()
    fresh.step(switched._frame)  # the same device time and frame count
    fresh.use_internal_finger(track)
    after_switch = switched.step(3000)
    reference = fresh.step(3000)
    touching = reference.touch["contact"] if reference.touch.shape[0] else None
    assert touching is None or touching.any()
    in_contact = reference.t_s >= reference.t_s[0] + 0.05  # once the panel has two samples
    assert np.ptp(reference.target_uv[in_contact]) > 0.3  # the grating is rendered
    np.testing.assert_allclose(after_switch.target_uv[in_contact],
                               reference.target_uv[in_contact], atol=1e-9)
