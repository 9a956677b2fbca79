"""Exit statuses of the command line, and user errors reported as one line on stderr (status 1)
without a traceback; internal errors get theirs and status 3."""

from __future__ import annotations

import traceback
from typing import Any

import click

from hcard.errors import HcardError
from hcard.terminal_text import printable

EXIT_OK = 0
"""Exit status: the command did what was asked (a valid card, a passed check)."""
EXIT_FAILED = 1
"""Exit status: invalid input (a file that cannot be read or is invalid) or a failed check."""
EXIT_USAGE = 2
"""Exit status: the command line itself is wrong (unknown option, bad value); click's own."""
EXIT_INTERNAL = 3
"""Exit status: an internal error, a bug in hcard or a plugin (the traceback follows)."""


class UserErrorGroup(click.Group):
    """A click group that reports :class:`HcardError` as ``Error: <message>`` and exits
    :data:`EXIT_FAILED`; anything else that escapes a command is a bug: its traceback is printed
    with a line saying so, and the exit status is :data:`EXIT_INTERNAL`."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except HcardError as exc:
            raise click.ClickException(printable(str(exc))) from None
        except (click.exceptions.Exit, click.ClickException, click.Abort, SystemExit,
                KeyboardInterrupt):
            raise
        except Exception as exc:
            traceback.print_exc()
            click.echo(f"hcard: internal error ({type(exc).__name__}): this is a bug; please "
                       "report it with the traceback above", err=True)
            ctx.exit(EXIT_INTERNAL)
