"""A recording's sidecar names its card and track relative to its own folder and never outside
it (spec/measurement-format.md MF13). On main ``card.path`` was resolved against the working
directory and could climb out with ``../..``: ``hcard calibrate --verify`` then loaded the
held-out card and track from wherever it pointed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from hcard import build, card_io
from hcard.calibration.measurement import (
    Measurement,
    MeasurementError,
    read_measurement,
    write_measurement,
)
from hcard.cli.main import cli

CSV = "t_s,fn_n,fl_n,amplitude_m\n0,0.5,0.2,1e-6\n0.001,0.5,0.2,1e-6\n"


def _recording(folder: Path, card_path: object, track: object = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "rec.csv"
    path.write_text(CSV)
    sidecar = {"device": "bench", "card": {"path": card_path}, "session": {"track": track}}
    (folder / "rec.csv.json").write_text(json.dumps(sidecar))
    return path


@pytest.mark.parametrize(("reference", "why"), [
    ("../../etc/verify.hcard", "lies outside the sidecar's folder"),
    ("plan/../../x.hcard", "lies outside the sidecar's folder"),
    ("/etc/passwd", "is an absolute path"),
    (5, "must be a file name or null"),
])
def test_a_reference_out_of_the_sidecars_folder_is_refused_naming_the_key(
        tmp_path: Path, reference: object, why: str) -> None:
    path = _recording(tmp_path / "a" / "b", reference)
    with pytest.raises(MeasurementError) as raised:
        read_measurement(path)
    assert str(raised.value).startswith(f"{path}.json: card.path: ")
    assert why in str(raised.value)
    result = CliRunner().invoke(cli, ["calibrate", str(path), "--verify", "sim://evita",
                                      "-o", str(tmp_path / "calib")])
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    (line,) = result.output.splitlines()
    assert line.startswith(f"Error: {path}.json: card.path: ") and why in line


def test_a_symbolic_link_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "elsewhere").mkdir()
    folder = tmp_path / "recordings"
    folder.mkdir()
    (folder / "plan").symlink_to(tmp_path / "elsewhere")
    path = _recording(folder, None, "plan/track.csv")
    with pytest.raises(MeasurementError, match=r"session\.track: 'plan/track\.csv' lies outside"):
        read_measurement(path)


def test_references_resolve_against_the_sidecars_folder_not_the_working_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = _recording(tmp_path / "rec", "plan/protocol.hcard", "plan/protocol.csv")
    monkeypatch.chdir(tmp_path)  # where plan/protocol.hcard does not exist
    files = read_measurement(path).files
    assert files == {"card.path": (tmp_path / "rec" / "plan" / "protocol.hcard").resolve(),
                     "session.track": (tmp_path / "rec" / "plan" / "protocol.csv").resolve()}
    assert read_measurement(_recording(tmp_path / "none", None)).files == {}


def test_a_writer_names_files_relative_to_the_sidecar_and_outside_ones_not_at_all(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    conditions = {"device": "bench", "card": {"path": "out/plan/protocol.hcard"},
                  "session": {"track": "protocol.csv"}}
    m = Measurement(t=[0.0, 0.001], normal_force=[0.5, 0.5], lateral_force=[0.2, 0.2],
                    amplitude=[1e-6, 1e-6], conditions=conditions)
    write_measurement(m, "out/rec.csv")
    written = json.loads((tmp_path / "out" / "rec.csv.json").read_text())
    assert written["card"]["path"] == "plan/protocol.hcard"
    assert written["session"]["track"] is None  # in the working directory, outside out/
    assert conditions["card"]["path"] == "out/plan/protocol.hcard"  # the caller's is unchanged


def test_calibrate_verify_finds_the_held_out_card_next_to_the_played_one_from_anywhere(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    plan = tmp_path / "work" / "plan"
    plan.mkdir(parents=True)
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    for name in ("protocol.hcard", "verify.hcard"):
        card_io.save(card, plan / name)
    (plan / "verify.csv").write_text("t_s,x_mm,y_mm\n0,1,5\n0.1,2,5\n")
    path = _recording(tmp_path / "work", "plan/protocol.hcard")
    monkeypatch.chdir(tmp_path)  # not the recording's folder
    from hcard.cli import calibrate_cmd

    found = calibrate_cmd._verification_files([read_measurement(path)], None, None)
    assert found == ((plan / "verify.hcard").resolve(), (plan / "verify.csv").resolve())
