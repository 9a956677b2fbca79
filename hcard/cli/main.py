"""Entry point of the ``hcard`` command: the click group and its commands, and :func:`main`,
the console script that runs them."""

from __future__ import annotations

import gc
import importlib
import sys
import warnings
from typing import TYPE_CHECKING, Any

import click

from hcard.cli.errors import UserErrorGroup
from hcard.cli.verbosity import verbosity_options
from hcard.limits import FORMAT_MAJOR, FORMAT_MINOR
from hcard.version import __version__

if TYPE_CHECKING:
    from hcard.plugins.kinds import CommandPlugin

COMMAND_MODULES = {
    "encode": "encode_cmd", "info": "card_cmds", "validate": "card_cmds",
    "render": "render_cmd", "preview": "preview_cmd", "predict": "predict_cmd",
    "plugins": "plugins_cmd", "calibrate": "calibrate_cmd",
    "import": "interchange_cmds", "export": "interchange_cmds", "view": "view_cmd",
}
"""Each core command's module under ``hcard.cli``, imported only when the command runs: ``hcard
validate`` loads the card modules and not the renderer or the calibration loop
(bench/bench_cli_startup.py). Other packages contribute commands through the ``hcard_commands``
hook (``hcard device`` and ``hcard play`` from ``hcard_device``, ``hcard conformance`` from
``hcard_conformance``)."""

COMMAND_SUMMARIES = {
    "calibrate": "Fit a model to recordings, find what it lacks, verify it.",
    "encode": "Encode a grayscale IMAGE: black is high friction, white low.",
    "export": "Export CARD to another tool's format: .hjif, Tanvas, TPad.",
    "import": "Import SOURCE, another tool's haptic asset, into a card.",
    "info": "Describe each CARD: metadata, surface, grid and every texture.",
    "plugins": "List installed plugins: encoders, predictors, drivers, formats.",
    "predict": "Evaluate a physics predictor MODEL at a point or over a sweep.",
    "preview": "Draw CARD as a PNG picture of its taxtels and textures.",
    "render": "Render CARD along a finger track into target friction.",
    "validate": "Check each CARD against the spec; list problems by rule.",
    "view": "Show each CARD on a local page; draw strokes and render them.",
}
"""The first sentence of each core command's help, which ``hcard --help`` lists without
importing any command module (tests/cli/test_cli.py checks them against the commands' own help)."""


def contributed_commands() -> dict[str, CommandPlugin]:
    """Commands other packages contribute (``hcard_commands`` hook, entry-point group
    ``hcard.commands``), by name, without the core's names. Problems (a plugin that fails to
    import, a name taken by a core command) are ``warning:`` lines; the rest still works.

    What an earlier run found is reused while the installed packages are unchanged
    (:mod:`hcard.plugins.command_cache`), so that ``hcard --help`` needs no entry-point scan."""
    global _remembered
    if _discovered():
        commands = _discover_commands()
    else:
        if _remembered is None:
            from hcard.plugins import command_cache

            _remembered = command_cache.load()
        commands = dict(_remembered) if _remembered is not None else _discover_commands()
    for name in sorted(set(commands) & set(COMMAND_MODULES)):
        if name not in _WARNED_SHADOWING:
            _WARNED_SHADOWING.add(name)
            _show_warning(f"plugin command '{name}' has the name of a core command; it is "
                          "ignored", UserWarning)
        del commands[name]
    return commands


_remembered: dict[str, CommandPlugin] | None = None
"""The commands :mod:`hcard.plugins.command_cache` remembered, read once per process."""

_WARNED_SHADOWING: set[str] = set()
"""Core command names a plugin command was found to shadow (each is warned once)."""


def _discovered() -> bool:
    registry = sys.modules.get("hcard.plugins.registry")  # not imported: not discovered
    return registry is not None and bool(registry.command_registry_discovered())


def _discover_commands() -> dict[str, CommandPlugin]:
    """The commands of the command registry, warning about its problems; when this call
    discovered them and there were none, remembered for the next run."""
    from hcard.plugins import command_cache
    from hcard.plugins.registry import get_command_registry

    fresh = not _discovered()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        registry = get_command_registry()
        commands = registry.commands
        broken = registry.broken
    for warning in caught:
        _show_warning(warning.message, warning.category)
    if fresh and not broken:
        modules = [getattr(plugin, "__file__", None)
                   for plugin in registry.plugin_manager.get_plugins()]
        command_cache.store(commands, [path for path in modules if isinstance(path, str)])
    return commands


class LazyCommandGroup(UserErrorGroup):
    """The ``hcard`` group: the core commands of :data:`COMMAND_MODULES` and the commands of
    :func:`contributed_commands`, each module imported when its command is asked for."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*COMMAND_MODULES, *contributed_commands()})

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list of ``hcard --help``: :data:`COMMAND_SUMMARIES` and the summaries
        of the contributed commands."""
        summaries = {name: command.summary for name, command in contributed_commands().items()}
        summaries.update(COMMAND_SUMMARIES)
        with formatter.section("Commands"):
            formatter.write_dl(sorted(summaries.items()))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        module_name = COMMAND_MODULES.get(cmd_name)
        if module_name is None:
            contributed = contributed_commands().get(cmd_name)
            return None if contributed is None else _load(contributed)
        module = importlib.import_module(f"hcard.cli.{module_name}")
        return next(command for command in module.COMMANDS if command.name == cmd_name)


def _load(command: CommandPlugin) -> click.Command | None:
    """The click command of a contributed ``command``; None, with a warning naming it, when it
    cannot be loaded (click then reports no such command)."""
    try:
        loaded = command.load()
    except Exception as exc:  # a broken plugin must not crash the tool
        from hcard.plugins import command_cache

        command_cache.forget_commands()  # perhaps remembered from before the package changed
        _show_warning(f"command '{command.name}' cannot be loaded: {type(exc).__name__}: {exc}",
                      UserWarning)
        return None
    if not isinstance(loaded, click.Command):
        _show_warning(f"command '{command.name}' loaded a {type(loaded).__name__}, not a click "
                      "command; it is ignored", UserWarning)
        return None
    return loaded


@click.group(cls=LazyCommandGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(
    __version__, prog_name="hcard",
    message=f"%(prog)s %(version)s (card format {FORMAT_MAJOR}.{FORMAT_MINOR})",
)
@verbosity_options
def cli() -> None:
    """hcard: the haptic-card toolkit for friction-modulation (UV/EV) touchscreens.

    A card (.hcard binary, or .json) describes a surface as a grid of taxtels, each playing a
    texture of (frequency, amplitude, phase) components on the UV and EV channels. Author cards
    (encode), check them (info, validate, preview), render them (render), evaluate the physics
    (predict), drive devices (device, play), prove an implementation (conformance) and fit the
    physics to tribometer recordings (calibrate).

    \b
    Examples:
      hcard encode examples/gratings.png -o gratings.hcard --preview gratings.png
      hcard validate gratings.hcard
      hcard -q render gratings.hcard --track stroke.csv -o frames.npz
      hcard encode --help
    """
    warnings.showwarning = _show_warning


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kw: Any) -> None:
    """Warnings on the command line as one ``warning: ...`` line each, without source lines."""
    print(f"warning: {message}", file=sys.stderr)


def main(args: list[str] | None = None) -> None:
    """The ``hcard`` console script and ``python -m hcard``: :func:`cli` on ``args`` (default:
    the process's arguments), then the exit of the process, which it speeds up.

    At exit the interpreter runs full garbage-collection passes over every object still alive,
    most of them made by the imports (numpy, protobuf, click, the plugins): the exit of a 0.19 s
    ``hcard encode`` at 1024^2 pixels took 28 ms, three times that of a process that only
    decodes the image with Pillow. :func:`gc.freeze` moves those objects to the permanent
    generation, which the passes skip: 7 ms (bench/bench_cli_startup.py prints the figures).
    Exit handlers, the flush of the standard streams and module teardown still run; what is no
    longer done is finalizing objects caught in reference cycles, which Python never promises
    at exit: commands close their files and devices themselves (``with`` blocks) before they
    return. Not for a process that goes on after the command (tests use :func:`cli` through
    click's runner): frozen objects are never collected.
    """
    try:
        cli(args, prog_name="hcard")
    finally:
        gc.freeze()
