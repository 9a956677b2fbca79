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


def large_valid_card():
    """A valid card near the largest (spec/README.md section 4: about 1.4 MB in binary form):
    256 UV textures of 16 components each, names of 1024 code points, a 256 x 256 grid using
    every texture; 1.3 MB in binary form."""
    import numpy as np

    text = "\U0001F600" * 1020  # 4 bytes each in UTF-8
    textures = []
    for t in range(256):
        components = [build.spatial(0.5 + 0.01 * (k + 1), 0.01, phase=0.1 * k,
                                    orientation=0.1 * k, channel="uv") if k % 2
                      else build.temporal(100.0 + k, 0.01) for k in range(16)]
        textures.append(build.texture(0.6, components, channel="uv",
                                      name=f"{t:04d}" + text))
    return build.card(256 * 0.3, 256 * 0.3, taxtel_mm=0.3, textures=textures,
                      texture_index=np.arange(256 * 256) % 256, title=text, author=text,
                      licence=text, description=text)
