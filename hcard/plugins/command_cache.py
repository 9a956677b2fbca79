"""The subcommands installed packages contribute, remembered between runs of ``hcard``.

Finding them means listing the entry points of every installed distribution (importing
:mod:`importlib.metadata` and reading each one's metadata) and importing pluggy: tens of
milliseconds that ``hcard --help`` did not spend when the core named its commands itself. So the
names, import paths and summaries found are kept in a small JSON file in the user's cache
directory, with what they depend on:

- the interpreter, ``sys.path``, and in each of its directories the name and modification time
  of every distribution's metadata directory (``.dist-info``, ``.egg-info``: installing,
  upgrading or removing a distribution changes them);
- the modification time of every module that contributed commands.

If any of these differ the commands are discovered again. Nothing is remembered when a plugin
had a problem, so its warning is given on every run. A cache that cannot be read or written is
ignored: it only saves time.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hcard.plugins.lazy_command import LazyCommand

if TYPE_CHECKING:
    from hcard.plugins.kinds import CommandPlugin

CACHE_FORMAT = "hcard-command-cache/1"
"""The ``format`` of the cache file; another value is ignored."""


def cache_path() -> Path:
    """``$XDG_CACHE_HOME/hcard/commands.json`` (``~/.cache`` when the variable is not set)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(root, "hcard", "commands.json")


def _mtime(path: str) -> int | None:
    try:
        return os.stat(path or ".").st_mtime_ns
    except OSError:
        return None


def _distributions(directory: str) -> list[list[Any]] | None:
    """``[name, modification time]`` of each distribution's metadata directory in
    ``directory`` (what :mod:`importlib.metadata` reads entry points from); None if it is not
    a readable directory."""
    try:
        names = os.listdir(directory)
    except OSError:
        return None
    return sorted(
        [name, _mtime(os.path.join(directory, name))]
        for name in names
        if name.endswith((".dist-info", ".egg-info"))
    )


def _environment() -> list[Any]:
    """What the discovered commands depend on besides their modules (JSON-ready)."""
    paths = [os.path.abspath(entry or ".") for entry in sys.path]
    return [sys.executable, sys.version, [[path, _distributions(path)] for path in paths]]


def load() -> dict[str, CommandPlugin] | None:
    """The remembered commands by name, or None when there are none or they may be stale."""
    try:
        document = json.loads(cache_path().read_text(encoding="utf-8"))
        if document.get("format") != CACHE_FORMAT or document["environment"] != _environment():
            return None
        if any(_mtime(path) != mtime for path, mtime in document["modules"]):
            return None
        return {
            entry["name"]: LazyCommand(entry["name"], entry["target"], entry["summary"])
            for entry in document["commands"]
        }
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def store(commands: dict[str, CommandPlugin], modules: list[str]) -> None:
    """Remember ``commands`` (all :class:`LazyCommand`, else nothing is kept), found in the
    plugin modules whose files are ``modules``."""
    if not all(isinstance(command, LazyCommand) for command in commands.values()):
        return
    document = {
        "format": CACHE_FORMAT,
        "environment": _environment(),
        "modules": [[path, _mtime(path)] for path in sorted(modules)],
        "commands": [
            {"name": name, "target": command.target, "summary": command.summary}
            for name, command in sorted(commands.items())
            if isinstance(command, LazyCommand)
        ],
    }
    path = cache_path()
    temporary = path.with_name(f".{path.name}.{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary.write_text(json.dumps(document), encoding="utf-8")
        os.replace(temporary, path)  # readers see the old file or the new one, never half
    except OSError:
        with contextlib.suppress(OSError):
            temporary.unlink(missing_ok=True)


def forget() -> None:
    """Drop the remembered commands (one could not be loaded: they are discovered again)."""
    with contextlib.suppress(OSError):
        cache_path().unlink(missing_ok=True)
