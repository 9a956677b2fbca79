"""No vector track runs along a taxtel boundary of a card it is played on: a correct device
whose touch reads one protocol count (10 um) off would otherwise play the neighbouring row for
the whole stroke and fail A1 and A5, an error 250 times under A5's 2.5 mm."""

from __future__ import annotations

import numpy as np
import pytest

from hcard_conformance.vectors.generate import RENDER_PAIRS
from hcard_conformance.vectors.manifest import default_root, load_manifest

BAND_MM = 0.5
"""Half-width of the band around a boundary line, mm."""
MAX_DWELL_S = 0.1
"""Longest contact time a track may spend inside one boundary's band, s: crossing it takes
2 x 0.5 mm / 25 mm/s = 0.04 s at the slowest vector speed; running along it, the whole stroke."""
STEP_S = 1e-3


def boundary_dwell(card, track) -> list[tuple[str, float]]:
    """(boundary, seconds in contact within :data:`BAND_MM` of it) for every interior grid
    line of ``card``, the track sampled every millisecond between its samples."""
    grid = card.grid
    t = np.arange(track.t[0], track.t[-1], STEP_S)
    x = np.interp(t, track.t, track.x)
    y = np.interp(t, track.t, track.y)
    segment = np.clip(np.searchsorted(track.t, t, side="right") - 1, 0, len(track) - 1)
    touching = track.contact[segment] & track.contact[np.minimum(segment + 1, len(track) - 1)]
    out = []
    for axis, position, pitch, count in (("x", x, grid.taxtel_width_mm, grid.cols),
                                         ("y", y, grid.taxtel_height_mm, grid.rows)):
        for k in range(1, count):
            inside = touching & (np.abs(position - k * pitch) < BAND_MM)
            out.append((f"{axis} = {k * pitch:g} mm", float(inside.sum()) * STEP_S))
    return out


@pytest.mark.parametrize(("card_name", "track_name"), RENDER_PAIRS)
def test_no_track_runs_along_a_boundary_of_its_card(card_name: str, track_name: str) -> None:
    manifest = load_manifest(default_root())
    card = next(c for c in manifest.cards if c.name == card_name).load_card()
    track = next(t for t in manifest.tracks if t.name == track_name).load_track()
    along = [(line, dwell) for line, dwell in boundary_dwell(card, track) if dwell > MAX_DWELL_S]
    assert not along, f"{track_name} on {card_name} runs along {along}"
