"""Hostile inputs other than the 16 MiB cards of tests/card/test_bounded_resources.py: each gets one
clear line (``Error: FILE: ...``) naming the file, exit status 1 and no traceback: duplicate
JSON keys (spec/README.md F3, spec/device-profile.md DP1, spec/measurement-format.md MF8), a
byte-order mark (accepted everywhere), a track whose span is infinitely many frames or that
holds too many samples (spec/track-format.md TK8), a directory given as an input file, and the
true count of a card's problems."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from hcard import build, card_io, track
from hcard.calibration.measurement import MeasurementError, read_measurement
from hcard.cli.main import cli
from hcard.errors import CardError
from hcard.physics.profile import DeviceProfile, ProfileError
from tests.helpers.cli import run_hcard
from tests.helpers.hostile_cards import indices_out_of_range
from tests.helpers.repository import REPO

CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
SIDECAR = {"device": "bench tribometer", "plate_frequency_hz": 30000.0}
CSV = "t_s,fn_n,fl_n,amplitude_m\n0,0.5,0.2,1e-6\n0.001,0.5,0.2,1e-6\n"


def run(*args: object) -> tuple[int, str]:
    """Exit status and everything ``hcard ARGS`` printed."""
    result = run_hcard(*args)
    return result.exit_code, result.output


def one_error_line(output: str, path: Path | str) -> str:
    """The one ``Error:`` line of ``output``, which names ``path``."""
    assert "Traceback" not in output
    (line,) = [text for text in output.splitlines() if text.startswith("Error:")]
    assert line.startswith(f"Error: {path}: "), line
    return line


def profile_text() -> str:
    return DeviceProfile.coupled_stimulator().to_json().decode()


# -- duplicate keys ------------------------------------------------------------------------------
def test_a_card_key_given_twice_is_an_error_naming_it(tmp_path: Path) -> None:
    text = card_io.to_json(CARD).replace('"width_mm": 20.0', '"width_mm": 20.0, "width_mm": 9000.0')
    path = tmp_path / "twice.json"
    path.write_text(text)
    code, output = run("validate", path)
    assert code == 1
    assert "key 'width_mm' appears twice in one object" in output
    with pytest.raises(CardError, match="'width_mm' appears twice"):
        card_io.load(path)


def test_a_card_field_under_both_its_names_is_an_error_naming_them(tmp_path: Path) -> None:
    text = card_io.to_json(CARD).replace('"width_mm": 20.0', '"width_mm": 20.0, "widthMm": 9000.0')
    path = tmp_path / "both.json"
    path.write_text(text)
    code, output = run("render", path, "--track", path, "-o", tmp_path / "out.csv")
    assert code == 1
    line = one_error_line(output, path)
    assert "surface.width_mm: given twice, as 'width_mm' and 'widthMm'" in line


def test_a_profile_key_given_twice_is_an_error_naming_it(tmp_path: Path) -> None:
    text = profile_text().replace('"name": "coupled-stimulator"',
                                  '"name": "coupled-stimulator", "name": "other"')
    path = tmp_path / "twice.profile.json"
    path.write_text(text)
    with pytest.raises(ProfileError, match="key 'name' appears twice"):
        DeviceProfile.load(path)
    code, output = run("predict", "--profile", path)
    assert code == 1
    assert "key 'name' appears twice" in one_error_line(output, path)


def test_a_sidecar_key_given_twice_is_an_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    path.write_text(CSV)
    text = json.dumps(SIDECAR).replace('"device": "bench tribometer"',
                                       '"device": "bench tribometer", "device": "other"')
    (tmp_path / "rec.csv.json").write_text(text)
    with pytest.raises(MeasurementError, match="key 'device' appears twice"):
        read_measurement(path)


# -- byte-order marks ----------------------------------------------------------------------------
def test_a_byte_order_mark_is_accepted_in_every_file(tmp_path: Path) -> None:
    bom = "\ufeff"
    card = tmp_path / "card.json"
    card.write_text(bom + card_io.to_json(CARD), encoding="utf-8")
    profile = tmp_path / "p.profile.json"
    profile.write_text(bom + profile_text(), encoding="utf-8")
    recording = tmp_path / "rec.csv"
    recording.write_text(bom + CSV, encoding="utf-8")
    (tmp_path / "rec.csv.json").write_text(bom + json.dumps(SIDECAR), encoding="utf-8")
    stroke = tmp_path / "track.csv"
    stroke.write_text(bom + "t_s,x_mm,y_mm\n0,1,5\n0.1,2,5\n", encoding="utf-8")
    assert card_io.load(card) == CARD
    assert DeviceProfile.load(profile).name == "coupled-stimulator"
    assert read_measurement(recording).conditions == SIDECAR
    assert len(track.read_track_csv(stroke)) == 2
    code, output = run("render", card, "--track", stroke, "-o", tmp_path / "out.csv",
                       "--profile", profile)
    assert code == 0, output


# -- tracks (spec/track-format.md TK8) ------------------------------------------------------------
def test_a_track_spanning_infinitely_many_frames_is_refused_in_one_line(tmp_path: Path) -> None:
    card = tmp_path / "card.hcard"
    card_io.save(CARD, card)
    stroke = tmp_path / "track.csv"
    stroke.write_text("t_s,x_mm,y_mm\n0,1,5\n1e305,2,5\n")
    out = tmp_path / "out.csv"
    out.write_text("previous\n")
    code, output = run("render", card, "--track", stroke, "-o", out)
    assert code == 1
    line = one_error_line(output, stroke)
    assert "t_s: the track spans 1e+305 s: inf frames" in line and "TK8" in line
    assert out.read_text() == "previous\n"


def test_a_track_with_more_samples_than_the_limit_is_refused_naming_the_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(track, "MAX_TRACK_SAMPLES", 1000)
    stroke = tmp_path / "track.csv"
    stroke.write_text("t_s,x_mm,y_mm\n# a comment\n"
                      + "".join(f"{i * 1e-3!r},1,5\n" for i in range(1001)))
    with pytest.raises(track.TrackError) as raised:
        track.read_track_csv(stroke)
    assert str(raised.value) == (f"{stroke}:1003: more than 1000 rows of data (the most a track "
                                 "may hold, spec/track-format.md TK8)")
    stroke.write_text("t_s,x_mm,y_mm\n" + "".join(f"{i * 1e-3!r},1,5\n" for i in range(1000)))
    assert len(track.read_track_csv(stroke)) == 1000


def test_the_track_limit_is_the_one_the_spec_states() -> None:
    text = (REPO / "spec" / "track-format.md").read_text()
    assert f"at most {track.MAX_TRACK_SAMPLES:,} (2^22) samples" in text
    assert track.MAX_TRACK_SAMPLES == 2**22


# -- directories as input ------------------------------------------------------------------------
def _inputs(tmp_path: Path) -> tuple[Path, Path, Path]:
    card = tmp_path / "card.hcard"
    card_io.save(CARD, card)
    stroke = tmp_path / "track.csv"
    stroke.write_text("t_s,x_mm,y_mm\n0,1,5\n0.1,2,5\n")
    folder = tmp_path / "a folder"
    folder.mkdir()
    return card, stroke, folder


@pytest.mark.parametrize("command", [
    ["validate", "{dir}"], ["info", "{dir}"], ["preview", "{dir}"],
    ["render", "{dir}", "--track", "{track}", "-o", "{out}.csv"],
    ["render", "{card}", "--track", "{dir}", "-o", "{out}.csv"],
    ["render", "{card}", "--track", "{track}", "-o", "{out}.csv", "--profile", "{dir}"],
    ["predict", "--profile", "{dir}"],
    ["encode", "{dir}", "-o", "{out}.hcard"],
    ["play", "{dir}", "--device", "sim://evita", "--track", "{track}", "-o", "{out}.csv"],
    ["play", "{card}", "--device", "sim://evita", "--track", "{dir}", "-o", "{out}.csv"],
    ["calibrate", "{recording}", "--profile", "{dir}"],
])
def test_a_directory_as_an_input_file_is_invalid_input(tmp_path: Path, command: list[str]) -> None:
    card, stroke, folder = _inputs(tmp_path)
    recording = tmp_path / "rec.csv"
    recording.write_text(CSV)
    (tmp_path / "rec.csv.json").write_text(json.dumps(SIDECAR))
    args = [a.format(dir=folder, track=stroke, card=card, recording=recording,
                     out=tmp_path / "out") for a in command]
    code, output = run(*args)
    assert code == 1, output
    assert "Traceback" not in output
    (line,) = output.splitlines()  # validate speaks its own form: "FILE: error F7: reason"
    assert line.startswith((f"Error: {folder}: is a directory", f"{folder}: error F7: is a "
                                                                "directory")), line


# -- the true count of problems ------------------------------------------------------------------
def test_validate_counts_every_problem_and_lists_a_bounded_number(tmp_path: Path) -> None:
    path = tmp_path / "indices.hcard"
    path.write_bytes(indices_out_of_range(count=20_000))
    code, output = run("validate", path)
    assert code == 1
    # G6 for each of the 20000 indices, and G5: 20000 entries for a 1 x 1 grid
    assert f"{path}: invalid: 20001 problem(s), 20001 error(s)" in output
    assert output.count(" G6: grid.texture_index[") == 99  # MAX_LISTED_PROBLEMS, G5 first
    code, output = run("info", path)
    assert f"{path}: invalid: 20001 error(s)" in output
    report = json.loads(CliRunner().invoke(cli, ["validate", "--json", str(path)]).stdout)
    assert report["problem_count"] == 20001
    with pytest.raises(CardError, match=r"\(and 20000 more problems\)"):
        card_io.load(path)
