"""Small valid cards used across the tests."""

from __future__ import annotations

import math

from hcard import build


def two_texture_card():
    """A 20 x 10 mm card: a UV grating on the left half, a BIPOLAR bump train on the right."""
    grating = build.texture(
        0.7,
        [build.spatial(1.0, 0.2, phase=0.25, orientation=math.pi / 6),
         build.temporal(150.0, 0.05)],
        channel="uv", locking="velocity", name="grating",
    )
    bumps = build.texture(
        1.1, [build.spatial(0.05, 0.3, channel="ev")], channel="bipolar", locking="position",
        name="bumps",
    )
    return build.card(20.0, 10.0, taxtel_mm=5.0, textures=[grating, bumps],
                      texture_index=[0, 0, 1, 1, 0, 0, 1, 1], title="two textures",
                      author="hcard tests", licence="CC0-1.0")
