"""Strict JSON (spec/README.md F3, F7, C5; section 4 limits): every wrong-typed value of a card
field is refused with its field path, unknown enum names are errors, nesting and integer length
are bounded in cards, measurement sidecars and device profiles; what the protobuf JSON mapping
allows (camelCase names, enums by number, numbers as strings, unknown fields) still loads."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from hcard import build, card_io
from hcard.calibration.measurement import MeasurementError, read_measurement
from hcard.cli.main import cli
from hcard.errors import CardError
from hcard.json_text import MAX_JSON_DEPTH, JsonInputError, json_depth, parse_json
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_error import ProfileError

CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="uv", name="a",
                  components=[build.spatial(5.0, 0.3, channel="ev")])], title="t")
BASE: dict[str, Any] = json.loads(card_io.to_json(CARD))


def mutated(path: tuple[Any, ...], value: Any) -> bytes:
    obj = copy.deepcopy(BASE)
    target = obj
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return json.dumps(obj).encode()


WRONG_TYPES = [
    (("surface", "width_mm"), True, "surface.width_mm: expected a number, got true"),
    (("grid", "taxtel_height_mm"), False, "grid.taxtel_height_mm: expected a number, got false"),
    (("textures", 0, "baseline"), [1.0], "textures[0].baseline: expected a number, got an array"),
    (("textures", 0, "components", 0, "phase"), {"v": 1},
     "textures[0].components[0].phase: expected a number, got an object"),
    (("grid", "cols"), True, "grid.cols: expected a whole number, got true"),
    (("grid", "rows"), 1.5, "grid.rows: expected a whole number, got float 1.5"),
    (("grid", "texture_index"), [0, "x"], "grid.texture_index[1]: expected a whole number"),
    (("grid", "texture_index"), 0, "grid.texture_index: expected an array, got int 0"),
    (("textures", 0, "channel"), True, "textures[0].channel: expected a Channel name, got true"),
    (("textures", 0, "locking"), 1.5, "textures[0].locking: expected a Locking name, got float"),
    (("textures", 0, "components", 0, "domain"), ["DOMAIN_SPATIAL"],
     "textures[0].components[0].domain: expected a Domain name, got an array"),
    (("metadata",), "a title", "metadata: expected an object, got the string 'a title'"),
    (("metadata", "title"), 5, "metadata.title: expected a string, got int 5"),
    (("version",), [1, 0], "version: expected an object, got an array"),
    (("textures",), {"name": "a"}, "textures: expected an array, got an object"),
    (("textures", 0), "plain", "textures[0]: expected an object, got the string 'plain'"),
]


@pytest.mark.parametrize(("path", "value", "message"), WRONG_TYPES,
                         ids=[".".join(map(str, p)) + "=" + repr(v) for p, v, _ in WRONG_TYPES])
def test_a_value_of_the_wrong_type_is_refused_naming_its_field(path, value, message) -> None:
    with pytest.raises(CardError, match="JSON does not match the card schema") as caught:
        card_io.card_from_bytes(mutated(path, value), source="bad.json")
    assert message in str(caught.value)
    assert "bad.json" in str(caught.value)


@pytest.mark.parametrize("name", ["CHANNEL_EVV", "channel_uv", "UV", ""])
def test_an_unknown_enum_name_is_an_error_not_a_dropped_field(name: str) -> None:
    with pytest.raises(CardError, match=r"unknown Channel .* rule C5"):
        card_io.card_from_bytes(mutated(("textures", 0, "components", 0, "channel"), name))


@pytest.mark.parametrize("text", ["0.0_2", "\u0662\u0660", "\uff12\uff10", "1e", "+5", " 20",
                                  "0x10", "inf"])
def test_a_number_in_a_string_takes_ascii_digits_only(text: str) -> None:
    with pytest.raises(CardError, match=r"surface\.width_mm: expected a number"):
        card_io.card_from_bytes(mutated(("surface", "width_mm"), text))


def test_what_the_protobuf_json_mapping_allows_still_loads() -> None:
    obj = copy.deepcopy(BASE)
    obj["surface"] = {"widthMm": "20", "heightMm": 10}  # camelCase, a number as a string
    obj["grid"]["cols"] = "2"  # an integer as a string
    obj["grid"]["rows"] = 1.0  # a whole number written with a point
    obj["textures"][0]["channel"] = 1  # an enum by number
    obj["textures"][0]["components"][0]["channel"] = None  # null: the default
    obj["extension_of_1_1"] = {"nested": [{"deep": 1}]}  # an unknown field (V4)
    card = card_io.card_from_bytes(json.dumps(obj).encode())
    assert card.surface.width_mm == 20.0 and card.grid.cols == 2 and card.grid.rows == 1
    assert card.textures[0].channel == 1
    assert card.textures[0].components[0].channel == 0
    nan = card_io.card_from_bytes(mutated(("surface", "width_mm"), "NaN"))
    assert nan.surface.width_mm != nan.surface.width_mm  # parsed; validation refuses it
    with pytest.raises(CardError, match="width_mm"):
        card_io.parse_card(mutated(("surface", "width_mm"), "NaN"))


def test_nesting_and_integer_length_are_bounded_with_one_clear_error() -> None:
    deep = ('{"x":' * 5000 + "1" + "}" * 5000).encode()
    with pytest.raises(CardError, match=f"nested deeper than {MAX_JSON_DEPTH}"):
        card_io.card_from_bytes(deep)
    inside_unknown = ('{"x":' * (MAX_JSON_DEPTH + 1) + "1" + "}" * (MAX_JSON_DEPTH + 1)).encode()
    with pytest.raises(CardError, match=f"nested {MAX_JSON_DEPTH + 1} .* more than"):
        card_io.card_from_bytes(inside_unknown)
    huge = json.dumps(BASE).replace('"major": 1', '"major": ' + "9" * 5000).encode()
    with pytest.raises(CardError, match="5000 digits"):
        card_io.card_from_bytes(huge)
    with pytest.raises(CardError, match="NaN is not JSON"):
        card_io.card_from_bytes(json.dumps(BASE).replace("20.0", "NaN").encode())


def test_json_depth_counts_arrays_and_objects() -> None:
    assert json_depth(1) == 0
    assert json_depth({"a": [1, {"b": []}]}) == 4
    assert json_depth(BASE) == 5  # Card / textures / texture / components / component
    assert json_depth(json.loads("[" * 900 + "]" * 900)) == 900
    with pytest.raises(JsonInputError) as caught:
        parse_json('{"a": 1,\n "b": }')
    assert (caught.value.line, caught.value.column) == (2, 7)


def _recording(tmp_path: Path, sidecar: str) -> Path:
    path = tmp_path / "rec.csv"
    path.write_text("t_s,amplitude_um,fn_n,fl_n\n0,1,0.5,0.2\n0.001,1,0.5,0.2\n")
    (tmp_path / "rec.csv.json").write_text(sidecar)
    return path


@pytest.mark.parametrize(("sidecar", "message"), [
    ('{"device": "a", "n": ' + "7" * 5000 + "}", "rec.csv.json: bad sidecar JSON (Exceeds"),
    ('{"device": "a", "x": ' + "[" * 5000 + "]" * 5000 + "}",
     f"rec.csv.json: bad sidecar JSON (nested deeper than {MAX_JSON_DEPTH}"),
    ('{"device": "a", "x": NaN}', "rec.csv.json: bad sidecar JSON (NaN is not JSON"),
])
def test_a_sidecar_beyond_the_bounds_is_one_clear_error(tmp_path: Path, sidecar: str,
                                                        message: str) -> None:
    with pytest.raises(MeasurementError) as caught:
        read_measurement(_recording(tmp_path, sidecar))
    assert message in str(caught.value)


def test_a_profile_nested_too_deep_is_one_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "profile.json"
    path.write_text('{"name": ' + "[" * 5000 + "]" * 5000 + "}")
    with pytest.raises(ProfileError, match=r"profile.json: not valid JSON \(nested deeper"):
        DeviceProfile.load(path)


def test_validate_reports_a_wrong_type_in_one_line_without_a_traceback(tmp_path: Path) -> None:
    path = tmp_path / "card.json"
    path.write_bytes(mutated(("textures", 0, "channel"), "CHANNEL_EVV"))
    result = CliRunner().invoke(cli, ["validate", str(path)])
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    assert "textures[0].channel: unknown Channel 'CHANNEL_EVV'" in result.output
    assert str(path) in result.output
