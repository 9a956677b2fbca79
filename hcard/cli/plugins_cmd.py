"""``hcard plugins``: list installed plugins and report broken ones."""

from __future__ import annotations

import json
import warnings

import click

from hcard.cli.verbosity import verbosity_options
from hcard.plugins.records import HcardPluginWarning, PluginInfo
from hcard.plugins.registry import get_registry

COLUMNS = ("NAME", "KIND", "VERSION", "PACKAGE", "DESCRIPTION")


def _row(info: PluginInfo) -> tuple[str, ...]:
    return (info.name, info.kind, info.version or "-", info.package, info.description)


def format_table(infos: list[PluginInfo]) -> str:
    """A plain-text table of ``infos`` with the :data:`COLUMNS` header, columns left-aligned."""
    rows = [COLUMNS, *(_row(info) for info in infos)]
    widths = [max(len(row[i]) for row in rows) for i in range(len(COLUMNS) - 1)]
    lines = []
    for row in rows:
        cells = [cell.ljust(width) for cell, width in zip(row[:-1], widths, strict=True)]
        lines.append("  ".join([*cells, row[-1]]).rstrip())
    return "\n".join(lines)


@click.command("plugins")
@verbosity_options
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def plugins(as_json: bool) -> None:
    """List installed plugins: encoders, predictors, drivers, formats.

    Plugins come from the ``hcard.plugins`` entry-point group (the built-ins too). A plugin that
    cannot be loaded is reported as a warning on stderr and skipped; the command still exits 0.

    \b
    Examples:
      hcard plugins
      hcard plugins --json | jq '.plugins[] | select(.kind == "predictor") | .name'
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", HcardPluginWarning)
        registry = get_registry()
        registry.collect()  # every hook, so that every problem is warned here
    # The registry is cached: problems found by an earlier discovery in this process are in
    # ``broken`` but were not warned again, so report from there and show other warnings as is.
    messages = [problem.reason for problem in registry.broken]
    for warning in caught:
        if issubclass(warning.category, HcardPluginWarning):
            if str(warning.message) not in messages:
                messages.append(str(warning.message))
        else:
            warnings.showwarning(
                warning.message, warning.category, warning.filename, warning.lineno
            )
    for message in messages:
        click.echo(f"warning: {message}", err=True)

    infos = registry.all()
    if as_json:
        document = {
            "plugins": [
                {
                    "name": info.name,
                    "kind": info.kind,
                    "version": info.version,
                    "package": info.package,
                    "entry_point": info.entry_point,
                    "description": info.description,
                }
                for info in infos
            ],
            "broken": [
                {"entry_point": problem.entry_point, "reason": problem.reason}
                for problem in registry.broken
            ],
        }
        click.echo(json.dumps(document, indent=2))
    elif infos:
        click.echo(format_table(infos))
    else:
        click.echo("no plugins installed")


COMMANDS = [plugins]
