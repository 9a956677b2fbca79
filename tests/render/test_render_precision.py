"""The renderer's numbers against an independent double-precision rendering of spec/README.md
section 6 (tests/helpers/reference_render.py), on random cards and strokes and on long tracks whose
phases reach millions of turns.

R13 lets a renderer evaluate the cosine in single precision once the phase is reduced to one
turn: a few 1e-7 relative friction per unit of amplitude. The tolerance below allows 7e-7 per
unit of amplitude times the largest sum of amplitudes of a texture, plus the rounding of a
single-precision sum of the components: micro-units of relative friction, five orders of
magnitude below the 8% friction JND (thesis appendix B.1; spec/conformance.md A1) and over ten
times below the 1e-5 of the golden vectors (R13).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard import build
from hcard.render import Renderer, RenderOptions
from hcard.track import make_track, straight_stroke
from hcard.v1 import card_pb2 as pb
from tests.helpers.reference_render import reference_render

ERROR_PER_AMPLITUDE = 7e-7
"""Bound on a component's error, relative friction per unit of its amplitude."""
SUM_ERROR = 1e-7
"""Bound on the rounding of the single-precision sum over a texture's components."""


def tolerance(card) -> float:
    """The error bound of ``card``: its largest texture amplitude sum times the bound per unit
    of amplitude, plus the rounding of the sum."""
    largest = max(sum(c.amplitude for c in t.components) for t in card.textures)
    return ERROR_PER_AMPLITUDE * largest + SUM_ERROR


def random_card(seed: int, *, taxtel_mm: float = 5.0, textures: int = 6):
    """A 120 x 80 mm card of ``textures`` random 16-component textures (spatial and temporal,
    all three channels and lockings) on a random grid."""
    rng = np.random.default_rng(seed)
    palette = []
    for t in range(textures):
        components = []
        for _ in range(16):
            phase = float(rng.uniform(0, 2 * math.pi))
            amplitude = float(rng.uniform(0, 0.3))
            if rng.uniform() < 0.25:
                components.append(build.temporal(float(rng.uniform(5, 1200)), amplitude,
                                                 phase=phase))
            else:
                components.append(build.spatial(float(rng.uniform(0.02, 5.0)), amplitude,
                                                phase=phase,
                                                orientation=float(rng.uniform(-3.1, 3.1))))
        channel = ("uv", "ev", "bipolar")[t % 3]
        palette.append(build.texture({"uv": 0.6, "ev": 1.5, "bipolar": 1.0}[channel],
                                     components, channel=channel,
                                     locking=("auto", "velocity", "position")[t % 3]))
    cols, rows = math.ceil(120.0 / taxtel_mm), math.ceil(80.0 / taxtel_mm)
    return build.card(120.0, 80.0, taxtel_mm=taxtel_mm, textures=palette,
                      texture_index=rng.integers(0, textures, cols * rows))


def random_stroke(seed: int, seconds: float, speed_mm_s: float):
    """A wandering 50 Hz stroke with jittered sample times, a lift-off and a sensor dropout
    longer than the dead-reckoning horizon."""
    rng = np.random.default_rng(seed + 100)
    t = np.cumsum(rng.uniform(0.016, 0.024, int(seconds * 50)))
    x = 60 + 55 * np.sin(2 * np.pi * t * speed_mm_s / 700 + rng.uniform(0, 6))
    y = 40 + 35 * np.sin(2 * np.pi * t * speed_mm_s / 900 + rng.uniform(0, 6))
    x += rng.normal(0, 0.05, t.size)
    contact = ~((t > t[0] + 0.4 * seconds) & (t < t[0] + 0.5 * seconds))
    kept = ~((t > t[0] + 0.7 * seconds) & (t < t[0] + 0.75 * seconds))
    return make_track(t[kept], x[kept], y[kept], contact=contact[kept])


def assert_matches_reference(card, frames, reference) -> None:
    assert np.array_equal(frames.texture, reference.texture)
    bound = tolerance(card)
    for name in ("uv", "ev"):
        assert np.max(np.abs(getattr(frames, name) - getattr(reference, name))) <= bound, name
    assert np.max(np.abs(frames.friction - reference.uv * reference.ev)) <= 4 * bound


@pytest.mark.parametrize(("seed", "speed_mm_s"), [(0, 150.0), (1, 60.0), (2, 900.0)])
def test_random_cards_and_strokes_match_the_double_precision_rendering(seed, speed_mm_s):
    """Random 16-component textures, lift-off, dropout; at 900 mm/s many components are in the
    band limit's transition or above it."""
    card = random_card(seed)
    track = random_stroke(seed, 1.5, speed_mm_s)
    frames = Renderer(card).render(track)
    reference = reference_render(card, track.t, track.x, track.y, track.contact)
    assert (frames.texture >= 0).mean() > 0.5
    assert_matches_reference(card, frames, reference)


def test_a_texture_change_every_few_frames_matches_the_double_precision_rendering():
    """A fast diagonal stroke over 0.5 mm taxtels of six textures: runs of a few frames."""
    card = random_card(3, taxtel_mm=0.5)
    track = straight_stroke((2.0, 2.0), (180.0, 120.0), 0.4, rate_hz=120.0)
    frames = Renderer(card).render(track)
    assert np.count_nonzero(np.diff(frames.texture)) > 120  # one every 30 frames or fewer
    assert_matches_reference(card, frames, reference_render(
        card, track.t, track.x, track.y, track.contact))


def test_position_only_mode_matches_the_reference_map_lookup():
    """Position-only mode (spec 6.7): no dead reckoning, every spatial component position-locked
    and unfiltered, temporal components band-limited; checked against the reference rendering
    of the same card made position-locked, sampled at each touch sample."""
    card = random_card(4)
    for texture in card.textures:
        texture.locking = pb.LOCKING_POSITION
    track = random_stroke(4, 1.0, 150.0)
    frames = Renderer(card, RenderOptions(mode="position-only")).render(track)
    # the reference with H = 0 holds the sample's position; spatial band limit off: the
    # stroke is slow enough (k v < 0.8 B for every component up to 5 cycles/mm at 160 mm/s)
    reference = reference_render(card, track.t, track.x, track.y, track.contact, horizon_s=0.0)
    speed = np.hypot(np.diff(track.x), np.diff(track.y)) / np.diff(track.t)
    assert speed.max() * 5.0 < 800.0
    assert_matches_reference(card, frames, reference)


def test_phases_of_millions_of_turns_keep_their_precision():
    """An hour after touch-down a 1 kHz temporal component is 3.6e6 turns, and a 50 cycles/mm
    grating 9.98 m from the origin 5e5 turns: a phase formed in single precision would be off
    by a large fraction of a turn; here every frame is within the bound."""
    band = RenderOptions(band_limit_hz=2000.0)
    hour = 3600.0
    card = build.card(10_000.0, 40.0, taxtel_mm=(5_000.0, 40.0), textures=[
        build.texture(1.0, [build.temporal(1000.0, 0.3, phase=0.4),
                            build.temporal(333.3, 0.2)], channel="bipolar"),
        build.texture(0.7, [build.spatial(50.0, 0.1, phase=1.0, orientation=0.3),
                            build.spatial(7.3, 0.1, orientation=-1.1)],
                      channel="uv", locking="position"),
    ], texture_index=[0, 1])
    # held on texture 0 (x < 5 m) for an hour: one sample at touch-down, one just before
    held = make_track([0.0, hour - 0.01], [100.0, 100.0], [20.0, 20.0])
    # stroking texture 1 near the far edge at 60 mm/s, 50 Hz samples
    t = hour + np.arange(0, 0.3, 0.02)
    stroke = make_track(t, 9_975.0 + 60.0 * (t - hour), np.full(t.size, 20.0))
    renderer = Renderer(card, band)
    for track in (held, stroke):
        stream = renderer.stream(t0=hour)
        stream.push(track.t, track.x, track.y, contact=track.contact)
        frames = stream.render(2500)
        reference = reference_render(card, track.t, track.x, track.y, track.contact,
                                     band_limit_hz=2000.0, t0=hour, frames=np.arange(2500))
        assert (frames.texture >= 0).all()
        assert_matches_reference(card, frames, reference)
