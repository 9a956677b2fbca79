"""Taxtel crossings (hcard/render/crossings.py): the texture of every frame, found from a
search for the frames where the finger enters another taxtel, against the frame-by-frame lookup
of an independent double-precision rendering (tests/helpers/reference_render.py, spec/README.md
R5-R7), and the search itself against an exhaustive one from deliberately wrong guesses."""

from __future__ import annotations

import numpy as np
import pytest

from hcard import build
from hcard.render import Renderer, RenderOptions
from hcard.render.compiled import compile_card
from hcard.render.crossings import Line, first_reached
from hcard.track import make_track
from tests.helpers.reference_render import reference_render


def checker_card(taxtel_mm: tuple[float, float], textures: int = 5, seed: int = 0):
    """A 20 x 14 mm card of one-component textures on taxtels of ``taxtel_mm`` (not square,
    pitches that are not binary fractions, so cell edges round), each taxtel a random texture."""
    rng = np.random.default_rng(seed)
    palette = [build.texture(0.6, [build.spatial(1.0 + t, 0.1)], channel="uv")
               for t in range(textures)]
    cols, rows = round(20.0 / taxtel_mm[0]), round(14.0 / taxtel_mm[1])
    return build.card(cols * taxtel_mm[0], rows * taxtel_mm[1], taxtel_mm=taxtel_mm,
                      textures=palette, texture_index=rng.integers(0, textures, cols * rows))


def wandering_track(seed: int, speed_mm_s: float, seconds: float = 0.6):
    """A 50 Hz stroke with jittered sample times that leaves the card (20 x 14 mm) and comes
    back across every edge, a pause, a lift-off and a dropout longer than the horizon."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.012, 0.028, int(seconds * 50)))
    x = 10 + 11 * np.sin(2 * np.pi * t * speed_mm_s / 60 + rng.uniform(0, 6))
    y = 7 + 8 * np.sin(2 * np.pi * t * speed_mm_s / 45 + rng.uniform(0, 6))
    paused = slice(len(t) // 5, len(t) // 5 + 3)
    x[paused], y[paused] = x[paused.start], y[paused.start]
    contact = ~((t > t[0] + 0.45 * seconds) & (t < t[0] + 0.5 * seconds))
    kept = ~((t > t[0] + 0.7 * seconds) & (t < t[0] + 0.85 * seconds))
    return make_track(t[kept], x[kept], y[kept], contact=contact[kept])


@pytest.mark.parametrize(("taxtel_mm", "speed_mm_s", "horizon_s"), [
    ((0.3, 0.7), 120.0, 0.1),   # a crossing every few segments
    ((0.1, 0.07), 60.0, 0.03),  # several per segment, the horizon inside the gaps
    ((0.1, 0.07), 900.0, 0.1),  # a taxtel every frame or two: looked up frame by frame
    ((3.0, 0.3), 400.0, 0.5),
])
def test_the_texture_of_every_frame_is_the_frame_by_frame_lookup(taxtel_mm, speed_mm_s,
                                                                 horizon_s):
    card = checker_card(taxtel_mm)
    options = RenderOptions(dead_reckoning_s=horizon_s)
    for seed in range(3):
        track = wandering_track(seed, speed_mm_s)
        frames = Renderer(card, options).render(track)
        reference = reference_render(card, track.t, track.x, track.y, track.contact,
                                     horizon_s=horizon_s)
        assert np.count_nonzero(np.diff(frames.texture)) > 20
        assert np.array_equal(frames.texture, reference.texture)


def test_streamed_blocks_cross_taxtels_as_the_batch():
    """Blocks of every size cut the segments anywhere; each block finds its own crossings."""
    card = checker_card((0.1, 0.07))
    track = wandering_track(4, 150.0)
    renderer = Renderer(card)
    batch = renderer.render(track)
    for block in (3, 50, 999):
        stream = renderer.stream()
        stream.push(track.t, track.x, track.y, contact=track.contact)
        textures = [stream.render(min(block, len(batch) - done)).texture
                    for done in range(0, len(batch), block)]
        assert np.array_equal(np.concatenate(textures), batch.texture)


def test_the_search_finds_each_crossing_from_any_guess():
    """Guesses anywhere between the bracket's ends (the line's guess is off only by rounding,
    so the bisection would otherwise go untested): the first frame whose key reaches the
    target, as a scan of every frame finds it with the key computed here from R6 and R7."""
    rng = np.random.default_rng(11)
    card = checker_card((0.1, 0.07))
    compiled = compile_card(card, RenderOptions())
    horizon_s, searches = 0.02, 300
    times = 5.0 + np.arange(400) / 10_000.0
    on_y = rng.uniform(size=searches) < 0.5
    velocity = rng.choice([-1.0, 1.0], searches) * rng.uniform(20.0, 2000.0, searches)
    sample_t = times[0] - rng.uniform(0.0, 0.01, searches)
    start = rng.uniform(-1.0, np.where(on_y, 15.0, 21.0))
    # the key (R6's position, R7's clipped cell, plus the card edges passed) at every frame
    position = start + velocity * np.minimum(times[:, None] - sample_t, horizon_s)
    pitch = np.where(on_y, card.grid.taxtel_height_mm, card.grid.taxtel_width_mm)
    count = np.where(on_y, card.grid.rows, card.grid.cols)
    extent = np.where(on_y, card.surface.height_mm, card.surface.width_mm)
    key = np.clip(np.floor(position / pitch), 0, count - 1) + (position >= 0) \
        + (position >= extent)
    direction = np.sign(velocity).astype(np.intp)
    key = (direction * key).astype(np.intp)
    moved = key[-1] > key[0]
    assert moved.sum() > 150
    target = key[0] + 1 + rng.integers(0, np.maximum(key[-1] - key[0], 1))
    expected = np.argmax(key >= target, axis=0)
    line = Line(compiled, times, horizon_s, on_y[moved], sample_t[moved], start[moved],
                velocity[moved])
    last, n = times.shape[0] - 1, int(moved.sum())
    for guess in (rng.integers(1, last + 1, n), np.full(n, 1), np.full(n, last),
                  expected[moved] + rng.integers(-3, 4, n)):
        found = first_reached(line, direction[moved], target[moved], np.zeros(n, np.intp),
                              np.full(n, last), guess)
        assert np.array_equal(found, expected[moved])
