"""Importing .hjif files hcard did not write (spec/interchange/hjif.md IJ70-IJ79): the expected
friction is computed here from the format's definition, independently of the importer; and
hostile files, each refused with one line naming the file, the JSON path and why (IJ27)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid
from tests.helpers.cli import assert_one_line_error, run_hcard
from tests.interchange.hjif_cards import friction_of, hjif_registered

__all__ = ["hjif_registered"]


def _document(modality="Friction", bands=None, devices=None, timescale=1000, unit=-3):
    """A hand-written .hjif: one perception, one channel (positions in mm by default)."""
    return {
        "version": "2023", "profile": "Main", "level": 1, "date": "2024-05-01",
        "description": "hand written", "timescale": timescale, "avatars": [],
        "perceptions": [{
            "id": 0, "avatar_id": 0, "description": "a texture",
            "perception_modality": modality, "unit_exponent": unit,
            "reference_devices": devices if devices is not None else [
                {"id": 1, "name": "piezo plate", "type": "Piezo"}],
            "effect_library": [],
            "channels": [{"id": 0, "description": "finger", "gain": 1.0,
                          "mixing_coefficient": 1.0, "body_part_mask": 0,
                          "bands": bands if bands is not None else _bands()}]}],
        "syncs": []}


def _bands(amplitudes=((0, 0.5), (10000, 0.5)), frequency=2, phase=1.0, level=0.2):
    frames = [{"relative_position": p, "amplitude_modulation": a} for p, a in amplitudes]
    frames[0]["frequency_modulation"] = frequency
    return [
        {"band_type": "Curve", "curve_type": "Linear", "lower_frequency_limit": 0,
         "upper_frequency_limit": 0, "effects": [{"effect_type": "Basis", "position": 0,
                                                  "keyframes": [
             {"relative_position": 0, "amplitude_modulation": level},
             {"relative_position": amplitudes[-1][0], "amplitude_modulation": level}]}]},
        {"band_type": "VectorialWave", "lower_frequency_limit": 0,
         "upper_frequency_limit": 100, "effects": [
             {"effect_type": "Basis", "position": 0, "phase": phase, "base_signal": "Sine",
              "keyframes": frames}]}]


def _read(tmp_path, document, name="hand.hjif", **options):
    from hcard_builtins.formats.hjif import HjifImporter

    path = tmp_path / name
    path.write_text(json.dumps(document))
    importer = HjifImporter()
    return importer.read(path, **importer.options(**options))


def test_ij73_a_constant_friction_texture_is_one_taxtel(tmp_path) -> None:
    """Friction with a Piezo reference device is UV over 0.3..1 (middle 0.65, half 0.35):
    friction(x) = 0.65 + 0.35 (0.2 + 0.5 sin(2 pi 2 x + 1.0)), x in mm (timescale 1000
    ticks per mm: unit_exponent -3)."""
    result = _read(tmp_path, _document())
    card = result.card
    require_valid(card)
    assert (card.grid.cols, card.grid.rows) == (1, 1)
    assert card.surface.width_mm == pytest.approx(10.0)
    texture = card.textures[0]
    assert texture.channel == pb.CHANNEL_UV and texture.locking == pb.LOCKING_POSITION
    x = np.linspace(0.0, 10.0, 10001)
    expected = 0.65 + 0.35 * (0.2 + 0.5 * np.sin(2 * math.pi * 2.0 * x + 1.0))
    assert np.max(np.abs(friction_of(texture, x) - expected)) < 1e-12
    assert texture.baseline == pytest.approx(0.72)
    assert texture.components[0].frequency == 2.0
    assert texture.components[0].amplitude == pytest.approx(0.175)
    assert result.stats["max_error_jnd"] < 1e-9
    assert card.metadata.title == "hand" and card.metadata.description == "hand written"


def test_ij73_amplitude_modulation_becomes_per_taxtel_amplitudes(tmp_path) -> None:
    """The amplitude falls linearly from 1 at 0 mm to 0 at 20 mm: 5 mm taxtels get it at
    their centres, 0.875, 0.625, 0.375 and 0.125 of the half range 0.5 (bipolar, no Piezo)."""
    document = _document(devices=[], bands=_bands(((0, 1.0), (20000, 0.0)), frequency=1,
                                                   phase=0.0, level=0.0))
    result = _read(tmp_path, document)
    card = result.card
    assert (card.grid.cols, card.grid.rows) == (4, 1)
    amplitudes = [card.textures[i].components[0].amplitude for i in card.grid.texture_index]
    assert amplitudes == pytest.approx([0.4375, 0.3125, 0.1875, 0.0625])
    assert all(card.textures[i].channel == pb.CHANNEL_BIPOLAR for i in card.grid.texture_index)
    # the hjif's own friction varies within each taxtel (+-0.0625 x the signal): the card's
    # is the centre's: at most 0.0625 x 1 relative friction off, 0.78 JND
    assert 0.3 < result.stats["max_error_jnd"] <= 0.0625 / 0.08 + 1e-9
    assert any("sampled at the centres of 5 mm taxtels" in line for line in result.log)


def test_ij76_friction_range_option_scales_the_signal(tmp_path) -> None:
    result = _read(tmp_path, _document(), friction_range=(0.5, 0.9))
    assert result.card.textures[0].baseline == pytest.approx(0.7 + 0.2 * 0.2)
    assert result.card.textures[0].components[0].amplitude == pytest.approx(0.1)


def test_ij75_electrotactile_is_ev(tmp_path) -> None:
    card = _read(tmp_path, _document("Electrotactile", devices=[])).card
    assert card.textures[0].channel == pb.CHANNEL_EV
    assert card.textures[0].baseline == pytest.approx(1.3 + 0.3 * 0.2)


def test_ij40_other_perceptions_are_listed_not_imported(tmp_path) -> None:
    document = _document()
    other = json.loads(json.dumps(document["perceptions"][0]))
    other.update(id=1, perception_modality="Vibrotactile")
    document["perceptions"].append(other)
    result = _read(tmp_path, document)
    assert result.log[0] == ("perception 1 (Vibrotactile) not imported: hcard imports "
                             "Friction, Electrotactile and Vibrotactile Texture")
    assert result.stats["channels"] == 1


def test_recognises_a_head_with_perceptions_and_timescale() -> None:
    from hcard_builtins.formats.hjif import HjifImporter

    importer = HjifImporter()
    assert importer.recognises(b'{"version":"2023","perceptions":[') == 2
    assert importer.recognises(b'\xef\xbb\xbf {"timescale":1000, "perceptions": []}') == 2
    assert importer.recognises(b'{"perceptions":[]}') == 0
    assert importer.recognises(b'{"textures":[], "version": 1}') == 0
    assert importer.recognises(b"\x89PNG\r\n") == 0


# --- Hostile and malformed files, through the command line ---------------------------------


def _hostile(tmp_path, text: str | bytes, name: str = "bad.hjif"):
    path = tmp_path / name
    if isinstance(text, str):
        text = text.encode()
    path.write_bytes(text)
    return path, run_hcard("import", path, "--from", "hjif", "-o", tmp_path / "out.hcard")


def _with(change) -> str:
    document = _document()
    change(document)
    return json.dumps(document)


CASES = {
    "not_json": ("{perceptions: [", ["not JSON", "line 1 column 2"]),
    "deep_nesting": ('{"perceptions":' + "[" * 40 + "]" * 40 + "}",
                     ["not JSON", "nested 41 arrays and objects deep, more than 32"]),
    "nan": (_with(lambda d: None).replace('"gain": 1.0', '"gain": NaN'),
            ["not JSON", "NaN is not JSON"]),
    "infinite": (_with(lambda d: None).replace('"amplitude_modulation": 0.5',
                                               '"amplitude_modulation": 1e999', 1),
                 ["perceptions[0].channels[0].bands[1].effects[0].keyframes[0]"
                  ".amplitude_modulation", "inf is not a finite number"]),
    "float_band_limit": (_with(lambda d: d["perceptions"][0]["channels"][0]["bands"][1].update(
        upper_frequency_limit=500.0)),
        ["perceptions[0].channels[0].bands[1].upper_frequency_limit",
         "500.0 must be written as a JSON integer"]),
    "float_frequency": (_with(lambda d: d["perceptions"][0]["channels"][0]["bands"][1][
        "effects"][0]["keyframes"][0].update(frequency_modulation=2.5)),
        ["keyframes[0].frequency_modulation", "must be a JSON integer, not a number"]),
    "unknown_modality": (_with(lambda d: d["perceptions"][0].update(
        perception_modality="Texture")),
        ["perceptions[0].perception_modality", "'Texture' is not one of the schema's values"]),
    "missing_timescale": (_with(lambda d: d.pop("timescale")),
                          ["timescale: missing (required) (the MPEG reference software "
                           "requires it)"]),
    "missing_body_part_mask": (_with(lambda d: d["perceptions"][0]["channels"][0].pop(
        "body_part_mask")), ["perceptions[0].channels[0].body_part_mask",
                             "drops a channel without it"]),
    "string_position": (_with(lambda d: d["perceptions"][0]["channels"][0]["bands"][1][
        "effects"][0].update(position="0")),
        ["effects[0].position", "must be a JSON integer, not a string"]),
    "bad_version": (_with(lambda d: d.update(version="2022")),
                    ["version", "'2022' is not an edition"]),
    "negative_phase": (_with(lambda d: d["perceptions"][0]["channels"][0]["bands"][1][
        "effects"][0].update(phase=-0.5)), ["effects[0].phase", "-0.5 is outside 0..6.28318"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_ij27_a_bad_file_is_one_line_naming_file_path_and_reason(hjif_registered, tmp_path,
                                                                case) -> None:
    text, fragments = CASES[case]
    path, result = _hostile(tmp_path, text)
    assert_one_line_error(result, str(path), *fragments)
    assert not (tmp_path / "out.hcard").exists()


def test_ij27_a_million_keyframes_are_refused_by_count(hjif_registered, tmp_path) -> None:
    import time

    document = _document()
    text = json.dumps(document).replace(
        '"keyframes": [{"relative_position": 0, "amplitude_modulation": 0.5',
        '"keyframes": [' + "{}," * 1_000_000 + '{"relative_position": 0, '
        '"amplitude_modulation": 0.5', 1)
    started = time.perf_counter()
    path, result = _hostile(tmp_path, text)
    assert time.perf_counter() - started < 20
    assert_one_line_error(result, str(path), "perceptions[0].channels[0].bands[1].effects[0]"
                          ".keyframes", "more than 524288 keyframes in the file")


def test_ij27_a_file_over_16_mib_is_refused_before_it_is_parsed(hjif_registered, tmp_path) -> None:
    path = tmp_path / "huge.hjif"
    with path.open("wb") as file:
        file.write(b'{"perceptions": [], "timescale": 1, "pad": "')
        file.truncate(16 * 1024 * 1024 + 10)
    result = run_hcard("import", path, "--from", "hjif", "-o", tmp_path / "out.hcard")
    assert_one_line_error(result, str(path), "16777226 bytes exceed the limit of 16777216")


def test_ij27_a_pipe_is_read_only_up_to_the_limit() -> None:
    from pathlib import Path

    from hcard.errors import AssetError
    from hcard_builtins.formats.hjif_import import ImportOptions, import_file

    with pytest.raises(AssetError, match="more than 16777216 bytes"):
        import_file(Path("/dev/zero"), ImportOptions())


def test_ij33_a_broken_extension_is_refused(hjif_registered, tmp_path) -> None:
    document = _document()
    document["description"] = 'hcard:{"hcard_hjif":1,"surface":[10,"wide"]}'
    path, result = _hostile(tmp_path, json.dumps(document))
    assert_one_line_error(result, str(path), "description:hcard.surface[1]",
                          "must be a JSON number, not a string")


def test_ij33_an_unknown_extension_version_is_refused(hjif_registered, tmp_path) -> None:
    document = _document()
    document["description"] = 'hcard:{"hcard_hjif":7}'
    path, result = _hostile(tmp_path, json.dumps(document))
    assert_one_line_error(result, str(path), "description:hcard.hcard_hjif",
                          "extension version 7 is not 1")


def test_ij56_a_companion_naming_an_unknown_channel_is_refused(hjif_registered, tmp_path) -> None:
    from tests.interchange.hjif_cards import export, mixed_card

    result = export(mixed_card())
    (tmp_path / "m.hjif").write_bytes(result.files[0][1])
    gltf = json.loads(result.files[1][1])
    import base64

    from hcard_builtins.formats.gltf_material import png_gray

    ids = np.full((8, 12), 9, dtype=np.uint8)
    gltf["images"][0]["uri"] = "data:image/png;base64," + base64.b64encode(
        png_gray(ids)).decode()
    (tmp_path / "m.gltf").write_text(json.dumps(gltf))
    cli = run_hcard("import", tmp_path / "m.hjif", "-o", tmp_path / "out.hcard")
    assert_one_line_error(cli, str(tmp_path / "m.gltf"), "images",
                          "pixel value 9 names no channel of the .hjif")


def test_options_that_do_not_apply_are_usage_errors(hjif_registered, tmp_path) -> None:
    path = tmp_path / "ok.hjif"
    path.write_text(json.dumps(_document()))
    result = run_hcard("import", path, "-o", tmp_path / "o.hcard", "--dpi", "100")
    assert_one_line_error(result, "--dpi: not an option of the hjif importer", status=2,
                          after_usage=True)


def test_a_bad_option_value_is_a_usage_error(hjif_registered, tmp_path) -> None:
    path = tmp_path / "ok.hjif"
    path.write_text(json.dumps(_document()))
    result = run_hcard("import", path, "-o", tmp_path / "o.hcard", "--taxtel-mm", "0.01")
    assert_one_line_error(result, "--taxtel-mm must be a number of mm in 0.05..10000, got 0.01",
                          status=2, after_usage=True)
    result = run_hcard("import", path, "-o", tmp_path / "o.hcard", "--friction-range", "1",
                       "0.5")
    assert_one_line_error(result, "--friction-range must satisfy 0 <= LO < HI <= 4, got 1 0.5",
                          status=2, after_usage=True)
