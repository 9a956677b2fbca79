"""Entry point of the ``hcard`` command: the click group and its commands."""

from __future__ import annotations

import importlib
import sys
import warnings
from typing import Any

import click

from hcard import __version__
from hcard.cli.errors import UserErrorGroup
from hcard.cli.verbosity import set_verbosity
from hcard.limits import FORMAT_MAJOR, FORMAT_MINOR

COMMAND_MODULES = {
    "encode": "encode_cmd", "info": "card_cmds", "validate": "card_cmds",
    "render": "render_cmd", "preview": "preview_cmd", "predict": "predict_cmd",
    "plugins": "plugins_cmd", "device": "device_cmd", "play": "device_cmd",
    "conformance": "conformance_cmd", "calibrate": "calibrate_cmd",
}
"""Each command's module under ``hcard.cli``, imported only when the command runs: ``hcard
validate`` loads the card modules and not the renderer, the calibration loop or the device
drivers (bench/bench_cli_startup.py)."""

COMMAND_SUMMARIES = {
    "calibrate": "Fit a model to recordings, find what it lacks, verify it.",
    "conformance": "Run the conformance suite against an implementation.",
    "device": "Serve the reference device over USB/IP, or list devices.",
    "encode": "Encode a grayscale IMAGE: black is high friction, white low.",
    "info": "Describe each CARD: metadata, surface, grid and every texture.",
    "play": "Play CARD on a device along a finger track and record it.",
    "plugins": "List installed encoders, predictors, drivers, effects, checks.",
    "predict": "Evaluate a physics predictor MODEL at a point or over a sweep.",
    "preview": "Draw CARD as a PNG picture of its taxtels and textures.",
    "render": "Render CARD along a finger track into target friction.",
    "validate": "Check each CARD against the spec; list problems by rule.",
}
"""The first sentence of each command's help, which ``hcard --help`` lists without importing
any command module (tests/test_cli_help.py checks them against the commands' own help)."""


class LazyCommandGroup(UserErrorGroup):
    """The ``hcard`` group: commands listed from :data:`COMMAND_MODULES`, each module imported
    when its command is asked for."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMAND_MODULES)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list of ``hcard --help``, from :data:`COMMAND_SUMMARIES`."""
        with formatter.section("Commands"):
            formatter.write_dl([(name, COMMAND_SUMMARIES[name])
                                for name in self.list_commands(ctx)])

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        module_name = COMMAND_MODULES.get(cmd_name)
        if module_name is None:
            return None
        module = importlib.import_module(f"hcard.cli.{module_name}")
        return next(command for command in module.COMMANDS if command.name == cmd_name)


@click.group(cls=LazyCommandGroup, context_settings={"help_option_names": ["-h", "--help"]})
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


