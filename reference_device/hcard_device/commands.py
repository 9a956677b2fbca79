"""The reference device's subcommands of ``hcard``, contributed through the ``hcard_commands``
hook (entry point ``device`` of the ``hcard.commands`` group).

This module is imported by every ``hcard --help``, so it names the commands and their help
summaries without importing them: :mod:`hcard_device.device_cmd` is imported when one runs.
"""

from __future__ import annotations

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.kinds import LazyCommand


@hookimpl
def hcard_commands() -> list[LazyCommand]:
    """``hcard device`` and ``hcard play``."""
    return [
        LazyCommand(
            "device", "hcard_device.device_cmd:device",
            "Serve the reference device over USB/IP, or list devices.",
        ),
        LazyCommand(
            "play", "hcard_device.device_cmd:play",
            "Play CARD on a device along a finger track and record it.",
        ),
    ]
