"""User errors on the command line: one line on stderr, exit status 1, no traceback."""

from __future__ import annotations

from typing import Any

import click

from hcard.errors import HcardError
from hcard.terminal_text import printable


class UserErrorGroup(click.Group):
    """A click group that reports :class:`HcardError` as ``Error: <message>`` and exits 1."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except HcardError as exc:
            raise click.ClickException(printable(str(exc))) from None
