"""Running ``hcard`` in a test, and the promise every command keeps to a user who made a mistake.

:func:`run_hcard` runs the command line in this process (click's :class:`~click.testing.CliRunner`,
fast, the usual way); :func:`run_python` runs a fresh interpreter, as a user's shell would, when
a test needs what only a new process has (distributions a test installed, a cache of its own).
:func:`assert_one_line_error` is README "Exit status" for a user's mistake: one ``Error:`` line
and no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner, Result

from hcard.cli.main import cli

USAGE_LINES = ("Usage: ", "Try ")
"""How the lines start that click prints before the error line of an option its own types
refuse (``Usage: hcard encode [OPTIONS] IMAGE``, ``Try 'hcard encode --help' for help.``)."""


def run_hcard(*args: object) -> Result:
    """``hcard ARGS`` in this process, each argument through :func:`str`."""
    return CliRunner().invoke(cli, [str(a) for a in args])


def run_python(*args: str, site: Path, cache: Path | None = None,
               timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    """``python ARGS`` in a fresh interpreter whose path starts with ``site`` (where the test
    installed distributions; also the working directory) and, given ``cache``, with
    ``XDG_CACHE_HOME`` there (else the run's own, tests/conftest.py); its output as text."""
    env = dict(os.environ)
    if cache is not None:
        env["XDG_CACHE_HOME"] = str(cache)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env,
                          cwd=site, timeout=timeout_s, check=False)


def assert_one_line_error(result: Result | subprocess.CompletedProcess[str], *fragments: str,
                          status: int = 1, after_usage: bool = False) -> str:
    """A user's mistake as every command reports it: exit ``status`` (1: a file or device is
    wrong, 2: the command line is), nothing on standard output, no traceback, and on standard
    error one line, ``Error: ...``, holding every fragment; returns that line. ``after_usage``:
    click's usage lines (:data:`USAGE_LINES`) may come before it, as click prints them for an
    option value its own types refuse."""
    if isinstance(result, subprocess.CompletedProcess):
        code, stdout, stderr = result.returncode, result.stdout, result.stderr
    else:
        code, stdout, stderr = result.exit_code, result.stdout, result.stderr
        # In this process a traceback is an exception other than the exit click raises.
        assert result.exception is None or isinstance(result.exception, SystemExit), \
            result.exc_info
    assert code == status, (code, stdout + stderr)
    assert "Traceback" not in stdout + stderr
    assert stdout == "", stdout
    *before, line = [text for text in stderr.splitlines() if text.strip()] or [""]
    assert line.startswith("Error: "), stderr
    if after_usage:
        assert all(text.startswith(USAGE_LINES) for text in before), stderr
    else:
        assert not before, stderr
    for fragment in fragments:
        assert fragment in line, line
    return line
