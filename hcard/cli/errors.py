"""Exit statuses of the command line, and user errors reported as one line on stderr without a
traceback: invalid input with status 1, a bad command line with status 2; internal errors get
their traceback and status 3; a standard output closed early (``hcard info CARD | head``) ends
the command quietly."""

from __future__ import annotations

import contextlib
import os
import sys
import traceback
from collections.abc import Iterator
from typing import Any

import click

from hcard.errors import HcardError, InputError, UsageError
from hcard.terminal_text import printable

EXIT_OK = 0
"""Exit status: the command did what was asked (a valid card, a passed check)."""
EXIT_FAILED = 1
"""Exit status: invalid input (a file that cannot be read or is invalid) or a failed check."""
EXIT_USAGE = 2
"""Exit status: the command line itself is wrong (an unknown option, a bad option value,
options that do not fit together): click's own, and every :class:`~hcard.errors.UsageError`."""
EXIT_INTERNAL = 3
"""Exit status: an internal error, a bug in hcard or a plugin (the traceback follows)."""
EXIT_BROKEN_PIPE = 141
"""Exit status when standard output was closed before the command finished (``| head``):
128 + SIGPIPE, what a program killed by the signal reports, as ``yes | head`` does."""


def usage_error(message: str) -> click.UsageError:
    """A :class:`~hcard.errors.UsageError` as click's usage error: exit status
    :data:`EXIT_USAGE`, shown as ``Error: <message>`` on one line (without a context click
    prints no usage header)."""
    error = click.UsageError(message)
    error.ctx = None
    return error


@contextlib.contextmanager
def option_values(*also: type[HcardError]) -> Iterator[None]:
    """Read option values inside this block: an :class:`~hcard.errors.InputError` raised there
    (a unit that does not parse, a malformed ``NAME=VALUE``), or one of the error types
    ``also`` (a model's ``PredictorError`` for a parameter outside its bounds), is about the
    command line, so it becomes a :class:`~hcard.errors.UsageError` (exit status 2) with the
    same message."""
    caught: tuple[type[HcardError], ...] = (InputError, *also)
    try:
        yield
    except caught as exc:
        raise UsageError(str(exc)) from None


def silence_closed_stdout() -> None:
    """Point standard output at the null device after the reader went away, so that the flush
    at exit finds nothing to write and prints no second error (Python's own advice for
    SIGPIPE)."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


class UserErrorGroup(click.Group):
    """A click group that reports :class:`HcardError` as ``Error: <message>``, exit status
    :data:`EXIT_FAILED` (:data:`EXIT_USAGE` for a :class:`~hcard.errors.UsageError`), and a
    closed standard output as a quiet :data:`EXIT_BROKEN_PIPE`; anything else that escapes a
    command is a bug: its traceback is printed with a line saying so, and the exit status is
    :data:`EXIT_INTERNAL`."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except UsageError as exc:
            raise usage_error(printable(str(exc))) from None
        except HcardError as exc:
            raise click.ClickException(printable(str(exc))) from None
        except BrokenPipeError:
            silence_closed_stdout()
            ctx.exit(EXIT_BROKEN_PIPE)
        except (click.exceptions.Exit, click.ClickException, click.Abort, SystemExit,
                KeyboardInterrupt):
            raise
        except Exception as exc:
            traceback.print_exc()
            click.echo(f"hcard: internal error ({type(exc).__name__}): this is a bug; please "
                       "report it with the traceback above", err=True)
            ctx.exit(EXIT_INTERNAL)
