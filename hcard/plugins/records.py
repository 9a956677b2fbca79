"""What the plugin registry records: where a plugin came from, each usable plugin object and
each problem, with the warning and the words that report a problem.

The parts of the plugin system hand each other these records: :mod:`hcard.plugins.discovery`
finds plugins, :mod:`hcard.plugins.validation` checks what they give, and
:class:`hcard.plugins.registry.PluginRegistry` keeps them and answers queries; ``hcard plugins``
prints them.
"""

from __future__ import annotations

import os
import traceback
from typing import Any, NamedTuple

import pluggy

_PLUGGY_DIR = os.path.dirname(pluggy.__file__)


class HcardPluginWarning(UserWarning):
    """A plugin was skipped (wholly or in part); the message names entry point, package, reason."""


class BrokenPlugin(NamedTuple):
    """A plugin problem found during discovery or registration.

    ``entry_point`` is the entry-point name (or the registered name of a plugin added with
    :meth:`~hcard.plugins.registry.PluginRegistry.register`); ``reason`` is the full message, as
    warned.
    """

    entry_point: str
    reason: str


class PluginInfo(NamedTuple):  # not a dataclass: 0.06 ms to define instead of 0.4 ms
    """One usable plugin object and where it came from.

    Attributes:
        name: the object's ``name``, unique within its kind.
        kind: one of :data:`hcard.plugins.kinds.KINDS`.
        version: version of the distribution that provided it ("" when unknown).
        package: name of that distribution (for example ``"hcard"``).
        entry_point: entry-point name in the ``hcard.plugins`` group ("" when registered in code).
        obj: the plugin object itself.
    """

    name: str
    kind: str
    version: str
    package: str
    entry_point: str
    obj: Any

    @property
    def description(self) -> str:
        """The object's one-line description ("" when it has none)."""
        return str(getattr(self.obj, "description", "") or "")


class PluginSource:
    """Where a registered plugin (module or object) came from: its entry point (or the name it
    was registered under in code), its distribution and that distribution's version. (The
    private records of the plugin system are slotted classes, not dataclasses or named tuples:
    a dataclass costs ~0.3 ms to define, a named tuple ~0.1 ms, a slotted class ~0.01 ms, and
    every command taking a plugin imports them.)"""

    __slots__ = ("entry_point", "package", "version")

    def __init__(self, entry_point: str, package: str, version: str) -> None:
        self.entry_point = entry_point
        self.package = package
        self.version = version

    def label(self) -> str:
        """How problem messages name the plugin: ``plugin 'E' from package 'P' (version V)``."""
        version = f" (version {self.version})" if self.version else ""
        return f"plugin '{self.entry_point}' from package '{self.package}'{version}"


def describe_exception(exc: BaseException) -> str:
    """``Type: message (at file:line)`` of an exception raised by plugin code."""
    message = " ".join(str(exc).split())  # one line, whatever the plugin raised
    text = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    frames = traceback.extract_tb(exc.__traceback__)
    # Point at the plugin's code, not at the import machinery or pluggy's validation.
    if frames and not frames[-1].filename.startswith(("<", _PLUGGY_DIR)):
        text += f" (at {frames[-1].filename}:{frames[-1].lineno})"
    return text
