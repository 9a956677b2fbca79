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

If any of these differ, discovery runs again. They are checked without statting every
installed distribution on each run: a directory whose own modification time is unchanged has
had no entry added, removed or renamed, so it holds the same metadata directories, and only
those declaring ``hcard`` entry points are looked at again (a file added to or replaced in
them). A directory that changed (anything installed or removed, or a file written to the
current directory) is listed again and compared distribution by distribution.

Nothing is remembered when a plugin had a problem, so its warning is given on every run. A
cache that cannot be read or written is ignored: it only saves time.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hcard.plugins.lazy_command import LazyCommand

if TYPE_CHECKING:
    from hcard.plugins.kinds import CommandPlugin

CACHE_FORMAT = "hcard-command-cache/2"
"""The ``format`` of the commands' cache file; another value is ignored."""

ENTRY_POINT_CACHE_FORMAT = "hcard-entry-point-cache/2"
"""The ``format`` of an entry-point group's cache file; another value is ignored."""

RACY_NS = 2 * 10**9
"""A directory modified less than this before the cache is written (ns) is not trusted by its
modification time, which the file system keeps with a coarse clock: a distribution installed
in the same tick would leave it unchanged."""

COMMANDS = "commands"
"""The name of the commands' cache file (without ``.json``)."""


class CachedEntryPoint:
    """An entry point as discovery found it, and the hooks its plugin implements. (A slotted
    class, not a named tuple: ~0.01 ms to define instead of ~0.1 ms, on every ``hcard encode``.)

    Attributes:
        name: the entry-point name, e.g. ``"builtin-encoders"``.
        value: what it names, ``"module"`` or ``"module:attribute"``.
        package: name of the distribution declaring it.
        version: that distribution's version.
        hooks: names of the hooks its plugin implements (all with a hook specification).
    """

    __slots__ = ("hooks", "name", "package", "value", "version")

    def __init__(self, name: str, value: str, package: str, version: str,
                 hooks: tuple[str, ...]) -> None:
        self.name = name
        self.value = value
        self.package = package
        self.version = version
        self.hooks = hooks


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


def _declares_hcard_entry_points(metadata_directory: str) -> bool:
    """Whether the distribution metadata directory declares an entry-point group of hcard
    (a section ``[hcard...]`` in its ``entry_points.txt``)."""
    try:
        with open(os.path.join(metadata_directory, "entry_points.txt"), encoding="utf-8") as file:
            lines = file.read().splitlines()
    except (OSError, ValueError):
        return False
    return any(line.strip().startswith("[hcard") for line in lines)


def _environment() -> list[Any]:
    """What the discovered plugins depend on besides their modules (JSON-ready): interpreter,
    and for each ``sys.path`` directory ``[path, modification time, distributions, names of the
    distributions declaring hcard entry points]``."""
    now = time.time_ns()
    directories = []
    for path in (_absolute(entry) for entry in sys.path):
        mtime = _mtime(path)  # before listing: a change made while listing shows in it
        distributions = _distributions(path)
        declaring = [name for name, _ in distributions or ()
                     if _declares_hcard_entry_points(os.path.join(path, name))]
        if mtime is not None and mtime > now - RACY_NS:
            mtime = None  # may change again within the clock's resolution: list it every time
        directories.append([path, mtime, distributions, declaring])
    return [sys.executable, sys.version, directories]


def _environment_unchanged(recorded: list[Any]) -> bool:
    """Whether the environment is still the ``recorded`` one (:func:`_environment`), without
    listing a directory that has not changed (see the module's description)."""
    executable, version, directories = recorded
    if executable != sys.executable or version != sys.version or len(directories) != len(sys.path):
        return False
    for entry, (path, mtime, distributions, declaring) in zip(sys.path, directories, strict=True):
        if _absolute(entry) != path:
            return False
        if mtime is not None and _mtime(path) == mtime:
            # No entry added, removed or renamed: the same metadata directories are there.
            recorded_mtimes = dict(distributions or ())
            if any(_mtime(os.path.join(path, name)) != recorded_mtimes.get(name)
                   for name in declaring):
                return False
        elif _distributions(path) != distributions:
            return False
    return True


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
        if document.get("format") != cache_format or not _environment_unchanged(
                document["environment"]):
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
    from hcard.atomic import write_atomically

    path = cache_path(name)
    with contextlib.suppress(OSError):  # readers see the old file or the new one, never half
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(path, json.dumps(document).encode("utf-8"))


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
    lazy = {name: command for name, command in commands.items()
            if isinstance(command, LazyCommand)}
    if len(lazy) != len(commands):
        return
    _write(COMMANDS, CACHE_FORMAT, modules, commands=[
        {"name": name, "target": command.target, "summary": command.summary}
        for name, command in sorted(lazy.items())
    ])


def forget(name: str = COMMANDS) -> None:
    """Drop cache file ``name`` (something remembered could not be loaded: it is discovered
    again)."""
    with contextlib.suppress(OSError):
        cache_path(name).unlink(missing_ok=True)


def forget_commands() -> None:
    """Drop both findings the commands are taken from: the commands and the entry points of
    their group (either alone would bring the other's stale command back on the next run)."""
    from hcard.plugins.hookspecs import COMMAND_ENTRY_POINT_GROUP

    forget(COMMANDS)
    forget(entry_point_cache_name(COMMAND_ENTRY_POINT_GROUP))


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
