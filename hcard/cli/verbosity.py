"""The command line's global ``-q/--quiet`` and ``-v/--verbose`` (``hcard -q encode ...``):
how much a command says on standard error besides its result and its errors."""

from __future__ import annotations

import click

QUIET, NORMAL, VERBOSE = -1, 0, 1
"""Verbosity levels: no progress lines; progress lines; every detail a command can list."""


def verbosity() -> int:
    """The level set on the ``hcard`` group for the running command (NORMAL outside one)."""
    context = click.get_current_context(silent=True)
    if context is None:
        return NORMAL
    level = context.find_root().meta.get("hcard.verbosity", NORMAL)
    return int(level)


def set_verbosity(context: click.Context, quiet: bool, verbose: bool) -> None:
    """Record the group's flags for its commands; both given is a usage error."""
    if quiet and verbose:
        raise click.UsageError("give -q or -v, not both")
    context.meta["hcard.verbosity"] = QUIET if quiet else VERBOSE if verbose else NORMAL


def quiet() -> bool:
    """Whether progress lines are to be left out."""
    return verbosity() == QUIET
