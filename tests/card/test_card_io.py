"""Loading, saving, versioning and validation of cards (spec/README.md sections 5, 7, 8)."""

from __future__ import annotations

import math
import os

import pytest

import hcard
from hcard import build, limits
from hcard.card_io import card_from_bytes, parse_card, to_bytes, to_json
from hcard.errors import CardError, CardValidationError
from hcard.v1 import card_pb2 as pb
from tests.helpers.cards import two_texture_card


def paths_of(card):
    return {p.path: p.reason for p in hcard.validate(card) if p.severity == "error"}


def test_valid_card_round_trips_binary_and_json(tmp_path):
    card = two_texture_card()
    assert hcard.validate(card) == []
    for name in ("card.hcard", "card.json", "card.hcard.json"):
        path = tmp_path / name
        hcard.save(card, path)
        loaded = hcard.load(path)
        assert loaded == card
        assert to_bytes(loaded) == to_bytes(card)
    assert (tmp_path / "card.json").read_text().lstrip().startswith("{")
    assert (tmp_path / "card.hcard").read_bytes() == to_bytes(card)


def test_json_uses_proto_field_names_and_enum_names():
    text = to_json(two_texture_card())
    assert '"taxtel_width_mm": 5.0' in text
    assert '"channel": "CHANNEL_UV"' in text
    camel = text.replace("taxtel_width_mm", "taxtelWidthMm")
    assert parse_card(camel.encode()) == two_texture_card()


def test_json_keeps_doubles_exact():
    card = two_texture_card()
    card.textures[0].components[0].phase = 0.1 + 0.2  # not representable in short decimal
    assert parse_card(to_json(card).encode()).textures[0].components[0].phase == 0.1 + 0.2


def test_form_is_detected_from_content_not_name(tmp_path):
    path = tmp_path / "misnamed.hcard"
    path.write_text(to_json(two_texture_card()))
    assert hcard.load(path) == two_texture_card()


def test_wrong_major_version_is_rejected_with_its_number(tmp_path):
    card = two_texture_card()
    card.version.major = 2
    path = tmp_path / "future.hcard"
    path.write_bytes(to_bytes(card))
    with pytest.raises(CardError, match=r"unsupported major version 2\.0") as info:
        hcard.load(path)
    assert info.value.field_path == "version.major"
    assert str(path) in str(info.value)


def test_newer_minor_loads_and_keeps_unknown_fields(tmp_path):
    card = two_texture_card()
    card.version.minor = 7
    # Field 99 (varint 5) and field 100 (a string) that a v1.7 writer might have added.
    unknown = bytes([0x98, 0x06, 0x05]) + bytes([0xA2, 0x06, 0x03]) + b"new"
    path = tmp_path / "newer.hcard"
    path.write_bytes(to_bytes(card) + unknown)
    loaded = hcard.load(path)
    assert loaded.version.minor == 7
    out = tmp_path / "rewritten.hcard"
    hcard.save(loaded, out)
    assert out.read_bytes().endswith(unknown) or unknown in out.read_bytes()
    # JSON of a newer minor: unknown keys are ignored, not an error.
    text = to_json(card).replace('"textures"', '"future_field": {"x": 1},\n  "textures"', 1)
    assert parse_card(text.encode()).version.minor == 7


def test_missing_version_is_not_a_card():
    card = two_texture_card()
    card.ClearField("version")
    with pytest.raises(CardError, match="missing format version"):
        parse_card(to_bytes(card))


@pytest.mark.parametrize("cut", [1, 5, 17, -3, -1])
def test_truncated_card_bytes_are_rejected(cut):
    data = to_bytes(two_texture_card())
    with pytest.raises(CardError):
        parse_card(data[:cut])


def test_corrupt_card_bytes_are_rejected():
    data = bytearray(to_bytes(two_texture_card()))
    data[1] = 0xFF  # length of the version field now runs past the end
    with pytest.raises(CardError, match="corrupt or truncated"):
        card_from_bytes(bytes(data))
    with pytest.raises(CardError, match="empty input"):
        card_from_bytes(b"")
    with pytest.raises(CardError, match="not valid JSON"):
        card_from_bytes(b"{ not json")
    with pytest.raises(CardError, match="does not match the card schema"):
        card_from_bytes(b'{"grid": {"cols": "many"}}')


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_errors(value):
    card = two_texture_card()
    card.textures[0].components[0].phase = value
    card.textures[1].baseline = value
    card.surface.width_mm = value
    found = paths_of(card)
    assert "must be finite" in found["textures[0].components[0].phase"]
    assert "finite" in found["textures[1].baseline"]
    assert "finite" in found["surface.width_mm"]


@pytest.mark.parametrize("frequency", [0.0, -1.0])
def test_zero_or_negative_frequency_is_an_error(frequency):
    card = two_texture_card()
    card.textures[0].components[1].frequency = frequency
    assert paths_of(card) == {
        "textures[0].components[1].frequency": f"must be > 0, got {frequency}"
    }


def test_too_many_components_is_an_error():
    card = two_texture_card()
    card.textures[1].components.extend(
        build.spatial(0.1 * (i + 1), 0.001) for i in range(limits.MAX_COMPONENTS_PER_TEXTURE)
    )
    assert "exceed the limit of 16" in paths_of(card)["textures[1].components"]


def test_grid_size_must_match_index_array():
    card = two_texture_card()
    del card.grid.texture_index[-1]
    assert "has 7 entries but the grid is 4 x 2 = 8" in paths_of(card)["grid.texture_index"]


def test_texture_index_outside_palette():
    card = two_texture_card()
    card.grid.texture_index[5] = 2
    assert paths_of(card) == {
        "grid.texture_index[5]": "texture 2 is outside the palette of 2 texture(s)"
    }


def test_every_problem_is_reported_at_once():
    card = two_texture_card()
    card.grid.texture_index[0] = 9
    card.textures[0].components[0].amplitude = -0.5
    card.textures[1].channel = pb.CHANNEL_UNSPECIFIED
    card.textures[1].locking = pb.LOCKING_UNSPECIFIED
    card.grid.cols = 3
    found = paths_of(card)
    assert set(found) >= {
        "grid.texture_index[0]",
        "textures[0].components[0].amplitude",
        "textures[1].channel",
        "textures[1].locking",
        "grid.cols",
    }
    with pytest.raises(CardValidationError) as info:
        parse_card(to_bytes(card))
    assert len(info.value.problems) == len(found)


def test_grid_must_cover_the_surface():
    card = two_texture_card()
    card.surface.width_mm = 21.0  # 4 taxtels of 5 mm cover only 20 mm
    assert "less than the surface" in paths_of(card)["grid.cols"]
    card.surface.width_mm = 14.0  # the 4th column lies wholly outside
    assert "wholly outside" in paths_of(card)["grid.cols"]


def test_channel_physics_rules():
    card = two_texture_card()
    card.textures[0].baseline = 1.2  # a UV texture cannot raise friction
    assert "UV can only lower friction" in paths_of(card)["textures[0].baseline"]
    card = two_texture_card()
    card.textures[0].components[0].amplitude = 0.5  # 0.7 + 0.5 + 0.05 > 1: clipped, warned
    warnings = [p for p in hcard.validate(card) if p.severity == "warning"]
    assert [w.path for w in warnings] == ["textures[0]"] and "clipped" in warnings[0].reason
    assert paths_of(card) == {}


def test_failed_save_keeps_the_previous_file(tmp_path):
    path = tmp_path / "keep.hcard"
    good = two_texture_card()
    hcard.save(good, path)
    before = path.read_bytes()
    bad = two_texture_card()
    bad.textures[0].components[0].frequency = math.nan
    with pytest.raises(CardValidationError):
        hcard.save(bad, path)
    assert path.read_bytes() == before
    # A failure while writing (the directory turned read-only) leaves it intact as well.
    if os.geteuid() != 0:
        os.chmod(tmp_path, 0o500)
        try:
            with pytest.raises(CardError, match="cannot write"):
                hcard.save(good, path)
        finally:
            os.chmod(tmp_path, 0o700)
        assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["keep.hcard"]  # no temporary left


def test_write_failure_mid_way_leaves_old_file(tmp_path, monkeypatch):
    """os.replace failing (disk full, cross-device...) must not touch the old file."""
    path = tmp_path / "keep.hcard"
    hcard.save(two_texture_card(), path)
    before = path.read_bytes()

    def refuse(*_args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(CardError, match="No space left"):
        hcard.save(build.card(5.0, 5.0, taxtel_mm=5.0, textures=[build.texture(0.5, channel="uv")]),
                   path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["keep.hcard"]


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(CardError, match="no such file") as info:
        hcard.load(tmp_path / "absent.hcard")
    assert "absent.hcard" in str(info.value)
    with pytest.raises(CardError, match="is a directory"):
        hcard.load(tmp_path)
