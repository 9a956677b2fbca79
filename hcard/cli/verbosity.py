"""The command line's ``-q/--quiet`` and ``-v/--verbose``: how much a command says on standard
error besides its result and its errors. Both are accepted the same way by the ``hcard`` group
and by every command (``hcard -q encode ...`` and ``hcard encode -q ...``), through
:func:`verbosity_options`; a command asks :func:`verbosity` or :func:`quiet`."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import click

QUIET, NORMAL, VERBOSE = -1, 0, 1
"""Verbosity levels: no progress lines; progress lines; every detail a command can list."""

_KEY = "hcard.verbosity"
_QUIET_HELP = "No progress lines on standard error (results and errors still print)."
_VERBOSE_HELP = "Every detail the command can list (e.g. every conformance case)."

F = TypeVar("F", bound=Callable[..., object])


def verbosity() -> int:
    """The level set for the running command by any ``-q``/``-v`` on its command line
    (NORMAL outside a command)."""
    context = click.get_current_context(silent=True)
    if context is None:
        return NORMAL
    return int(context.find_root().meta.get(_KEY, NORMAL))


def quiet() -> bool:
    """Whether progress lines are to be left out."""
    return verbosity() == QUIET


def _record(level: int) -> Callable[[click.Context, click.Parameter, bool], None]:
    """The callback of ``-q`` (``level`` QUIET) or ``-v`` (VERBOSE): record the level on the
    root context, where every command reads it; both given anywhere is a usage error."""
    def callback(context: click.Context, _param: click.Parameter, given: bool) -> None:
        if not given:
            return
        meta = context.find_root().meta
        if meta.get(_KEY, level) != level:
            raise click.UsageError("give -q or -v, not both", ctx=context)
        meta[_KEY] = level
    return callback


def verbosity_options(command: F) -> F:
    """Add ``-q/--quiet`` and ``-v/--verbose`` to a click command or group (the flags are not
    passed to the function: it asks :func:`verbosity`)."""
    for flags, level, text in ((("-v", "--verbose"), VERBOSE, _VERBOSE_HELP),
                               (("-q", "--quiet"), QUIET, _QUIET_HELP)):
        command = click.option(*flags, is_flag=True, expose_value=False, is_eager=True,
                               callback=_record(level), help=text)(command)
    return command
