"""The info, validate and render commands, and user errors without tracebacks (item 6)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

import hcard
from hcard.card_io import to_bytes
from hcard.cli.main import cli
from hcard.render import render
from hcard.track import read_track_csv, straight_stroke, track_to_csv
from tests.helpers.cards import two_texture_card
from tests.helpers.cli import assert_one_line_error
from tests.helpers.cli import run_hcard as run


@pytest.fixture()
def card_file(tmp_path):
    path = tmp_path / "two.hcard"
    hcard.save(two_texture_card(), path)
    return path


@pytest.fixture()
def track_file(tmp_path):
    path = tmp_path / "stroke.csv"
    stroke = straight_stroke((1.0, 5.0), (40.0, 0.0), 0.4)
    path.write_text("# a 0.4 s stroke\n" + track_to_csv(stroke))
    return path


def test_every_command_has_help():
    for command in ("encode", "info", "validate", "render", "preview", "plugins"):
        result = run(command, "--help")
        assert result.exit_code == 0 and "Usage: " in result.output
        assert len(result.output.splitlines()) > 3


def test_info_summarises_the_card(card_file):
    result = run("info", card_file)
    assert result.exit_code == 0, result.output
    assert "surface: 20 x 10 mm" in result.output
    assert "grid: 4 x 2 taxtels of 5 x 5 mm" in result.output
    assert "[0] 'grating': baseline 0.7, UV, velocity locking, 2 component(s), on 4 taxtel(s)" \
        in result.output
    assert "spatial 1 c/mm (period 1 mm)" in result.output
    assert "orientation=30.0 deg" in result.output


def test_validate_accepts_a_good_card(card_file):
    result = run("validate", card_file)
    assert result.exit_code == 0
    assert "valid hcard 1.0 card (binary, 2 textures, 4 x 2 taxtels)" in result.output


def test_validate_lists_field_paths_and_exits_non_zero(tmp_path):
    card = two_texture_card()
    card.textures[0].components[0].frequency = -2.0
    card.grid.texture_index[3] = 7
    path = tmp_path / "bad.hcard"
    path.write_bytes(to_bytes(card))
    result = run("validate", path)
    assert result.exit_code == 1
    assert "textures[0].components[0].frequency: must be > 0, got -2.0" in result.output
    assert "grid.texture_index[3]: texture 7 is outside the palette" in result.output
    as_json = run("validate", "--json", path)
    assert as_json.exit_code == 1 and '"valid": false' in as_json.output


@pytest.mark.parametrize("command", ["info", "validate", "preview"])
def test_corrupt_and_missing_cards_give_one_line(command, tmp_path):
    """One line: ``Error: ...``, or for validate the file's one finding with its rule."""
    if command == "validate":
        def one_line_error(result, *fragments):
            assert result.exit_code == 1
            lines = [line for line in result.output.splitlines() if line.strip()]
            assert len(lines) == 1, lines
            assert any(f": error {rule}: " in lines[0] for rule in ("F7", "V1")), lines
            for fragment in fragments:
                assert fragment in lines[0]
    else:
        one_line_error = assert_one_line_error
    corrupt = tmp_path / "corrupt.hcard"
    corrupt.write_bytes(b"\x0a\xff\x01")
    extra = ["-o", tmp_path / "p.png"] if command == "preview" else []
    one_line_error(run(command, corrupt, *extra), "corrupt.hcard", "corrupt or truncated")
    one_line_error(run(command, tmp_path / "none.hcard", *extra), "none.hcard", "no such file")
    future = tmp_path / "future.hcard"
    card = two_texture_card()
    card.version.major = 3
    future.write_bytes(to_bytes(card))
    one_line_error(run(command, future, *extra), "unsupported major version 3")


def test_render_csv_matches_the_renderer(card_file, track_file, tmp_path):
    out = tmp_path / "frames.csv"
    result = run("render", card_file, "--track", track_file, "-o", out)
    assert result.exit_code == 0, result.output
    assert "4001 frames at 10000 Hz" in result.output
    table = np.genfromtxt(out, delimiter=",", names=True)
    frames = render(two_texture_card(), read_track_csv(track_file))
    assert table.dtype.names == ("t_s", "uv", "ev", "friction", "contact", "texture")
    assert np.array_equal(table["uv"], frames.uv)  # round-trip exact (spec rule TO1)
    assert np.array_equal(table["friction"], frames.friction)
    assert np.array_equal(table["texture"].astype(int), frames.texture)


def test_render_npz_and_position_only(card_file, track_file, tmp_path):
    out = tmp_path / "frames.npz"
    result = run("render", card_file, "--track", track_file, "-o", out, "--mode", "position-only",
                 "--frame-rate", "2000", "--band-limit", "500")
    assert result.exit_code == 0, result.output
    data = np.load(out)
    assert data["t_s"].shape == (801,) and data["contact"].dtype == bool
    assert data["texture"].dtype == np.int32
    assert math.isclose(data["t_s"][1] - data["t_s"][0], 1 / 2000)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("t_s,x_mm\n0,1\n", "header lacks column(s) y_mm"),
        ("t_s,x_mm,y_mm\n0,1,1\n0.01,abc,1\n", "bad.csv:3: column x_mm: 'abc' is not a number"),
        ("t_s,x_mm,y_mm\n0,1,1\n0.01,\u0662,1\n", "column x_mm: '\u0662' is not a number"),
        ("t_s,x_mm,y_mm\n0,1,1\n0.01,0.0_2,1\n", "column x_mm: '0.0_2' is not a number"),
        ("t_s,x_mm,y_mm\n0,1,1\n0.01,1\n", "bad.csv:3: row has 2 fields, the header has 3"),
        ("t_s,t_s,x_mm,y_mm\n0,1,1,1\n", "column 't_s' appears twice in the header"),
        ("t_s;x_mm;y_mm\n0;1;1\n", "the columns are separated by semicolons"),
        ("t_s,x_mm,y_mm\n0," + "x" * 200_000 + ",1\n", "a cell may hold at most 131072"),
        ("t_s,x_mm,y_mm\n0,1,1\n0,2,1\n", "time must increase strictly"),
        ("t_s,x_mm,y_mm\n0,1,1\n0.02,nan,1\n", "non-finite value"),
        ("t_s,x_mm,y_mm,contact\n0,1,1,2\n", "only 0 or 1"),
        ("# nothing\n", "empty file (no header row)"),
    ],
)
def test_bad_tracks_give_one_line(card_file, tmp_path, text, message):
    """(Cases of every bad-input class of the track reader; the huge cell is 200,000 chars.)"""
    track = tmp_path / "bad.csv"
    track.write_text(text)
    assert_one_line_error(run("render", card_file, "--track", track, "-o", tmp_path / "o.csv"),
                          message)


def test_bad_render_options(card_file, track_file, tmp_path):
    result = run("render", card_file, "--track", track_file, "-o", tmp_path / "o.txt")
    assert result.exit_code == 2 and "must end in .csv or .npz" in result.output
    result = run("render", card_file, "--track", track_file, "-o", tmp_path / "o.csv",
                 "--frame-rate", "1000", "--band-limit", "900")
    assert result.exit_code == 2 and "alias" in result.output


def test_console_script_reports_user_errors_without_traceback(tmp_path):
    missing = tmp_path / "missing.hcard"
    proc = subprocess.run([sys.executable, "-m", "hcard", "info", str(missing)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.strip() == f"Error: {missing}: no such file"
    assert "Traceback" not in proc.stderr


def test_version_names_the_card_format_the_tool_implements() -> None:
    from hcard import __version__
    from hcard.limits import FORMAT_MAJOR, FORMAT_MINOR

    result = CliRunner().invoke(cli, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == (
        f"hcard {__version__} (card format {FORMAT_MAJOR}.{FORMAT_MINOR})")


def test_exit_statuses_tell_invalid_input_from_usage_and_from_a_bug(tmp_path, monkeypatch) -> None:
    """0 ok, 1 invalid input or a failed check, 2 usage, 3 internal error (a bug)."""
    from hcard import build, card_io
    from hcard.cli import card_cmds

    good = tmp_path / "good.hcard"
    card_io.save(build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5,
                                                                                  channel="uv")]),
                 good)
    bad = tmp_path / "bad.hcard"
    bad.write_bytes(b"\xff\xff\xff")
    runner = CliRunner()
    assert runner.invoke(cli, ["validate", str(good)]).exit_code == 0
    assert runner.invoke(cli, ["validate", str(bad)]).exit_code == 1
    assert runner.invoke(cli, ["validate", str(tmp_path / "missing.hcard")]).exit_code == 1
    assert runner.invoke(cli, ["validate", "--no-such-option", str(good)]).exit_code == 2

    def broken(card):
        raise ZeroDivisionError("injected")

    monkeypatch.setattr(card_cmds, "validate", broken)
    crashed = runner.invoke(cli, ["validate", str(good)])
    assert crashed.exit_code == 3
    assert "internal error (ZeroDivisionError): this is a bug" in crashed.output
    assert "Traceback" in crashed.output


def test_conformance_json_to_standard_output_holds_only_the_json() -> None:
    result = CliRunner().invoke(cli, ["conformance", "--driver", "sim://", "--level", "format",
                                      "--json", "-", "-q"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["passed"] is True and report["totals"]["cases"] >= 40
    assert "PASS" not in result.stdout.split("\n", 1)[0]  # the table went to stderr
    assert not Path("-").exists()


def test_global_quiet_leaves_out_progress_lines_and_quiet_with_verbose_is_usage(tmp_path):
    runner = CliRunner()
    args = ["conformance", "--driver", "sim://", "--level", "format"]
    loud = runner.invoke(cli, args)
    assert loud.exit_code == 0 and "case(s), ok" in loud.stderr
    hushed = runner.invoke(cli, ["-q", *args])
    assert hushed.exit_code == 0 and "case(s), ok" not in hushed.stderr
    assert "PASS" in hushed.stdout or "passed" in hushed.stdout.lower()  # the result prints
    listed = runner.invoke(cli, ["-v", *args])
    assert len(listed.stdout.splitlines()) > len(hushed.stdout.splitlines())  # every case
    both = runner.invoke(cli, ["-q", "-v", "validate", str(tmp_path / "b.hcard")])
    assert both.exit_code == 2 and "give -q or -v, not both" in both.output


def test_the_command_list_is_each_commands_own_first_sentence():
    from hcard.cli.main import COMMAND_MODULES, COMMAND_SUMMARIES, cli, contributed_commands

    context = click.Context(cli)
    assert sorted(COMMAND_SUMMARIES) == sorted(COMMAND_MODULES)
    contributed = {name: c.summary for name, c in contributed_commands().items()}
    # The device and conformance packages contribute their commands through the hook.
    assert {"device", "play", "conformance"} <= set(contributed)
    listing = run("--help").output
    for name, summary in {**COMMAND_SUMMARIES, **contributed}.items():
        help_text = " ".join(cli.get_command(context, name).help.split())
        first_sentence = help_text.split(". ")[0].rstrip(".") + "."
        assert summary == first_sentence, name
        assert f"  {name}" in listing
        assert len(summary) <= 64, (name, "one line of the 80-column listing")


def test_the_command_list_imports_no_command_module():
    code = ("import sys\nfrom hcard.cli.main import cli\n"
            "try:\n    cli(['--help'], standalone_mode=False)\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.endswith('_cmd') or m == 'numpy'"
            " or m.startswith('hcard.cli.card_cmds')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]"
