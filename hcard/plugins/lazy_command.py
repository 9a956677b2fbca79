"""A subcommand of ``hcard`` named by import path (a :class:`~hcard.plugins.kinds.CommandPlugin`).

Its own small module: ``hcard --help`` reads remembered commands
(:mod:`hcard.plugins.command_cache`) without importing the plugin kinds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    import click


class LazyCommand(NamedTuple):  # not a dataclass: 0.06 ms to define instead of 0.4 ms
    """A :class:`CommandPlugin` naming the click command by import path.

    Attributes:
        name: the subcommand.
        target: ``"package.module:attribute"`` of the ``click.Command``.
        summary: the first sentence of the command's help, on one line.
    """

    name: str
    target: str
    summary: str

    def load(self) -> click.Command:
        """Import ``target`` and return the command it names."""
        import pkgutil

        return pkgutil.resolve_name(self.target)
