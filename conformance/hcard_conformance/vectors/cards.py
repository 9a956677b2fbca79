"""The valid vector cards: one function per card, each tagged with what it exercises.

Tags (spec/conformance.md Q6): ``dense`` (fine gratings a 50 Hz position-only renderer cannot
render), ``coarse`` (position-locked gratings of period >= 10 mm), ``sparse`` (position-locked
features drawn as taxtels: edges, a button), ``bipolar``, ``temporal``, ``oriented``,
``checkerboard`` (two or more textures alternating per taxtel).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hcard import build
from hcard.v1 import card_pb2 as pb

WIDTH_MM = 120.0
"""Surface width of every vector card, mm."""
HEIGHT_MM = 80.0
"""Surface height of every vector card, mm."""
LICENCE = "CC0-1.0"
AUTHOR = "hcard conformance vectors"


@dataclass(frozen=True)
class VectorCard:
    """A vector card with its name and tags."""

    name: str
    tags: tuple[str, ...]
    card: pb.Card


def _card(
    title: str,
    description: str,
    textures: list[pb.Texture],
    *,
    taxtel_mm: float | tuple[float, float],
    texture_index: np.ndarray | None = None,
) -> pb.Card:
    card = build.card(
        WIDTH_MM,
        HEIGHT_MM,
        taxtel_mm=taxtel_mm,
        textures=textures,
        texture_index=texture_index,
        title=title,
        author=AUTHOR,
        licence=LICENCE,
        description=description,
    )
    # A fixed generator string keeps the bytes independent of the hcard version.
    card.metadata.generator = "hcard_conformance.vectors"
    return card


def _taxtel_centres(taxtel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    cols = build.grid_count(WIDTH_MM, taxtel_mm)
    rows = build.grid_count(HEIGHT_MM, taxtel_mm)
    xs = (np.arange(cols) + 0.5) * taxtel_mm
    ys = (np.arange(rows) + 0.5) * taxtel_mm
    return np.meshgrid(xs, ys)


def single_grating() -> VectorCard:
    """A 1 mm UV grating, velocity-locked, over the whole surface."""
    tex = build.texture(
        0.7, [build.spatial(1.0, 0.2)], channel="uv", locking="velocity", name="grating-1mm"
    )
    card = _card("single grating", "1 mm UV grating, velocity-locked.", [tex], taxtel_mm=10.0)
    return VectorCard("single-grating", ("dense",), card)


def single_grating_auto() -> VectorCard:
    """A 2.5 mm EV grating with AUTO locking (resolves to VELOCITY, README R8)."""
    tex = build.texture(
        1.4, [build.spatial(0.4, 0.3, phase=0.5)], channel="ev", locking="auto",
        name="grating-2.5mm-ev",
    )
    card = _card("auto grating", "2.5 mm EV grating, AUTO locking.", [tex], taxtel_mm=10.0)
    return VectorCard("single-grating-auto", ("dense",), card)


def oriented_gratings() -> VectorCard:
    """Four 1.25 mm UV gratings with wave vectors at 0, 45, 90 and 135 degrees, one a quadrant."""
    textures = [
        build.texture(
            0.65,
            [build.spatial(0.8, 0.25, orientation=angle)],
            channel="uv",
            locking="velocity",
            name=f"grating-{round(math.degrees(angle))}deg",
        )
        for angle in (0.0, math.pi / 4, math.pi / 2, 3 * math.pi / 4)
    ]
    index = np.array([[0, 1], [2, 3]])
    card = _card(
        "oriented gratings",
        "1.25 mm UV gratings at 0/45/90/135 degrees, one per quadrant.",
        textures,
        taxtel_mm=(60.0, 40.0),
        texture_index=index,
    )
    return VectorCard("oriented-gratings", ("dense", "oriented"), card)


def checkerboard() -> VectorCard:
    """Two textures alternating on 20 mm taxtels: a 1 mm UV grating and a 2 mm EV grating."""
    textures = [
        build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv", locking="velocity",
                      name="uv-1mm"),
        build.texture(1.5, [build.spatial(0.5, 0.3)], channel="ev", locking="velocity",
                      name="ev-2mm"),
    ]
    xs, ys = _taxtel_centres(20.0)
    index = (np.floor(xs / 20.0) + np.floor(ys / 20.0)).astype(int) % 2
    card = _card("checkerboard", "UV 1 mm and EV 2 mm gratings alternating on 20 mm taxtels.",
                 textures, taxtel_mm=20.0, texture_index=index)
    return VectorCard("checkerboard", ("checkerboard", "dense"), card)


def checkerboard_three() -> VectorCard:
    """Three textures cycling along x on 15 mm taxtels: constant, fine grating, bipolar grating."""
    textures = [
        build.texture(0.8, channel="uv", locking="position", name="flat-0.8"),
        build.texture(0.6, [build.spatial(1.25, 0.25)], channel="uv", locking="auto",
                      name="uv-0.8mm"),
        build.texture(1.0, [build.spatial(0.25, 0.5)], channel="bipolar", locking="velocity",
                      name="bipolar-4mm"),
    ]
    xs, ys = _taxtel_centres(15.0)
    index = (np.floor(xs / 15.0) + np.floor(ys / 15.0)).astype(int) % 3
    card = _card("three-texture checkerboard", "Constant, UV and bipolar textures cycling.",
                 textures, taxtel_mm=15.0, texture_index=index)
    return VectorCard("checkerboard-three", ("checkerboard", "dense", "bipolar"), card)


def edge() -> VectorCard:
    """A friction step: natural friction left of x = 60 mm, half friction right of it."""
    textures = [
        build.texture(1.0, channel="uv", locking="position", name="natural"),
        build.texture(0.5, channel="uv", locking="position", name="slippery"),
    ]
    xs, _ = _taxtel_centres(2.0)
    index = (xs >= WIDTH_MM / 2).astype(int)
    card = _card("edge", "Step from relative friction 1.0 to 0.5 at x = 60 mm (2 mm taxtels).",
                 textures, taxtel_mm=2.0, texture_index=index)
    return VectorCard("edge", ("sparse",), card)


def button() -> VectorCard:
    """A 24 x 24 mm button: slippery 2 mm rim, sticky (EV) face, natural friction around it."""
    textures = [
        build.texture(1.0, channel="uv", locking="position", name="background"),
        build.texture(0.4, channel="uv", locking="position", name="rim"),
        build.texture(1.6, channel="ev", locking="position", name="face"),
    ]
    xs, ys = _taxtel_centres(2.0)
    outer = (np.abs(xs - 60.0) < 12.0) & (np.abs(ys - 40.0) < 12.0)
    inner = (np.abs(xs - 60.0) < 10.0) & (np.abs(ys - 40.0) < 10.0)
    index = np.where(inner, 2, np.where(outer, 1, 0))
    card = _card("button", "24 mm button centred at (60, 40) mm: UV rim, EV face.",
                 textures, taxtel_mm=2.0, texture_index=index)
    return VectorCard("button", ("sparse",), card)


def bipolar_grating() -> VectorCard:
    """A 2 mm BIPOLAR grating swinging 0.4..1.6: UV below 1, EV above."""
    tex = build.texture(1.0, [build.spatial(0.5, 0.6)], channel="bipolar", locking="velocity",
                        name="bipolar-2mm")
    card = _card("bipolar grating", "2 mm bipolar grating, 0.4..1.6.", [tex], taxtel_mm=10.0)
    return VectorCard("bipolar-grating", ("bipolar", "dense"), card)


def bipolar_extreme() -> VectorCard:
    """A BIPOLAR grating spanning the full range 0..4 (safety vector, spec/conformance.md S1)."""
    tex = build.texture(2.0, [build.spatial(0.4, 2.0)], channel="bipolar", locking="velocity",
                        name="bipolar-full-range")
    card = _card("bipolar full range", "2.5 mm bipolar grating spanning 0..4.", [tex],
                 taxtel_mm=10.0)
    return VectorCard("bipolar-extreme", ("bipolar", "dense"), card)


def temporal() -> VectorCard:
    """Temporal components: a 250 Hz UV buzz and a 120 Hz EV buzz on a UV baseline."""
    tex = build.texture(
        0.7,
        [build.temporal(250.0, 0.15), build.temporal(120.0, 0.3, phase=1.0, channel="ev")],
        channel="uv",
        locking="position",
        name="buzz",
    )
    card = _card("temporal", "250 Hz UV and 120 Hz EV vibrations from touch-down.", [tex],
                 taxtel_mm=10.0)
    return VectorCard("temporal", ("temporal",), card)


def coarse_grating() -> VectorCard:
    """A 40 mm UV grating, position-locked: a coarse shape position control renders well."""
    tex = build.texture(0.75, [build.grating_period(40.0, 0.2)], channel="uv",
                        locking="position", name="grating-40mm")
    card = _card("coarse grating", "40 mm UV grating, position-locked.", [tex], taxtel_mm=10.0)
    return VectorCard("coarse-grating", ("coarse",), card)


def later_minor() -> VectorCard:
    """A card of a later minor version (1.9) whose two UV gratings can leave [0, 1]: readers
    accept any minor (README V2) and warn of what the renderer will clip (W1: 0.9 + 0.3 above
    1; W2: 0.1 - 0.3 below 0)."""
    high = build.texture(0.9, [build.spatial(1.0, 0.3)], channel="uv", locking="velocity",
                         name="above-one")
    low = build.texture(0.1, [build.spatial(1.0, 0.3)], channel="uv", locking="velocity",
                        name="below-zero")
    card = _card("later minor", "Version 1.9; UV gratings that clip above 1 and below 0.",
                 [high, low], taxtel_mm=(60.0, 80.0), texture_index=np.array([0, 1]))
    card.version.minor = 9
    return VectorCard("later-minor", ("dense",), card)


CARD_FACTORIES: tuple[Callable[[], VectorCard], ...] = (
    single_grating,
    single_grating_auto,
    oriented_gratings,
    checkerboard,
    checkerboard_three,
    edge,
    button,
    bipolar_grating,
    bipolar_extreme,
    temporal,
    coarse_grating,
    later_minor,
)


def vector_cards() -> list[VectorCard]:
    """Every valid vector card, in manifest order."""
    return [factory() for factory in CARD_FACTORIES]
