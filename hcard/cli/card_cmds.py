"""``hcard info`` and ``hcard validate``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from hcard.card_io import (
    card_from_bytes,
    check_version,
    format_for_path,
    looks_like_json,
    parse_card,
    read_card_file,
)
from hcard.describe import describe_card
from hcard.terminal_text import printable
from hcard.validate import validate

CARD = click.Path(dir_okay=False, path_type=Path)


@click.command()
@click.argument("card", type=CARD)
def info(card: Path) -> None:
    """Print a readable summary of CARD: metadata, surface, grid and every texture."""
    data = read_card_file(card)
    loaded = parse_card(data, source=card)
    form = "JSON" if looks_like_json(data) else "binary"
    click.echo(printable(f"{card}: hcard card, {form}, {len(data)} bytes"))
    for line in describe_card(loaded):
        click.echo(printable(line))


@click.command(name="validate")
@click.argument("card", type=CARD)
@click.option("--json", "as_json", is_flag=True, help="Print the problems as JSON.")
@click.option("--strict", is_flag=True, help="Treat warnings as errors.")
def validate_cmd(card: Path, as_json: bool, strict: bool) -> None:
    """Check CARD against the rules of the spec; list every problem with its field path.

    Exits 0 when the card is valid, 1 when it has errors (or warnings, with --strict).
    """
    data = read_card_file(card)
    parsed = card_from_bytes(data, source=card)
    check_version(parsed, source=card)
    problems = validate(parsed)
    failing = [p for p in problems if strict or p.severity == "error"]
    if as_json:
        click.echo(
            json.dumps(
                {
                    "file": str(card),
                    "valid": not failing,
                    "problems": [
                        {"path": p.path, "reason": p.reason, "severity": p.severity}
                        for p in problems
                    ],
                },
                indent=2,
            )
        )
    else:
        for p in problems:
            click.echo(printable(f"{card}: {p.severity}: {p}"), err=True)
        if not failing:
            form = "JSON" if format_for_path(card) == "json" or looks_like_json(data) else "binary"
            click.echo(printable(
                f"{card}: valid hcard {parsed.version.major}.{parsed.version.minor} card ({form}, "
                f"{len(parsed.textures)} textures, {parsed.grid.cols} x {parsed.grid.rows} taxtels)"
            ))
    if failing:
        errors = sum(p.severity == "error" for p in failing)
        if not as_json:
            click.echo(printable(f"{card}: invalid: {len(failing)} problem(s), {errors} error(s)"),
                       err=True)
        raise SystemExit(1)


COMMANDS = [info, validate_cmd]
