"""card -> .hjif (+ glTF) -> card (spec/interchange/hjif.md IJ80-IJ82): with the hcard
extension the card comes back within float32 of the format (IJ80); without it, what the
format holds along x (IJ81); and the figures the exporter states about its own file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid
from tests.interchange.hjif_cards import (
    _fixed_date,
    export,
    fine_card,
    friction_of,
    mixed_card,
    plain_card,
)

__all__ = ["_fixed_date"]

AMPLITUDE_TOLERANCE = 1e-6
"""Relative friction: float32 of a signal times a half range of at most 2 (IJ80)."""
PHASE_TOLERANCE = 1e-5
"""Radians: float32 of a phase below 2 pi (3.8e-7) plus the 5.3e-6 of a phase above the
schema's 6.28318 written as 0 (IJ13, IJ80)."""


def _write(tmp_path, card, name="card"):
    result = export(card)
    paths = []
    for suffix, data in result.files:
        path = tmp_path / (name + (suffix or ".hjif"))
        path.write_bytes(data)
        paths.append(path)
    return result, paths


def _import(path, **options):
    from hcard_builtins.formats.hjif import HjifImporter

    importer = HjifImporter()
    return importer.read(path, **importer.options(**options))


def _phase_gap(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


def _assert_same_card(back: pb.Card, card: pb.Card) -> None:
    assert back.metadata.title == card.metadata.title
    assert back.metadata.author == card.metadata.author
    assert back.metadata.licence == card.metadata.licence
    assert back.metadata.description == card.metadata.description
    assert (back.surface.width_mm, back.surface.height_mm) == (
        card.surface.width_mm, card.surface.height_mm)
    assert (back.grid.cols, back.grid.rows) == (card.grid.cols, card.grid.rows)
    assert list(back.grid.texture_index) == list(card.grid.texture_index)
    assert len(back.textures) == len(card.textures)
    for t, (got, want) in enumerate(zip(back.textures, card.textures, strict=True)):
        assert (got.name, got.channel, got.locking) == (want.name, want.channel, want.locking)
        assert abs(got.baseline - want.baseline) <= AMPLITUDE_TOLERANCE, t
        assert len(got.components) == len(want.components)
        for g, w in zip(got.components, want.components, strict=True):
            assert (g.domain, g.frequency, g.orientation, g.channel) == (
                w.domain, w.frequency, w.orientation, w.channel)
            assert abs(g.amplitude - w.amplitude) <= AMPLITUDE_TOLERANCE
            assert _phase_gap(g.phase, w.phase) <= PHASE_TOLERANCE


@pytest.mark.parametrize("make", [mixed_card, plain_card, fine_card])
def test_ij80_the_card_comes_back_with_the_extension(tmp_path, make) -> None:
    card = make()
    _, paths = _write(tmp_path, card)
    result = _import(paths[0])
    require_valid(result.card)
    _assert_same_card(result.card, card)
    assert result.stats["hcard_extension"] is True
    assert result.stats["gltf_companion"] is (card.grid.cols * card.grid.rows > 1)


def test_ij80_phase_above_the_schema_maximum_comes_back_within_the_tolerance(tmp_path) -> None:
    """A cosine phase of 2 pi - pi/2 - 2e-6 is a sine phase just under 2 pi, above 6.28318:
    written as 0, 2.3e-6 rad off."""
    card = plain_card(phase=1.5 * math.pi - 2e-6)
    _, paths = _write(tmp_path, card)
    document = json.loads(paths[0].read_bytes())
    assert document["perceptions"][0]["channels"][0]["bands"][1]["effects"][0]["phase"] == 0.0
    back = _import(paths[0]).card.textures[0].components[0]
    assert 2e-6 <= _phase_gap(back.phase, card.textures[0].components[0].phase) <= 2.5e-6


def test_ij51_without_the_gltf_the_map_is_lost_and_said(tmp_path) -> None:
    card = mixed_card()
    _, paths = _write(tmp_path, card)
    paths[1].unlink()
    result = _import(paths[0])
    assert list(result.card.grid.texture_index) == [0] * 96
    assert any("no glTF companion card.gltf" in line for line in result.log)


def test_ij81_without_the_extension_the_friction_along_x_comes_back(tmp_path) -> None:
    """The plain card's grating (0.5 cycles/mm, whole cycles per metre) read from the
    standard fields alone: a position-locked UV texture of the same friction along x."""
    card = plain_card()
    _, paths = _write(tmp_path, card)
    document = json.loads(paths[0].read_bytes())
    document["description"] = "edited by another tool"
    paths[0].write_text(json.dumps(document))
    result = _import(paths[0])
    back = result.card
    require_valid(back)
    assert result.stats["hcard_extension"] is False
    assert back.textures[0].channel == pb.CHANNEL_UV
    assert back.textures[0].locking == pb.LOCKING_POSITION
    assert back.metadata.description == "edited by another tool"
    # effects span the surface's diagonal: the texture is as long
    assert back.surface.width_mm == pytest.approx(math.hypot(40.0, 10.0), abs=0.025)
    x = np.linspace(0.0, 40.0, 4001)
    error = friction_of(back.textures[0], x) - friction_of(card.textures[0], x)
    assert np.max(np.abs(error)) < 2e-6
    assert result.stats["max_error_jnd"] < 1e-4


def test_ij81_without_the_extension_a_tilted_grating_keeps_its_profile(tmp_path) -> None:
    """Orientation is lost: the tilted grating of the mixed card comes back along x with its
    frequency along its own wave vector (IJ42)."""
    card = mixed_card()
    _, paths = _write(tmp_path, card)
    document = json.loads(paths[0].read_bytes())
    document["description"] = ""
    paths[0].write_text(json.dumps(document))
    result = _import(paths[0])
    uv = result.card.textures[result.card.grid.texture_index[0]]
    assert [round(c.frequency, 6) for c in uv.components] == [1.0, 0.234]
    assert all(c.orientation == 0 for c in uv.components)
    # one texture per channel from its first segment: the 0.0003 cycles/mm of the rounded
    # frequency drifts along the 72 mm (0.05 x 2 pi x 0.0003 x 72.1 = 0.0068: 0.085 JND)
    assert result.stats["rms_error_jnd"] < 0.03
    assert 0.01 < result.stats["max_error_jnd"] < 0.085


def test_ij60_the_exporter_states_its_own_fidelity(tmp_path) -> None:
    """The mixed card's .hjif against the card: 0.2337 cycles/mm is written as 234 cycles per
    metre, re-anchored in segments, the error within the 0.02 rad phase budget."""
    result, _ = _write(tmp_path, mixed_card())
    stats = result.stats
    assert stats["timescale"] == 40000 and stats["unit_exponent"] == 0
    assert stats["perceptions"] == 3 and stats["channels"] == 3
    # 0.05 amplitude x 0.02 rad = 0.001 relative friction at most: 0.0125 JND
    assert stats["max_error_jnd"] < 0.0125
    assert stats["rms_error_jnd"] < stats["max_error_jnd"]


def test_ij12_segments_bound_the_phase_error_of_the_rounded_frequency() -> None:
    from hcard import build
    from hcard_builtins.formats.hjif_export import Axis, grating_of

    axis = Axis(0)
    component = build.spatial(0.2337, 0.1, phase=0.0)
    length = round(72.11 / 0.025)
    grating = grating_of(component, 0.35, axis, length)
    assert grating.f_int == 234
    dk = 0.2337 - 0.234
    worst = max(math.pi * abs(dk) * seg * 0.025 for _, seg, _ in grating.segments)
    assert len(grating.segments) == math.ceil(math.pi * abs(dk) * 72.1 / 0.02)
    assert worst <= 0.02


def test_ij55_the_gltf_places_the_textures(tmp_path) -> None:
    from hcard_builtins.formats.gltf_material import read_taxtel_map

    card = mixed_card()
    _, paths = _write(tmp_path, card)
    gltf = json.loads(paths[1].read_text())
    assert gltf["asset"]["version"] == "2.0"
    assert gltf["extensionsUsed"] == ["MPEG_haptic", "MPEG_haptic_material"]
    friction = gltf["materials"][0]["extensions"]["MPEG_haptic_material"]["friction"][0]
    assert friction["type"] == "Reference"
    taxtel_map = read_taxtel_map(paths[1])
    assert taxtel_map.ids.shape == (8, 12)
    assert taxtel_map.ids.ravel().tolist() == list(card.grid.texture_index)
    assert taxtel_map.surface_mm == pytest.approx((60.0, 40.0), rel=1e-6)
    assert taxtel_map.taxtel_mm == pytest.approx((5.0, 5.0), rel=1e-6)


def test_one_taxtel_has_no_gltf() -> None:
    assert [suffix for suffix, _ in export(plain_card()).files] == [""]


def test_the_same_card_gives_the_same_bytes() -> None:
    first, second = export(mixed_card()), export(mixed_card())
    assert first.files == second.files


def test_losses_name_what_the_format_cannot_hold() -> None:
    losses = {loss.field: loss for loss in export(mixed_card()).losses}
    assert set(losses) == {"channel", "locking", "orientation", "friction-scale", "phase",
                           "components", "taxtel-map", "metadata"}
    assert "1 temporal component" in losses["components"].detail
    assert "0.0003 cycles/mm" in losses["components"].detail
    assert losses["taxtel-map"].carried.startswith("the glTF companion")
    assert "uv 0.3..1, ev 1..1.6, bipolar 0.5..1.5" in losses["friction-scale"].detail
    assert losses["phase"].carried == ""
    plain = {loss.field for loss in export(plain_card()).losses}
    assert plain == {"channel", "locking", "friction-scale", "phase"}
