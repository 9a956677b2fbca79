"""The conformance suite's subcommand of ``hcard``, contributed through the ``hcard_commands``
hook (entry point ``conformance`` of the ``hcard.commands`` group).

This module is imported by every ``hcard --help``, so it names the command and its help
summary without importing it: :mod:`hcard_conformance.conformance_cmd` is imported when it runs.
"""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.kinds import LazyCommand


@hookimpl
def hcard_commands() -> list[LazyCommand]:
    """``hcard conformance``."""
    return [
        LazyCommand(
            "conformance", "hcard_conformance.conformance_cmd:conformance",
            "Run the conformance suite against an implementation.",
        ),
    ]
