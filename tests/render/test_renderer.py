"""The hybrid renderer against analytic signals (spec/README.md section 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard import build
from hcard.errors import CardValidationError, TrackError
from hcard.render import Renderer, RenderOptions
from hcard.render.runs import band_limit_gain
from hcard.render.touch import _extend_block, empty_table, extend_table
from hcard.track import make_track, straight_stroke
from tests.helpers.signals import tone, wrap

FS = 10_000.0


def grating_card(k: float, amplitude: float, *, phase: float = 0.0, orientation: float = 0.0,
                 locking: str = "velocity", channel: str = "uv", baseline: float = 0.7,
                 width: float = 400.0, height: float = 400.0, taxtel: float = 5.0):
    texture = build.texture(
        baseline,
        [build.spatial(k, amplitude, phase=phase, orientation=orientation)],
        channel=channel,
        locking=locking,
    )
    return build.card(width, height, taxtel_mm=taxtel, textures=[texture])


def steady(frames, after_s: float = 0.05):
    """Frames from ``after_s`` after the start (past the first touch interval)."""
    keep = frames.t >= frames.t[0] + after_s
    return frames.t[keep] - frames.t[0], keep


@pytest.mark.parametrize("locking", ["velocity", "position", "auto"])
@pytest.mark.parametrize(
    ("k", "speed", "orientation_deg"), [(0.5, 80.0, 30.0), (2.0, 60.0, -75.0), (0.8, 150.0, 0.0)]
)
def test_swept_grating_renders_k_times_v(k, speed, orientation_deg, locking):
    """A grating swept along its wave vector at 50 Hz touch is a k*v Hz sinusoid with the
    analytic amplitude and phase (within 1%)."""
    theta = math.radians(orientation_deg)
    direction = np.array([math.cos(theta), math.sin(theta)])
    start = np.array([200.0, 200.0]) - direction * speed * 0.6
    amplitude, phase = 0.15, 0.9
    card = grating_card(k, amplitude, phase=phase, orientation=theta, locking=locking)
    track = straight_stroke(tuple(start), tuple(direction * speed), 1.2, rate_hz=50.0)
    frames = Renderer(card, RenderOptions(frame_rate_hz=FS)).render(track)
    t, keep = steady(frames)
    expected_phase = wrap(phase + 2 * math.pi * k * float(direction @ start))
    measured_a, measured_phi, residual = tone(t, frames.uv[keep], k * speed)
    assert measured_a == pytest.approx(amplitude, rel=0.01)
    assert abs(wrap(measured_phi - expected_phase)) < 0.01 * 2 * math.pi
    assert residual < 0.01 * amplitude  # nothing but that one tone


def test_dense_grating_texture_control_beats_position_only():
    """1 mm grating at 100 mm/s, 50 Hz touch: texture control renders the 100 Hz tone;
    position-only control samples the grating twice a period per touch sample and cannot."""
    card = grating_card(1.0, 0.2, locking="auto")
    track = straight_stroke((20.0, 50.0), (100.0, 0.0), 1.0, rate_hz=50.0)
    hybrid = Renderer(card, RenderOptions(frame_rate_hz=FS)).render(track)
    classic = Renderer(card, RenderOptions(frame_rate_hz=FS, mode="position-only")).render(track)
    t, keep = steady(hybrid)
    a_hybrid, _, _ = tone(t, hybrid.uv[keep], 100.0)
    a_classic, _, _ = tone(t, classic.uv[keep], 100.0)
    assert a_hybrid == pytest.approx(0.2, rel=0.01)
    assert a_classic < 0.01
    assert a_hybrid - a_classic > 0.19


def test_position_only_aliases_a_dense_grating():
    """At 110 mm/s the classic map lookup turns the 110 Hz grating into a 10 Hz staircase."""
    card = grating_card(1.0, 0.2, locking="position")
    track = straight_stroke((20.0, 50.0), (110.0, 0.0), 2.0, rate_hz=50.0)
    classic = Renderer(card, RenderOptions(mode="position-only")).render(track)
    t, keep = steady(classic)
    assert tone(t, classic.uv[keep], 110.0)[0] < 0.02
    assert tone(t, classic.uv[keep], 10.0)[0] > 0.15


def test_coarse_feature_is_rendered_by_position_only_too():
    """A 40 mm grating at 30 mm/s (0.75 Hz) is within the 25 Hz reach of a 50 Hz sensor."""
    card = grating_card(1 / 40.0, 0.2, locking="position")
    track = straight_stroke((20.0, 50.0), (30.0, 0.0), 4.0, rate_hz=50.0)
    classic = Renderer(card, RenderOptions(mode="position-only")).render(track)
    t, keep = steady(classic)
    assert tone(t, classic.uv[keep], 0.75)[0] == pytest.approx(0.2, rel=0.02)


@pytest.mark.parametrize("crossing_at_sample", [False, True])
def test_no_phase_jump_crossing_taxtels_with_the_same_texture(crossing_at_sample):
    """Phase increments per frame stay k*v/fs across a taxtel boundary (< 1e-6 rad)."""
    k, speed = 1.3, 70.0
    card = grating_card(k, 0.2, locking="velocity", width=40.0, height=10.0, taxtel=5.0)
    assert card.grid.cols == 8
    # Start so that the 25 mm boundary falls on a touch sample or between two.
    x0 = 25.0 - speed * (0.3 if crossing_at_sample else 0.307)
    track = straight_stroke((x0, 5.0), (speed, 0.0), 0.5, rate_hz=50.0)
    frames = Renderer(card).render(track, with_phase=True)
    t, keep = steady(frames)
    step_rad = np.diff(frames.phase[keep, 0]) * 2 * math.pi
    assert np.max(np.abs(step_rad - 2 * math.pi * k * speed / FS)) < 1e-6
    x = x0 + speed * t
    assert x.min() < 25.0 < x.max() < 40.0  # the stroke does cross the boundary
    assert not np.isnan(step_rad).any()


def test_phase_continues_through_another_texture():
    """Leaving texture 0 for texture 1 and coming back: texture 0 resumes in phase with the
    odometer, as if it had played all along."""
    k, speed = 2.0, 50.0
    grating = build.texture(0.7, [build.spatial(k, 0.2)], channel="uv", locking="velocity")
    flat = build.texture(0.9, channel="uv", locking="velocity")
    card = build.card(30.0, 10.0, taxtel_mm=10.0, textures=[grating, flat],
                      texture_index=[0, 1, 0])
    track = straight_stroke((2.0, 5.0), (speed, 0.0), 0.5, rate_hz=50.0)
    frames = Renderer(card).render(track)
    t, keep = steady(frames)
    uv, texture = frames.uv[keep], frames.texture[keep]
    x = 2.0 + speed * t
    first, back = (texture == 0) & (x < 10), (texture == 0) & (x > 20)
    assert first.any() and back.any() and (texture == 1).any()
    expected = 0.7 + 0.2 * np.cos(2 * math.pi * k * x)
    assert np.max(np.abs(uv[back] - expected[back])) < 1e-5
    assert np.all(np.abs(uv[texture == 1] - 0.9) < 1e-12)


@pytest.mark.parametrize("locking", ["velocity", "position"])
def test_sweep_along_the_ridges_is_constant(locking):
    """Moving perpendicular to the wave vector never changes the grating's phase."""
    card = grating_card(1.0, 0.2, orientation=0.0, locking=locking, phase=0.4)
    track = straight_stroke((100.3, 20.0), (0.0, 120.0), 1.0, rate_hz=50.0)
    frames = Renderer(card).render(track)
    assert np.ptp(frames.uv) < 1e-9
    assert frames.uv[0] == pytest.approx(0.7 + 0.2 * math.cos(2 * math.pi * 100.3 + 0.4), abs=1e-6)


def test_band_limit_gain_curve():
    """Unit gain below 0.8 B, zero from B, smoothstep between (spec rule R10)."""
    f = np.array([0.0, 799.0, 800.0, 900.0, 1000.0, 1500.0])
    np.testing.assert_allclose(band_limit_gain(f, 1000.0), [1, 1, 1, 0.5, 0, 0], atol=1e-12)


def test_component_above_band_limit_is_attenuated_not_aliased():
    """k*v above the band limit is cut by >= 20 dB; above Nyquist it leaves no alias tone,
    where plain sampling of the same grating would put a full-amplitude tone at 3 kHz."""
    amplitude = 0.2
    for k, speed, f_true, f_alias in ((1.0, 1500.0, 1500.0, None), (5.0, 1400.0, 7000.0, 3000.0)):
        card = grating_card(k, amplitude, locking="velocity", width=4000.0, taxtel=50.0)
        track = straight_stroke((100.0, 100.0), (speed, 0.0), 0.5, rate_hz=50.0)
        frames = Renderer(card, RenderOptions(band_limit_hz=1000.0)).render(track)
        t, keep = steady(frames)
        a_true = tone(t, frames.uv[keep], f_true)[0] if f_true < FS / 2 else 0.0
        assert 20 * math.log10(max(a_true, 1e-12) / amplitude) <= -20
        assert np.ptp(frames.uv[keep]) < 1e-9
        if f_alias is not None:
            assert tone(t, frames.uv[keep], f_alias)[0] < 1e-6
            naive = amplitude * np.cos(2 * math.pi * f_true * t)
            assert tone(t, naive, f_alias)[0] == pytest.approx(amplitude, rel=1e-3)


def test_in_band_and_transition_temporal_components():
    """Temporal components run from touch-down; 300 Hz passes whole, 900 Hz at half gain."""
    texture = build.texture(
        1.0, [build.temporal(300.0, 0.1, phase=0.5), build.temporal(900.0, 0.1)],
        channel="bipolar", locking="auto",
    )
    card = build.card(50.0, 50.0, taxtel_mm=10.0, textures=[texture])
    track = straight_stroke((10.0, 10.0), (20.0, 0.0), 1.0)
    frames = Renderer(card, RenderOptions(band_limit_hz=1000.0)).render(track)
    t = frames.t - frames.t[0]
    friction = frames.friction
    a300, phi300, _ = tone(t, friction, 300.0)
    assert a300 == pytest.approx(0.1, rel=0.01)
    assert abs(wrap(phi300 - 0.5)) < 0.01
    assert tone(t, friction, 900.0)[0] == pytest.approx(0.05, rel=0.01)


def test_bipolar_split_and_channel_clipping():
    """BIPOLAR values below 1 go to UV, above 1 to EV, and uv*ev is the texture."""
    bipolar = build.texture(1.0, [build.temporal(50.0, 0.3)], channel="bipolar")
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[bipolar])
    track = straight_stroke((5.0, 5.0), (1.0, 0.0), 0.2)
    frames = Renderer(card).render(track)
    expected = 1.0 + 0.3 * np.cos(2 * math.pi * 50.0 * (frames.t - frames.t[0]))
    np.testing.assert_allclose(frames.friction, expected, atol=1e-6)
    np.testing.assert_allclose(frames.uv, np.minimum(expected, 1.0), atol=1e-6)
    np.testing.assert_allclose(frames.ev, np.maximum(expected, 1.0), atol=1e-6)
    # A UV texture cannot raise friction: its swing above 1 is clipped, EV stays at 1.
    uv_only = build.texture(0.9, [build.temporal(50.0, 0.3)], channel="uv")
    frames = Renderer(build.card(10.0, 10.0, taxtel_mm=10.0, textures=[uv_only])).render(track)
    assert frames.uv.max() == pytest.approx(1.0) and np.all(frames.ev == 1.0)
    assert frames.uv.min() == pytest.approx(0.6, abs=1e-6)


def test_lift_off_and_leaving_the_surface_are_neutral():
    card = grating_card(1.0, 0.2, width=50.0, height=50.0, taxtel=5.0)
    t = np.arange(0, 1.0, 0.02)
    x = 10 + 60 * t  # leaves the 50 mm surface at t = 0.667 s
    contact = (t < 0.3) | (t >= 0.5)
    frames = Renderer(card).render(make_track(t, x, np.full_like(t, 25.0), contact=contact))
    tt = frames.t
    lifted = (tt >= 0.3) & (tt < 0.5)
    assert np.all(frames.uv[lifted] == 1.0) and np.all(frames.texture[lifted] == -1)
    outside = tt > 0.67
    assert np.all(frames.uv[outside] == 1.0) and np.all(frames.texture[outside] == -1)
    inside = (tt > 0.55) & (tt < 0.65)
    assert np.all(frames.texture[inside] == 0) and np.ptp(frames.uv[inside]) > 0.3


def test_dead_reckoning_stops_at_the_horizon():
    """When touch samples stop arriving, extrapolation ends after dead_reckoning_s."""
    card = grating_card(0.5, 0.2, locking="velocity")
    track = make_track([0.0, 0.02, 0.04, 0.5], [100.0, 101.0, 102.0, 102.0], [50.0] * 4)
    frames = Renderer(card, RenderOptions(dead_reckoning_s=0.1)).render(track)
    held = (frames.t > 0.15) & (frames.t < 0.5)
    assert np.ptp(frames.uv[held]) < 1e-12
    moving = (frames.t > 0.04) & (frames.t < 0.14)
    assert np.ptp(frames.uv[moving]) > 0.1


def test_batch_and_streaming_agree():
    """Streaming block by block gives the batch numbers to 1e-9, with lift-off in between."""
    rng = np.random.default_rng(3)
    textures = [
        build.texture(0.6, [build.spatial(1.2, 0.1, orientation=0.3),
                            build.spatial(0.05, 0.1, phase=1.0),
                            build.temporal(120.0, 0.05)], channel="uv", locking="auto"),
        build.texture(1.2, [build.spatial(0.7, 0.2, orientation=-1.0)], channel="bipolar",
                      locking="velocity"),
    ]
    card = build.card(60.0, 40.0, taxtel_mm=5.0, textures=textures,
                      texture_index=rng.integers(0, 2, 12 * 8))
    t = np.cumsum(rng.uniform(0.015, 0.025, 120))
    x = 30 + 25 * np.sin(t * 3.1) + rng.normal(0, 0.1, t.size)
    y = 20 + 15 * np.sin(t * 2.3)
    contact = ~((t > 1.0) & (t < 1.3))
    track = make_track(t, x, y, contact=contact)
    renderer = Renderer(card)
    batch = renderer.render(track)
    for block in (50, 137):
        stream = renderer.stream()
        parts, pushed = [], 0
        while sum(len(p) for p in parts) < len(batch):
            end_time = t[0] + (sum(len(p) for p in parts) + block - 1) / FS
            while pushed < len(t) and t[pushed] <= end_time:
                stream.push(t[pushed], x[pushed], y[pushed], contact=contact[pushed])
                pushed += 1
            parts.append(stream.render(min(block, len(batch) - sum(len(p) for p in parts))))
        uv = np.concatenate([p.uv for p in parts])
        ev = np.concatenate([p.ev for p in parts])
        assert np.max(np.abs(uv - batch.uv)) < 1e-9
        assert np.max(np.abs(ev - batch.ev)) < 1e-9
        assert np.array_equal(np.concatenate([p.texture for p in parts]), batch.texture)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_touch_samples_pushed_one_at_a_time_extend_the_table_as_the_vectorised_code(seed):
    """A stream extends its touch table one pushed sample at a time; that one-sample path of
    extend_table gives the vectorised code's numbers on the same sample, bit for bit: velocity,
    odometer, contact start and count through touch-downs, lifts and gaps longer than the
    dead-reckoning horizon (and the whole table agrees with one vectorised extension of all
    the samples to rounding: the odometer sums its steps in another order)."""
    rng = np.random.default_rng(seed)
    m = 200
    t = np.cumsum(rng.choice([0.004, 0.02, 0.15], m, p=[0.3, 0.6, 0.1]))
    position = np.column_stack((rng.normal(30, 5, m), rng.normal(20, 5, m)))
    contact = rng.uniform(size=m) > 0.2
    horizon = 0.1
    names = ("t", "position", "contact", "velocity", "odometer", "contact_start",
             "samples_in_contact")
    table = empty_table()
    for k in range(m):
        sample = (t[k : k + 1], position[k : k + 1], contact[k : k + 1], horizon)
        one, vectorised = extend_table(table, *sample), _extend_block(table, *sample)
        for name in names:
            assert getattr(one, name).dtype == getattr(vectorised, name).dtype
            np.testing.assert_array_equal(getattr(one, name), getattr(vectorised, name),
                                          err_msg=f"{name} of sample {k}")
        table = table.concat(one)
    batch = extend_table(empty_table(), t, position, contact, horizon)
    for name in names:
        np.testing.assert_allclose(getattr(table, name), getattr(batch, name), rtol=1e-12,
                                   atol=1e-12, err_msg=name)
    assert np.count_nonzero(batch.velocity) > m // 2  # moving samples were compared
    assert np.count_nonzero(batch.samples_in_contact == 0) > 10  # and touch-downs
    assert np.count_nonzero(np.diff(t) > horizon) > 5  # and gaps beyond the horizon


def test_invalid_inputs_are_refused():
    bad = grating_card(1.0, 0.2)
    bad.textures[0].components[0].frequency = -1.0
    with pytest.raises(CardValidationError, match="frequency"):
        Renderer(bad)
    with pytest.raises(TrackError, match="increase strictly"):
        make_track([0.0, 0.02, 0.02], [1, 2, 3], [1, 1, 1])
    with pytest.raises(ValueError, match="alias"):
        RenderOptions(frame_rate_hz=1000.0, band_limit_hz=1000.0)
    stream = Renderer(grating_card(1.0, 0.2)).stream()
    stream.push(1.0, 10.0, 10.0)
    with pytest.raises(TrackError, match="does not follow"):
        stream.push(0.5, 10.0, 10.0)


def test_streaming_in_blocks_of_any_size_gives_the_batch_numbers():
    """Blocks of 1 to 1000 frames, cutting runs of frames anywhere (the kernel advances each
    run's phase from an anchor frame that a block may not hold): the batch numbers to 1e-9
    (R12)."""
    rng = np.random.default_rng(5)
    textures = [
        build.texture(0.6 + 0.1 * i, [build.spatial(float(k), 0.05, orientation=0.5 * i + k)
                                      for k in (0.3, 1.1, 2.9)]
                      + [build.temporal(70.0 * (i + 1), 0.04)],
                      channel=("uv", "bipolar", "ev")[i % 3], locking="auto")
        for i in range(3)
    ]
    textures[2].baseline = 1.4
    card = build.card(60.0, 40.0, taxtel_mm=2.0, textures=textures,
                      texture_index=rng.integers(0, 3, 30 * 20))
    t = np.cumsum(rng.uniform(0.015, 0.025, 30))
    t[20:] += 0.2  # a dropout past the dead-reckoning horizon
    track = make_track(t, 30 + 20 * np.sin(t * 5.0), 20 + 10 * np.cos(t * 4.0))
    renderer = Renderer(card)
    batch = renderer.render(track)
    for block in (1, 7, 50, 255, 256, 300, 1000):
        stream = renderer.stream()
        stream.push(track.t, track.x, track.y)
        parts, done = [], 0
        while done < len(batch):
            parts.append(stream.render(min(block, len(batch) - done)))
            done += len(parts[-1])
        for name in ("uv", "ev"):
            streamed = np.concatenate([getattr(p, name) for p in parts])
            assert np.max(np.abs(streamed - getattr(batch, name))) <= 1e-9, (block, name)
        assert np.array_equal(np.concatenate([p.texture for p in parts]), batch.texture)


def test_a_track_whose_velocity_overflows_renders_its_frames_off_the_card_as_neutral():
    """Finite positions 1e300 mm apart 20 ms apart: the velocity estimate overflows and the
    dead-reckoned position is not a number there; those frames are off the card (neutral),
    the others render (the taxtel lookup used to index the grid with the cast of a NaN)."""
    card = grating_card(1.0, 0.2, width=100.0, height=100.0, taxtel=10.0)
    t = np.arange(10) * 0.02
    x = np.array([50.0, 50.0, 1e300, -1e300, 50.0, 50.0, 50.0, 1e307, 50.0, 50.0])
    with np.errstate(over="ignore", invalid="ignore"):
        frames = Renderer(card).render(make_track(t, x, np.full(10, 50.0)))
    assert np.isfinite(frames.uv).all() and np.isfinite(frames.ev).all()
    off = ((frames.t >= 0.04) & (frames.t < 0.08)) | ((frames.t >= 0.14) & (frames.t < 0.16))
    assert np.all(frames.texture[off] == -1) and np.all(frames.uv[off] == 1.0)
    assert np.all(frames.texture[frames.t < 0.04] == 0)
