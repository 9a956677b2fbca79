"""What plugin discovery found, remembered between runs of ``hcard``.

Discovery means listing the entry points of every installed distribution (importing
:mod:`importlib.metadata` and reading each one's metadata), importing pluggy and every plugin
module: tens of milliseconds that ``hcard --help`` and ``hcard encode`` did not spend when the
core named its commands and its encoder itself. So two findings are kept in small JSON files in
the user's cache directory:

- the subcommands of ``hcard.commands`` (names, import paths and summaries: :func:`load`,
  :func:`store`), so that ``hcard --help`` needs neither the scan nor pluggy;
- the entry points of a group such as ``hcard.plugins`` (name, import path, distribution and the
  hooks each implements: :func:`load_entry_points`, :func:`store_entry_points`), so that the
  registry imports only the plugin modules implementing the hook a command asks for.

Each is kept with what it depends on:

- the interpreter, ``sys.path``, and in each of its directories the name and modification time
  of every distribution's metadata directory (``.dist-info``, ``.egg-info``: installing,
  upgrading or removing a distribution changes them);
- the modification time of every module that contributed.

If any of these differ, discovery runs again. Nothing is remembered when a plugin had a problem,
so its warning is given on every run. A cache that cannot be read or written is ignored: it
only saves time.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from hcard.plugins.lazy_command import LazyCommand

if TYPE_CHECKING:
    from hcard.plugins.kinds import CommandPlugin

CACHE_FORMAT = "hcard-command-cache/1"
"""The ``format`` of the commands' cache file; another value is ignored."""

ENTRY_POINT_CACHE_FORMAT = "hcard-entry-point-cache/1"
"""The ``format`` of an entry-point group's cache file; another value is ignored."""

COMMANDS = "commands"
"""The name of the commands' cache file (without ``.json``)."""


class CachedEntryPoint(NamedTuple):
    """An entry point as discovery found it, and the hooks its plugin implements.

    Attributes:
        name: the entry-point name, e.g. ``"builtin-encoders"``.
        value: what it names, ``"module"`` or ``"module:attribute"``.
        package: name of the distribution declaring it.
        version: that distribution's version.
        hooks: names of the hooks its plugin implements (all with a hook specification).
    """

    name: str
    value: str
    package: str
    version: str
    hooks: tuple[str, ...]


def cache_path(name: str = COMMANDS) -> Path:
    """``$XDG_CACHE_HOME/hcard/<name>.json`` (``~/.cache`` when the variable is not set)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(root, "hcard", f"{name}.json")


def entry_point_cache_name(group: str) -> str:
    """The cache file name (without ``.json``) of the entry-point ``group``."""
    return f"entry-points-{group}"


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
    """What the discovered plugins depend on besides their modules (JSON-ready)."""
    paths = [_absolute(entry) for entry in sys.path]
    return [sys.executable, sys.version, [[path, _distributions(path)] for path in paths]]


def _absolute(entry: str) -> str:
    """The ``sys.path`` entry as an absolute path; as it is when the current directory no
    longer exists (a relative entry then names nothing, and listing it finds nothing)."""
    try:
        return os.path.abspath(entry or ".")
    except OSError:
        return entry


def _read(name: str, cache_format: str) -> dict[str, Any] | None:
    """The document of cache file ``name`` when it has ``cache_format`` and is still valid
    (same environment, every module unchanged), else None."""
    try:
        document = json.loads(cache_path(name).read_text(encoding="utf-8"))
        if document.get("format") != cache_format or document["environment"] != _environment():
            return None
        if any(_mtime(path) != mtime for path, mtime in document["modules"]):
            return None
        return dict(document)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _write(name: str, cache_format: str, modules: list[str], **contents: Any) -> None:
    """Write cache file ``name``: ``contents`` and what they depend on (``modules``: the files
    of the plugin modules that contributed them)."""
    document = {
        "format": cache_format,
        "environment": _environment(),
        "modules": [[path, _mtime(path)] for path in sorted(modules)],
        **contents,
    }
    path = cache_path(name)
    temporary = path.with_name(f".{path.name}.{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary.write_text(json.dumps(document), encoding="utf-8")
        os.replace(temporary, path)  # readers see the old file or the new one, never half
    except OSError:
        with contextlib.suppress(OSError):
            temporary.unlink(missing_ok=True)


def load() -> dict[str, CommandPlugin] | None:
    """The remembered commands by name, or None when there are none or they may be stale."""
    document = _read(COMMANDS, CACHE_FORMAT)
    if document is None:
        return None
    try:
        return {
            entry["name"]: LazyCommand(entry["name"], entry["target"], entry["summary"])
            for entry in document["commands"]
        }
    except (KeyError, TypeError):
        return None


def store(commands: dict[str, CommandPlugin], modules: list[str]) -> None:
    """Remember ``commands`` (all :class:`LazyCommand`, else nothing is kept), found in the
    plugin modules whose files are ``modules``."""
    if not all(isinstance(command, LazyCommand) for command in commands.values()):
        return
    _write(COMMANDS, CACHE_FORMAT, modules, commands=[
        {"name": name, "target": command.target, "summary": command.summary}
        for name, command in sorted(commands.items())
        if isinstance(command, LazyCommand)
    ])


def forget(name: str = COMMANDS) -> None:
    """Drop cache file ``name`` (something remembered could not be loaded: it is discovered
    again)."""
    with contextlib.suppress(OSError):
        cache_path(name).unlink(missing_ok=True)


def load_entry_points(group: str) -> list[CachedEntryPoint] | None:
    """The remembered entry points of ``group``, in discovery order, or None when there are
    none or they may be stale."""
    document = _read(entry_point_cache_name(group), ENTRY_POINT_CACHE_FORMAT)
    if document is None or document.get("group") != group:
        return None
    try:
        return [
            CachedEntryPoint(str(entry["name"]), str(entry["value"]), str(entry["package"]),
                             str(entry["version"]), tuple(str(hook) for hook in entry["hooks"]))
            for entry in document["entry_points"]
        ]
    except (KeyError, TypeError):
        return None


def store_entry_points(group: str, entry_points: list[CachedEntryPoint],
                       modules: list[str]) -> None:
    """Remember the ``entry_points`` of ``group`` (in discovery order), whose plugins are
    defined in the files ``modules``."""
    _write(entry_point_cache_name(group), ENTRY_POINT_CACHE_FORMAT, modules, group=group,
           entry_points=[
               {"name": entry.name, "value": entry.value, "package": entry.package,
                "version": entry.version, "hooks": list(entry.hooks)}
               for entry in entry_points
           ])
