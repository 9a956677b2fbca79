"""The cards of the view tests: two of one grid that differ in one texture."""

from __future__ import annotations

import math

from hcard import build
from hcard.v1 import card_pb2 as pb

GRATING = (1.0, 0.2, 0.3, math.pi / 6)
"""(cycles/mm, amplitude, phase rad, orientation rad) of card A's UV grating."""


def card_a() -> pb.Card:
    """40 x 30 mm in 5 mm taxtels: a UV grating on the left half, an EV texture of two
    components on the right."""
    k, a, phase, theta = GRATING
    grating = build.texture(0.7, [build.spatial(k, a, phase=phase, orientation=theta)],
                            channel="uv", locking="velocity", name="grating")
    ev = build.texture(1.3, [build.spatial(0.5, 0.2), build.spatial(2.0, 0.1, phase=1.0)],
                       channel="ev", locking="position", name="ev")
    index = [0 if col < 4 else 1 for row in range(6) for col in range(8)]
    return build.card(40.0, 30.0, taxtel_mm=5.0, textures=[grating, ev], texture_index=index,
                      title="A")


def card_b() -> pb.Card:
    """Card A with its EV texture's baseline raised to 1.5 and the top-left taxtel playing it."""
    card = card_a()
    card.textures[1].baseline = 1.5
    card.grid.texture_index[0] = 1
    card.metadata.title = "B"
    return card
