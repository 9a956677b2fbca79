"""The ``hcard`` console script, :func:`hcard.cli.main.main`: the entry point pyproject.toml
declares, that a command run through it writes all it should, and its fast exit (the
interpreter's final garbage-collection passes skipped by :func:`gc.freeze`, which the click
group alone must not do: tests and embedding programs go on after a command).

Each run is a fresh interpreter, as a user's is; the cards it writes are compared with the same
command run in this process through click's runner (no fast exit)."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest
from click.testing import CliRunner

import hcard
from hcard.card_io import parse_card
from hcard.cli.main import cli, main
from tests.helpers.repository import REPO

BUTTON = REPO / "examples" / "button.png"
_HCARD = next(e for e in entry_points(group="console_scripts") if e.name == "hcard")
CONSOLE_SCRIPT = f"from {_HCARD.module} import {_HCARD.attr}; {_HCARD.attr}()"
"""What the installed ``hcard`` script runs: its entry point's function, called."""


def fresh(code: str, *args: str) -> subprocess.CompletedProcess[bytes]:
    """``python -c code args...`` in a new interpreter, its output captured as bytes."""
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True,
                          timeout=120, check=False)


def frozen_after(call: str) -> str:
    """The last line a fresh interpreter prints after ``call`` (which ends in SystemExit): its
    exit code and whether the garbage collector's objects were frozen."""
    code = ("import gc\nfrom hcard.cli.main import cli, main\nimport runpy, sys\n"
            f"try:\n    {call}\nexcept SystemExit as done:\n"
            "    print(done.code, gc.get_freeze_count() > 0)\n")
    return fresh(code).stdout.decode().strip().splitlines()[-1]


def test_the_installed_console_script_is_main() -> None:
    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "hcard"]
    assert script.value == "hcard.cli.main:main"
    assert script.load() is main


@pytest.fixture(scope="module")
def reference_card(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The card of ``hcard -q encode button.png``, run in this process through click's runner
    (no fast exit), once for the module."""
    reference = tmp_path_factory.mktemp("reference") / "button.hcard"
    in_process = CliRunner().invoke(cli, ["-q", "encode", str(BUTTON), "-o", str(reference)])
    assert in_process.exit_code == 0, in_process.output
    return reference.read_bytes()


def test_an_encode_through_the_console_script_writes_the_card_and_the_whole_summary(
    tmp_path: Path, reference_card: bytes
) -> None:
    card = tmp_path / "button.hcard"
    done = fresh(CONSOLE_SCRIPT, "-q", "encode", str(BUTTON), "-o", str(card), "--json")
    assert done.returncode == 0, done.stderr.decode()
    summary = json.loads(done.stdout)  # all of it: the piped stdout was flushed at exit
    assert summary["output_bytes"] == card.stat().st_size
    assert card.read_bytes() == reference_card
    assert hcard.load(card).metadata.title == "button"


def test_a_card_written_to_standard_output_arrives_whole(reference_card: bytes) -> None:
    done = fresh(CONSOLE_SCRIPT, "-q", "encode", str(BUTTON), "-o", "-")
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout == reference_card
    assert parse_card(done.stdout, source="<stdout>").grid.cols > 0
    assert b"wrote" not in done.stdout and b"card size" in done.stderr  # summary on stderr


def test_the_console_script_exits_with_the_collector_frozen(tmp_path):
    missing = tmp_path / "missing.hcard"
    assert frozen_after("main(['--version'])") == "0 True"
    assert frozen_after(f"main(['info', {str(missing)!r}])") == "1 True"  # a user error too
    assert frozen_after("sys.argv = ['hcard', '--version']; "
                        "runpy.run_module('hcard', run_name='__main__')") == "0 True"


def test_the_click_group_alone_leaves_the_collector_alone():
    assert frozen_after("cli(['--version'])") == "0 False"
