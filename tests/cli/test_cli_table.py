"""The command line holds its own table (README "Exit status"): every bad option value exits 2
with one line, ``-q``/``-v`` are accepted the same way by every command, every ``--help``
has examples that name real options, and a closed standard output ends a command quietly."""

from __future__ import annotations

import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

import hcard
from hcard.cli.errors import EXIT_BROKEN_PIPE, EXIT_USAGE
from hcard.cli.main import cli
from hcard.track import straight_stroke, track_to_csv
from tests.helpers.cards import two_texture_card
from tests.helpers.cli import run_hcard as run
from tests.helpers.repository import REPO as ROOT

RECORDING = ROOT / "examples" / "thesis_measurements" / "ev_hover_table3_3_gap0p25mm.csv"
"""A recording with its sidecar, for the options of ``calibrate run`` read after the data."""


def every_command(command: click.Command = cli, path: tuple[str, ...] = ()
                  ) -> Iterator[tuple[tuple[str, ...], click.Command]]:
    """Each command of the ``hcard`` tree with its path of names, the groups included."""
    yield path, command
    if isinstance(command, click.Group):
        context = click.Context(command, info_name=path[-1] if path else "hcard")
        for name in command.list_commands(context):
            sub = command.get_command(context, name)
            assert sub is not None, name
            yield from every_command(sub, (*path, name))


COMMANDS = dict(every_command())


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    """A valid card and track in ``tmp_path``, and an example image."""
    card = tmp_path / "card.hcard"
    hcard.save(two_texture_card(), card)
    track = tmp_path / "stroke.csv"
    track.write_text(track_to_csv(straight_stroke((1.0, 5.0), (40.0, 0.0), 0.2)))
    return {"card": card, "track": track, "dir": tmp_path,
            "image": ROOT / "examples" / "gratings.png"}


BAD_OPTION_VALUES = [
    # (command line, a fragment of the one error line)
    ("encode {image} -o {dir}/x.hcard --width-mm -5", "--width-mm"),
    ("encode {image} -o {dir}/x.hcard --components 99", "--components"),
    ("encode {image} -o {dir}/x.hcard --channel sideways", "--channel"),
    ("render {card} --track {track} -o {dir}/x.txt", ".csv or .npz"),
    ("render {card} --track {track} -o {dir}/x.csv --mode chaotic", "--mode"),
    ("preview {card} -o {dir}/x.jpg", ".png"),
    ("preview {card} --dpi 5", "--dpi"),
    ("predict nosuch", "no predictor plugin named 'nosuch'"),
    ("predict dimensionless-group --input amplitude=2kg", "--input amplitude"),
    ("predict dimensionless-group --input amplitude", "expected NAME=VALUE"),
    ("predict dimensionless-group --param psi_star=-1", "outside its bounds"),
    ("predict dimensionless-group --sweep amplitude=0:5um:1", "COUNT must be between 2"),
    ("calibrate plan --device uv -o {dir}/plan --duration 5parsecs", "unknown unit 'parsecs'"),
    ("calibrate plan --device ultraviolet -o {dir}/plan", "--device"),
    ("calibrate run {recording} -o {dir}/c --test-fraction 2", "--test-fraction"),
    ("calibrate run {recording} -o {dir}/c --min-improvement lots", "--min-improvement"),
    ("calibrate run {recording} -o {dir}/c --contact-threshold 5kg", "--contact-threshold"),
    ("calibrate run {recording} -o {dir}/c --model nosuch", "no predictor plugin named"),
    ("calibrate run {recording} -o {dir}/c --finger nosuch", "--finger"),
    ("calibrate run {recording} -o {dir}/c --effect nosuch", "unknown effect(s) nosuch"),
    ("calibrate run {recording} -o {dir}/c --bootstrap 1", "--bootstrap"),
    ("calibrate {recording} -o {dir}/c --model ev-kaczmarek --free nosuch", "--free"),
    ("calibrate {recording} -o {dir}/c --model ev-kaczmarek --param nosuch=1", "--param"),
    ("calibrate {recording} -o {dir}/c --model ev-kaczmarek --param area=-1m2", "area"),
    ("device synthesize --device uv", "-o/--output"),
    ("device synthesize --device uv -o {dir}/s --duration 5parsecs", "unknown unit 'parsecs'"),
    ("device synthesize --device uv -o {dir}/s --effect nosuch", "nosuch"),
    ("device synthesize --device uv -o {dir}/s --uri warp://drive", "warp"),
    ("device serve --effect nosuch", "nosuch"),
    ("device serve --port 70000", "--port"),
    ("device list --host 127.0.0.1:99999", "port"),
    ("play {card} --device warp://drive --track {track} -o {dir}/r.csv", "warp"),
    ("play {card} --device sim://evita --track {track} -o {dir}/r.txt", ".csv"),
    ("conformance --driver reference --option nonsense", "KEY=VALUE"),
    ("conformance --driver reference --timing sundial", "--timing"),
    ("conformance --driver warp://drive --level format", "warp"),
    ("plugins --colour", "--colour"),
]


@pytest.mark.parametrize(("line", "fragment"), BAD_OPTION_VALUES)
def test_every_bad_option_value_exits_2_with_one_error_line(line: str, fragment: str,
                                                           files: dict[str, Path]) -> None:
    args = shlex.split(line.format(**files, recording=RECORDING))
    result = run(*args)
    assert result.exit_code == EXIT_USAGE, (result.exit_code, result.output)
    assert "Traceback" not in result.output
    errors = [text for text in result.output.splitlines() if text.startswith("Error: ")]
    assert len(errors) == 1, result.output
    assert fragment in errors[0], errors[0]


@pytest.mark.parametrize("path", [path for path in COMMANDS if path])
def test_every_command_takes_quiet_and_verbose(path: tuple[str, ...]) -> None:
    command = COMMANDS[path]
    flags = {flag for param in command.params for flag in getattr(param, "opts", ())}
    assert {"-q", "--quiet", "-v", "--verbose"} <= flags, path
    # given on the group and on the command, they meet in one setting: both is a usage error
    result = run("-q", *path, "-v", "--help")
    assert result.exit_code == EXIT_USAGE and "give -q or -v, not both" in result.output
    assert run(*path, "-q", "--help").exit_code == 0


def _example_lines(help_text: str) -> list[str]:
    """The command lines under the ``Examples:`` heading of a help page."""
    lines = help_text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip() == "Examples:")
    examples = []
    for line in lines[start + 1:]:
        if not line.strip():
            break
        examples.append(line.strip())
    return examples


def _command_of(words: list[str]) -> tuple[click.Command, list[str]]:
    """The command an example's words name (after ``hcard``), and its own words."""
    command: click.Command = cli
    path: tuple[str, ...] = ()
    rest = list(words)
    while isinstance(command, click.Group):
        while rest and rest[0].startswith("-"):
            rest.pop(0)  # group options (-q, -v)
        if rest and (*path, rest[0]) in COMMANDS:
            path = (*path, rest.pop(0))
        elif getattr(command, "default_command", None):  # `hcard calibrate rec.csv` is `run`
            path = (*path, command.default_command)
        else:
            break
        command = COMMANDS[path]
    return command, rest


@pytest.mark.parametrize("path", list(COMMANDS))
def test_every_help_page_has_examples_that_name_real_options(path: tuple[str, ...]) -> None:
    result = run(*path, "--help")
    assert result.exit_code == 0, result.output
    examples = _example_lines(result.output)
    assert examples, f"hcard {' '.join(path)} --help has no examples"
    for example in examples:
        words = shlex.split(example.split(" | ")[0])
        assert words[0] == "hcard", example
        command, rest = _command_of(words[1:])
        known = {flag for param in command.params for flag in getattr(param, "opts", ())}
        for word in rest:
            if word.startswith("-") and word != "-":
                assert word.split("=")[0] in known | {"-h", "--help"}, (example, word)


def test_a_closed_standard_output_ends_the_command_quietly(tmp_path: Path) -> None:
    """``hcard predict ... | head -1``: the reader goes away after one line; the command ends
    with status 141 (128 + SIGPIPE) and says nothing (was: an internal error with a
    traceback)."""
    command = [sys.executable, "-m", "hcard", "predict", "dimensionless-group",
               "--sweep", "amplitude=0:5um:200000"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert process.stdout is not None and process.stderr is not None
    first = process.stdout.readline()
    process.stdout.close()
    stderr = process.stderr.read().decode()
    assert process.wait(timeout=120) == EXIT_BROKEN_PIPE, stderr
    assert first.startswith(b"#")
    assert stderr == ""
