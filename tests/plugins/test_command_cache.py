"""``hcard --help`` reuses the contributed commands an earlier run found, until a distribution
is installed or removed; a plugin with a problem is warned about on every run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

LIST_COMMANDS = (
    "import sys\nfrom hcard.cli.main import cli\n"
    "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
    "print(sorted(m for m in ('pluggy', 'importlib.metadata') if m in sys.modules))\n"
)
"""Prints ``hcard --help``, then which of the discovery machinery's modules it imported."""

GREETER = '''
from hcard.plugins import LazyCommand, hookimpl


@hookimpl
def hcard_commands():
    return [LazyCommand("greet", "hcardtest_greet_cmd:greet", "Greet the user.")]
'''

GREET_COMMAND = '''
import click


@click.command("greet")
def greet():
    """Greet the user."""
    click.echo("hello")
'''


def _run(args: list[str], cache: Path, site: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, XDG_CACHE_HOME=str(cache))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env,
                          cwd=site, timeout=120, check=False)


def _install(site: Path, name: str, entry_points: str, modules: dict[str, str]) -> None:
    dist_info = site / f"{name.replace('-', '_')}-1.0.dist-info"
    dist_info.mkdir()
    (dist_info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n", encoding="utf-8")
    (dist_info / "entry_points.txt").write_text(entry_points, encoding="utf-8")
    for module, source in modules.items():
        (site / f"{module}.py").write_text(source, encoding="utf-8")


def test_help_reuses_the_commands_until_a_distribution_is_installed(tmp_path: Path) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    first = _run(["-c", LIST_COMMANDS], cache, site)
    assert first.returncode == 0, first.stderr
    assert first.stdout.splitlines()[-1] == "['importlib.metadata', 'pluggy']"  # discovered
    remembered = json.loads((cache / "hcard" / "commands.json").read_text(encoding="utf-8"))
    assert {c["name"] for c in remembered["commands"]} >= {"device", "play", "conformance"}

    second = _run(["-c", LIST_COMMANDS], cache, site)
    assert second.stdout.splitlines()[-1] == "[]"  # no entry-point scan, no pluggy
    assert second.stdout.splitlines()[:-1] == first.stdout.splitlines()[:-1]  # same listing

    _install(site, "greeter", "[hcard.commands]\ngreet = hcardtest_greeter\n",
             {"hcardtest_greeter": GREETER, "hcardtest_greet_cmd": GREET_COMMAND})
    third = _run(["-c", LIST_COMMANDS], cache, site)
    assert third.stdout.splitlines()[-1] == "['importlib.metadata', 'pluggy']"  # found again
    assert "  greet        Greet the user." in third.stdout
    ran = _run(["-m", "hcard", "greet"], cache, site)
    assert (ran.returncode, ran.stdout) == (0, "hello\n"), ran.stderr


def test_a_remembered_command_that_no_longer_loads_is_warned_and_forgotten(
    tmp_path: Path,
) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    _install(site, "greeter", "[hcard.commands]\ngreet = hcardtest_greeter\n",
             {"hcardtest_greeter": GREETER, "hcardtest_greet_cmd": GREET_COMMAND})
    assert _run(["-m", "hcard", "greet"], cache, site).stdout == "hello\n"
    (site / "hcardtest_greet_cmd.py").unlink()  # the command's module is gone, the plugin not
    gone = _run(["-m", "hcard", "greet"], cache, site)
    assert gone.returncode == 2
    assert ("warning: command 'greet' cannot be loaded: ModuleNotFoundError: No module named "
            "'hcardtest_greet_cmd'") in gone.stderr
    assert "Traceback" not in gone.stderr
    assert not (cache / "hcard" / "commands.json").exists()
