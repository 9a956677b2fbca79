"""Cards and helpers the .hjif tests share (spec/interchange/hjif.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from hcard import build
from hcard.v1 import card_pb2 as pb

SCHEMAS = Path(__file__).resolve().parents[1] / "data" / "public" / "mpeg" / "Specifications"
"""MPEG's public .hjif JSON schemas (tests/data/public/mpeg/README.md)."""
DATE_EPOCH = "1700000000"
"""``SOURCE_DATE_EPOCH`` of the tests' exports (2023-11-14T22:13:20Z)."""


def mixed_card() -> pb.Card:
    """A 60 x 40 mm card in 5 mm taxtels: UV (a tilted grating, a grating whose frequency is
    not a whole number of cycles per metre, a temporal vibration), EV and bipolar textures,
    a component on its own channel, names and metadata."""
    uv = build.texture(0.8, [build.spatial(1.0, 0.1, phase=0.3, orientation=0.5),
                             build.spatial(0.2337, 0.05, phase=-1.0),
                             build.temporal(200.0, 0.05, phase=0.7)],
                       channel="uv", locking="velocity", name="ridges")
    ev = build.texture(1.2, [build.spatial(2.0, 0.15, phase=2.0)], channel="ev",
                       locking="position", name="grip")
    bipolar = build.texture(1.0, [build.spatial(0.4, 0.3, phase=6.2, orientation=-2.0),
                                  build.spatial(0.05, 0.1, channel="ev")],
                            channel="bipolar", locking="auto")
    index = [(c // 4 + r) % 3 for r in range(8) for c in range(12)]
    return build.card(60.0, 40.0, taxtel_mm=5.0, textures=[uv, ev, bipolar],
                      texture_index=index, title="mixed", author="hcard tests",
                      licence="CC0-1.0", description="three channels")


def plain_card(k: float = 0.5, phase: float = 0.4) -> pb.Card:
    """One UV taxtel of 40 x 10 mm: baseline 0.7 and one grating along x of ``k`` cycles/mm,
    position-locked: what an .hjif holds without the extension (orientation 0, one texture,
    a frequency of whole cycles per metre)."""
    texture = build.texture(0.7, [build.spatial(k, 0.2, phase=phase)], channel="uv",
                            locking="position")
    return build.card(40.0, 10.0, taxtel_mm=(40.0, 10.0), textures=[texture])


def fine_card() -> pb.Card:
    """A card with a 25 cycles/mm grating (above 10: the axis unit becomes 100 mm) and 140
    textures (above level 1's 128 channels in one perception)."""
    textures = [build.texture(0.5 + 0.003 * t, [build.spatial(25.0, 0.05),
                                                build.spatial(0.1 * (t % 9 + 1), 0.02)],
                              channel="uv") for t in range(140)]
    index = [t % 140 for t in range(14 * 10)]
    return build.card(70.0, 50.0, taxtel_mm=5.0, textures=textures, texture_index=index)


CARDS = {"mixed": mixed_card, "plain": plain_card, "fine": fine_card}


@pytest.fixture(autouse=True)
def _fixed_date(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", DATE_EPOCH)


def export(card: pb.Card) -> Any:
    """The exporter's result for ``card``."""
    from hcard_builtins.formats.hjif import HjifExporter

    return HjifExporter().write(card)


def exported_json(card: pb.Card) -> dict[str, Any]:
    """The exported .hjif of ``card`` as parsed JSON (ints stay ints, floats floats)."""
    return json.loads(export(card).files[0][1])


def walk(value: Any, path: str = "") -> Any:
    """Every (JSON path, key, value) of a parsed JSON value."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield path, key, item
            yield from walk(item, f"{path}.{key}" if path else key)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from walk(item, f"{path}[{i}]")


def friction_of(texture: pb.Texture, x_mm: Any) -> Any:
    """A texture's relative friction along x at y = 0 by the card's component formula
    ``A cos(2 pi k (n . p) + phase)`` (spec/README.md R9, position-locked, no band limit),
    spatial components only, written out here independently of the importer."""
    import numpy as np

    total = np.full(np.shape(x_mm), texture.baseline)
    for c in texture.components:
        if c.domain == pb.DOMAIN_SPATIAL:
            total = total + c.amplitude * np.cos(2 * math.pi * c.frequency * math.cos(
                c.orientation) * np.asarray(x_mm) + c.phase)
    return total


@pytest.fixture
def hjif_registered() -> Any:
    """The registry with the hjif importer and exporter. The built-in ``formats`` entry point
    provides them once its sibling modules (``bitmaps``, ``haps``) are in the tree; until
    then (a branch with only this format) they are registered here, in code, and the registry
    is rediscovered afterwards."""
    import types
    import warnings

    from hcard.plugins.hookspecs import hookimpl
    from hcard.plugins.registry import get_registry
    from hcard_builtins.formats.hjif import HjifExporter, HjifImporter

    registry = get_registry()
    if "hjif" in registry.importers and "hjif" in registry.exporters:
        yield registry
        return
    plugin = types.ModuleType("hjif_formats_only")
    plugin.hcard_importers = hookimpl(lambda: [HjifImporter()])  # type: ignore[attr-defined]
    plugin.hcard_exporters = hookimpl(lambda: [HjifExporter()])  # type: ignore[attr-defined]
    registry.register(plugin, package="hcard-tests", version="0")
    yield registry
    from hcard.plugins.records import HcardPluginWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)
        get_registry(refresh=True)
