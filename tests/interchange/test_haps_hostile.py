"""The ``haps`` importer against hostile and broken files, each refused in bounded time with
one line naming the file, the field and why (spec/interchange/haps.md IH6), and ``hcard
import`` of .haps files from the command line."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest

from hcard.card_io import load
from hcard.errors import AssetError
from hcard_builtins.formats.haps import HapsImporter
from hcard_builtins.formats.haps_parse import MAX_HAPS_BYTES, MAX_KEYFRAMES
from tests.helpers.cli import assert_one_line_error, run_hcard
from tests.interchange.test_haps import haps, note

SECONDS = 10.0
"""Longest a refusal may take (each takes well under one second here)."""
PULSE = note([(0, 1.0), (0.3, 1.0), (0.31, 0.0), (1, 0.0)], [(0, 20.0), (1, 20.0)])
"""One pulse at 20 cycles per unit."""
FIRST_NOTE = "m_texture.m_melodies[0].m_notes[0]"
AMPLITUDE = f"{FIRST_NOTE}.m_hapticEffect.m_amplitudeModulation.m_keyframes"


def refusal(path: Path) -> str:
    """The one-line AssetError of importing ``path``, checked to come in bounded time."""
    started = time.perf_counter()
    with pytest.raises(AssetError) as caught:
        HapsImporter().read(path)
    assert time.perf_counter() - started < SECONDS
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    return message


def document_with(change: Any) -> dict[str, Any]:
    """A one-pulse document after ``change(document)``."""
    document = haps([[json.loads(json.dumps(PULSE))]])
    change(document)
    return document


def first_note(document: dict[str, Any]) -> dict[str, Any]:
    notes: dict[str, Any] = document["m_texture"]["m_melodies"][0]["m_notes"][0]
    return notes


def set_amplitude(index: int, key: str, value: Any) -> Any:
    def change(document: dict[str, Any]) -> None:
        frames = first_note(document)["m_hapticEffect"]["m_amplitudeModulation"]["m_keyframes"]
        frames[index][key] = value
    return change


@pytest.mark.parametrize(("text", "expected"), [
    ("not json at all", "not JSON: line 1 column 1: Expecting value"),
    ("[1, 2, 3]", "a .haps file is a JSON object, not an array"),
    ('{"m_version": "5", "m_texture": ', "not JSON: line 1 column 33: Expecting value"),
    ('{"m_texture": {"m_melodies": [{"m_notes": [{"m_hapticEffect": {"m_amplitudeModulation": '
     '{"m_keyframes": [{"m_time": NaN, "m_value": 1}]}}}]}]}}',
     "not JSON: NaN is not JSON"),
    ('{"m_texture": ' + "[" * 100_000 + "]" * 100_000 + "}",
     "not JSON: nested deeper than 16 arrays and objects"),
    ('{"m_texture": ' + "[" * 20 + "]" * 20 + "}",
     "not JSON: nested 21 arrays and objects deep, more than 16"),
    ('{"m_version": "5", "m_vibration": {"m_melodies": []}}',
     "m_texture: missing: the file holds no texture perception (m_vibration)"),
    ('{"m_texture": []}', "m_texture: must be an object, not an array"),
])
def test_broken_text_is_refused_in_one_line(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "bad.haps"
    path.write_text(text, encoding="utf-8")
    message = refusal(path)
    assert message.startswith(f"{path}: {expected}"), message


@pytest.mark.parametrize(("change", "field", "reason"), [
    (set_amplitude(1, "m_time", "0.3"), f"{AMPLITUDE}[1].m_time", "must be a number, not a "
     "string"),
    (set_amplitude(1, "m_time", -0.5), f"{AMPLITUDE}[1].m_time", "-0.5 is below 0"),
    (set_amplitude(2, "m_time", 0.1), f"{AMPLITUDE}[2].m_time",
     "0.1 comes before the previous keyframe's 0.3 (positions must not decrease)"),
    (set_amplitude(0, "m_value", "__1e999__"), f"{AMPLITUDE}[0].m_value",
     "must be a finite number, not inf"),
    (set_amplitude(0, "m_value", 10**400), f"{AMPLITUDE}[0].m_value",
     "must be a finite number"),
    (set_amplitude(0, "m_value", 1.5), f"{AMPLITUDE}[0].m_value", "1.5 is above 1"),
    (set_amplitude(0, "m_value", True), f"{AMPLITUDE}[0].m_value",
     "must be a number, not a boolean"),
    (lambda d: first_note(d).update(m_length=0), f"{FIRST_NOTE}.m_length", "0 must be above 0"),
    (lambda d: first_note(d).update(m_gain=1e300), f"{FIRST_NOTE}.m_gain", "1e+300 is above"),
    (lambda d: first_note(d)["m_hapticEffect"]["m_frequencyModulation"]["m_keyframes"][0]
     .update(m_value=0.0), f"{FIRST_NOTE}.m_hapticEffect.m_frequencyModulation.m_keyframes[0]"
     ".m_value", "0 must be above 0"),
    (lambda d: first_note(d)["m_hapticEffect"]["m_amplitudeModulation"].update(m_keyframes=[]),
     AMPLITUDE, "empty: a modulation needs a keyframe"),
    (lambda d: d["m_texture"]["m_melodies"][0].update(m_notes={}),
     "m_texture.m_melodies[0].m_notes", "must be an array, not an object"),
    (lambda d: d.update(m_length_unit="mm"), "m_length_unit",
     "must be an integer, not a string"),
    (lambda d: d["m_texture"]["m_melodies"].clear(), "m_texture",
     "no texture notes to import (0 melodies, 0 notes)"),
])
def test_bad_values_name_their_field(tmp_path: Path, change: Any, field: str,
                                     reason: str) -> None:
    path = tmp_path / "bad.haps"
    # 1e999 is valid JSON that Python reads as infinity (json.dumps would write "Infinity")
    text = json.dumps(document_with(change)).replace('"__1e999__"', "1e999")
    path.write_text(text, encoding="utf-8")
    assert refusal(path).startswith(f"{path}: {field}: {reason}")


def test_a_transient_only_texture_is_refused_naming_m_texture(tmp_path: Path) -> None:
    """IH2: a note with ``m_type`` and no curves (a transient) is skipped; none left: refused."""
    document = document_with(lambda d: first_note(d).update(m_hapticEffect={"m_type": 0}))
    path = tmp_path / "transient.haps"
    path.write_text(json.dumps(document), encoding="utf-8")
    assert refusal(path) == (f"{path}: m_texture: no texture notes to import (1 melodies, "
                             f"1 notes; skipped: {FIRST_NOTE} (m_type 0: a note without "
                             "amplitude and frequency keyframes))")


def test_too_many_keyframes_are_refused_past_the_limit(tmp_path: Path) -> None:
    """IH6: 120,000 keyframes (3 MB, within the byte limit) pass the 100,000 keyframe limit."""
    frames = [(i / 120_000, 1.0) for i in range(120_000)]
    path = tmp_path / "many.haps"
    path.write_text(json.dumps(haps([[note(frames, [(0, 5.0)])]])), encoding="utf-8")
    assert refusal(path) == (f"{path}: {AMPLITUDE}: more than {MAX_KEYFRAMES} keyframes in the "
                             "texture perception")


def test_a_million_keyframes_are_refused_by_size_before_parsing(tmp_path: Path) -> None:
    """IH6: 10^6 keyframes take 26 MB, over the 16 MiB read limit: refused unread."""
    body = ",".join(['{"m_time":0,"m_value":1}'] * 1_000_000)
    path = tmp_path / "million.haps"
    path.write_text('{"m_texture":{"m_melodies":[{"m_notes":[{"m_hapticEffect":'
                    '{"m_amplitudeModulation":{"m_keyframes":[' + body + ']}}}]}]}}',
                    encoding="utf-8")
    size = path.stat().st_size
    assert refusal(path) == f"{path}: {size} bytes exceed the limit of {MAX_HAPS_BYTES} bytes"


def test_a_huge_sparse_file_is_refused_unread(tmp_path: Path) -> None:
    """IH6: a file claiming 1 TB (sparse) is refused by its size alone."""
    path = tmp_path / "huge.haps"
    with path.open("wb") as file:
        file.write(b'{"m_texture": ')
        file.truncate(10**12)
    assert refusal(path) == f"{path}: {10**12} bytes exceed the limit of {MAX_HAPS_BYTES} bytes"


def test_a_texture_too_long_for_the_card_is_refused(tmp_path: Path) -> None:
    """IH7: 200 units at the default 100 mm are 20 m, over the card's 10 m side."""
    long_note = note([(0, 1.0), (200, 1.0)], [(0, 5.0)], length=200.0)
    path = tmp_path / "long.haps"
    path.write_text(json.dumps(haps([[long_note]])), encoding="utf-8")
    assert "m_texture: the texture's 200 units at 100 mm per unit make 20000 mm" in \
        refusal(path)


# --- hcard import ---------------------------------------------------------------------------

def pulse_file(tmp_path: Path) -> Path:
    path = tmp_path / "pulse.haps"
    path.write_text(json.dumps(haps([[PULSE]])), encoding="utf-8")
    return path


def test_hcard_import_recognises_haps_and_writes_the_card(tmp_path: Path) -> None:
    """The pulse at 10 mm per unit: 10 mm wide, fidelity printed in JND."""
    out = tmp_path / "pulse.hcard"
    result = run_hcard("import", pulse_file(tmp_path), "-o", out, "--length-unit-mm", 10)
    assert result.exit_code == 0, result.output
    card = load(out)
    assert card.surface.width_mm == pytest.approx(10.0)
    assert card.textures[0].components[0].frequency == pytest.approx(2.0)
    assert "haps: Interhaptics .haps v5, texture perception: 1 notes" in result.stdout
    assert "x the 0.08 friction JND" in result.stdout


def test_hcard_import_json_summary(tmp_path: Path) -> None:
    out = tmp_path / "pulse.json"
    result = run_hcard("import", pulse_file(tmp_path), "-o", out, "--json",
                       "--friction-range", 1.0, 1.6, "--taxtel-mm", 1, "--title", "Pulse")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["format"] == "haps"
    assert summary["width_mm"] == pytest.approx(100.0) and summary["length_unit_mm"] == 100.0
    assert summary["channel"] == "ev" and summary["friction_range"] == [1.0, 1.6]
    assert summary["rms_error_jnd"] < 0.6 and summary["max_error_jnd"] < 5.0
    assert "position-only" in summary["fidelity_basis"]
    assert load(out).metadata.title == "Pulse"


def test_hcard_import_refuses_an_option_of_bitmaps(tmp_path: Path) -> None:
    result = run_hcard("import", pulse_file(tmp_path), "-o", tmp_path / "x.hcard", "--dpi", 160)
    assert_one_line_error(result, "--dpi does not apply to .haps import", status=2,
                          after_usage=True)


def test_hcard_import_of_a_hostile_file_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.haps"
    path.write_text(json.dumps(document_with(set_amplitude(1, "m_time", "0.3"))),
                    encoding="utf-8")
    result = run_hcard("import", path, "-o", tmp_path / "x.hcard")
    assert_one_line_error(result, str(path), f"{AMPLITUDE}[1].m_time",
                          "must be a number, not a string")
    assert not (tmp_path / "x.hcard").exists()
