"""Hook specifications of the hcard plugin system (pluggy project name ``hcard``).

A plugin is a module (or object) registered through the entry-point group ``hcard.plugins``
that implements one or more of these hooks with :data:`hcard.plugins.hookimpl`. Each kind of
plugin has one hook, made from its row of :data:`hcard.plugins.kinds.KIND_TABLE` (the hook's
name, the Protocol of the objects it returns, what they are): ``hcard_encoders`` returns a list
of :class:`~hcard.plugins.kinds.EncoderPlugin`, and so on. Every object has a ``name`` (unique
within its kind) and a one-line ``description``.

Subcommands come through the same hook system (:func:`hcard_commands`), from modules named in
the entry-point group ``hcard.commands`` (:data:`COMMAND_ENTRY_POINT_GROUP`): ``hcard --help``
imports only those, so they must be light (the command itself is imported when it runs).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pluggy

from hcard.plugins.kinds import KIND_TABLE, CommandPlugin, Kind

PROJECT = "hcard"
ENTRY_POINT_GROUP = "hcard.plugins"
COMMAND_ENTRY_POINT_GROUP = "hcard.commands"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


def _kind_hook(kind: Kind) -> Callable[[], list[Any]]:
    """The hook specification of ``kind``: no arguments, returns its plugin objects."""

    def spec() -> list[Any]:
        """Replaced below by the kind's own documentation."""

    spec.__name__ = spec.__qualname__ = kind.hook
    spec.__doc__ = (f"Return {kind.description} (each a "
                    f":class:`~hcard.plugins.kinds.{kind.protocol.__name__}`).")
    spec.__annotations__ = {"return": f"list[{kind.protocol.__name__}]"}
    return hookspec(spec)


globals().update({kind.hook: _kind_hook(kind) for kind in KIND_TABLE})


@hookspec
def hcard_commands() -> list[CommandPlugin]:
    """Return subcommands of ``hcard`` (usually :class:`~hcard.plugins.kinds.LazyCommand`:
    name, import path, one-line summary), as pytest plugins add options."""


COMMAND_HOOK = hcard_commands.__name__
"""The hook contributing subcommands (:class:`~hcard.plugins.kinds.CommandPlugin`), which are
kept apart from the plugin kinds: ``hcard --help`` lists them, ``hcard plugins`` does not."""

ALL_HOOKS: tuple[str, ...] = (*(kind.hook for kind in KIND_TABLE), COMMAND_HOOK)
"""Every hook a plugin may implement."""
