"""The exporter's .hjif against MPEG's public JSON schemas and against what the MPEG reference
software requires beyond them (spec/interchange/hjif.md IJ20-IJ29), one test per requirement."""

from __future__ import annotations

import json
import re

import pytest

from tests.interchange.hjif_cards import CARDS, SCHEMAS, _fixed_date, exported_json, walk

__all__ = ["_fixed_date"]

jsonschema = pytest.importorskip("jsonschema")
referencing = pytest.importorskip("referencing")


def _validator():
    from referencing.jsonschema import DRAFT4

    resources = [(path.name, DRAFT4.create_resource(json.loads(path.read_text())))
                 for path in sorted(SCHEMAS.glob("*.schema.json"))]
    registry = referencing.Registry().with_resources(resources)
    top = json.loads((SCHEMAS / "MPEG_haptics.schema.json").read_text())
    return jsonschema.Draft4Validator(top, registry=registry)


@pytest.fixture(scope="module")
def validator():
    return _validator()


@pytest.fixture(scope="module", params=sorted(CARDS))
def document(request):
    import os

    os.environ["SOURCE_DATE_EPOCH"] = "1700000000"
    return exported_json(CARDS[request.param]())


def test_the_schemas_are_the_ten_public_files() -> None:
    assert len(list(SCHEMAS.glob("*.schema.json"))) == 10


def test_every_export_validates_against_the_public_schemas(validator, document) -> None:
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in validator.iter_errors(document)]
    assert errors == []


def test_the_schema_check_is_live(validator) -> None:
    """The validator refuses what the schema refuses: 'Texture' is no modality of it (the
    reference's own name for Vibrotactile Texture), a phase of 6.3 is above its 6.28318."""
    document = exported_json(CARDS["mixed"]())
    document["perceptions"][0]["perception_modality"] = "Texture"
    document["perceptions"][0]["channels"][0]["bands"][1]["effects"][0]["phase"] = 6.3
    messages = sorted(e.message for e in validator.iter_errors(document))
    assert len(messages) == 2
    assert "'Texture' is not one of" in messages[0]
    assert "6.3 is greater than the maximum of 6.28318" in messages[1]


def test_ij20_timescale_and_syncs_are_present(document) -> None:
    assert isinstance(document["timescale"], int) and 1 <= document["timescale"] <= 48000
    assert document["syncs"] == [] and document["avatars"] == []


def test_ij21_version_is_an_edition_the_reference_accepts(document) -> None:
    assert document["version"] == "2023"
    assert re.fullmatch(r"[0-9]{4}(-[1-9])?", document["version"])


def test_ij22_profile_is_main_for_friction_and_electrotactile(document) -> None:
    assert document["profile"] == "Main"
    modalities = {p["perception_modality"] for p in document["perceptions"]}
    assert modalities <= {"Friction", "Electrotactile"}


def test_ij23_every_channel_has_an_integer_body_part_mask(document) -> None:
    channels = [c for p in document["perceptions"] for c in p["channels"]]
    assert channels
    assert all(type(c["body_part_mask"]) is int and c["body_part_mask"] == 0 for c in channels)


def test_ij24_modality_strings_are_exactly_the_schema_names(document) -> None:
    for perception in document["perceptions"]:
        assert perception["perception_modality"] in ("Friction", "Electrotactile")


def test_ij25_band_limits_and_frequencies_are_json_integers(document) -> None:
    found = 0
    for _, key, value in walk(document):
        if key in ("lower_frequency_limit", "upper_frequency_limit", "frequency_modulation",
                   "relative_position", "position", "id", "timescale", "level"):
            assert type(value) is int, (key, value)
            found += 1
        if key in ("lower_frequency_limit", "upper_frequency_limit", "frequency_modulation"):
            assert 0 <= value <= 10000
    assert found >= 12


def test_ij26_no_effect_semantic_scheme(document) -> None:
    keys = {key for _, key, _ in walk(document)}
    assert "effect_semantic_scheme" not in keys and "semantic_keywords" not in keys


def test_ij13_phases_are_float32_within_the_schema(document) -> None:
    import numpy as np

    phases = [v for _, key, v in walk(document) if key == "phase"]
    assert phases
    for phase in phases:
        assert 0.0 <= phase <= 6.28318
        assert float(np.float32(phase)) == phase


def test_ij13_each_effect_has_one_frequency_keyframe(document) -> None:
    """The reference accumulates phase across frequency keyframes with a millisecond factor
    in its code: a second one at a timescale other than 1000 inverts the signal after it."""
    effects = [effect for perception in document["perceptions"]
               for channel in perception["channels"] for band in channel["bands"]
               for effect in band["effects"] if band["band_type"] == "VectorialWave"]
    assert effects
    for effect in effects:
        assert sum("frequency_modulation" in key for key in effect["keyframes"]) == 1


def test_ij28_level_follows_the_channel_and_band_counts(document) -> None:
    channels = max(len(p["channels"]) for p in document["perceptions"])
    bands = max(len(c["bands"]) for p in document["perceptions"] for c in p["channels"])
    assert document["level"] == (1 if channels <= 128 and bands <= 7 else 2)


def test_the_fine_card_is_level_2_in_decimetres() -> None:
    document = exported_json(CARDS["fine"]())
    assert document["level"] == 2
    assert document["timescale"] == 4000
    perception = document["perceptions"][0]
    assert perception["unit_exponent"] == -1
    band = perception["channels"][0]["bands"][1]
    assert band["lower_frequency_limit"] == band["upper_frequency_limit"] == 2500
