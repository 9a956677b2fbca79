"""A4 (spatial phase, spec/conformance.md 3.4) on the golden render itself and on a copy of it
displaced by a known lag: 0 for the first, that lag's distance for the second, also on a track
that lifts off and touches again."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hcard.render import render
from hcard.track import FingerTrack
from hcard_conformance import metrics
from hcard_conformance.metrics import Signal, Tolerances
from hcard_conformance.vectors import load_manifest

MANIFEST = load_manifest()
CARD = "coarse-grating"
TRACKS = ("liftoff", "slow-stroke", "moderate-stroke", "fast-stroke")


def golden(track_name: str) -> tuple[Signal, FingerTrack, set[int]]:
    """The golden render of the coarse grating along ``track_name`` (with its speed onsets),
    the track and the card's position-locked textures."""
    entry = next(e for e in MANIFEST.renders if e.card == CARD)
    card = MANIFEST.card(CARD).load_card()
    track = MANIFEST.track(track_name).load_track()
    frames = render(card, track, entry.options())
    signal = replace(Signal.of(frames), events=metrics.speed_onsets(track))
    return signal, track, metrics.position_locked_textures(card, entry.options())


@pytest.mark.parametrize("track_name", TRACKS)
def test_the_golden_render_against_itself_is_not_displaced(track_name: str) -> None:
    """On ``liftoff`` the frames after the lift-off (neutral friction, out of contact) and the
    guard frames before it once drew A4's unnormalised correlation to a 50 ms lag: 3.0 mm
    (FAIL) for the golden render against itself."""
    signal, track, locked = golden(track_name)
    metric = metrics.spatial_phase_error(signal, signal, Tolerances(), track, locked)
    assert metric.applicable
    assert metric.value == 0.0, metric.detail


def test_a_displaced_copy_is_measured_at_its_lag_across_a_lift_off() -> None:
    """The golden render 15 ms late (the same contact): A4 reports the speed x 15 ms."""
    signal, track, locked = golden("liftoff")
    lag = 150  # frames at 10 kHz
    assert metrics.frame_rate(signal) == 10_000.0
    late = replace(signal, m=np.concatenate((np.full(lag, signal.m[0]), signal.m[:-lag])))
    metric = metrics.spatial_phase_error(late, signal, Tolerances(), track, locked)
    assert "lag 15.0 ms at 60 mm/s" in metric.detail  # the track strokes at 60 mm/s
    assert metric.value == pytest.approx(60.0 * 0.015)
