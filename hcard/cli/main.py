"""Entry point of the ``hcard`` command: the click group and its commands."""

from __future__ import annotations

import sys
import warnings
from typing import Any

import click

from hcard import __version__
from hcard.cli.errors import UserErrorGroup
from hcard.cli.verbosity import set_verbosity
from hcard.limits import FORMAT_MAJOR, FORMAT_MINOR


@click.group(cls=UserErrorGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(
    __version__, prog_name="hcard",
    message=f"%(prog)s %(version)s (card format {FORMAT_MAJOR}.{FORMAT_MINOR})",
)
@click.option("-q", "--quiet", is_flag=True,
              help="No progress lines on standard error (results and errors still print).")
@click.option("-v", "--verbose", is_flag=True,
              help="Every detail a command can list (e.g. every conformance case).")
@click.pass_context
def cli(context: click.Context, quiet: bool, verbose: bool) -> None:
    """hcard: the haptic-card toolkit for friction-modulation (UV/EV) touchscreens.

    A card (.hcard binary, or .json) describes a surface as a grid of taxtels, each playing a
    texture of (frequency, amplitude, phase) components on the UV and EV channels. Author cards
    (encode), check them (info, validate, preview), render them (render), evaluate the physics
    (predict), drive devices (device, play), prove an implementation (conformance) and fit the
    physics to tribometer recordings (calibrate).
    """
    warnings.showwarning = _show_warning
    set_verbosity(context, quiet, verbose)


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kw: Any) -> None:
    """Warnings on the command line as one ``warning: ...`` line each, without source lines."""
    print(f"warning: {message}", file=sys.stderr)


def _register_commands() -> None:
    from hcard.cli import (
        calibrate_cmd,
        card_cmds,
        conformance_cmd,
        device_cmd,
        encode_cmd,
        plugins_cmd,
        predict_cmd,
        preview_cmd,
        render_cmd,
    )

    for module in (encode_cmd, card_cmds, render_cmd, preview_cmd, predict_cmd, plugins_cmd,
                   device_cmd, conformance_cmd, calibrate_cmd):
        for command in module.COMMANDS:
            cli.add_command(command)


_register_commands()
