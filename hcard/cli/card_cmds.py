"""``hcard info`` and ``hcard validate``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from hcard.bounded_read import STDIN
from hcard.card_io import (
    card_from_bytes,
    check_version,
    format_for_path,
    looks_like_json,
    read_card_file,
)
from hcard.cli.errors import EXIT_FAILED
from hcard.cli.input_files import INPUT_FILE_OR_STDIN
from hcard.cli.verbosity import verbosity_options
from hcard.describe import card_summary, describe_card
from hcard.errors import CardError, Problem, problem_count
from hcard.terminal_text import printable
from hcard.v1 import card_pb2 as pb
from hcard.validate import validate

CARD = INPUT_FILE_OR_STDIN


@click.command()
@verbosity_options
@click.argument("cards", nargs=-1, required=True, type=CARD)
@click.option("--json", "as_json", is_flag=True,
              help="Print the summary as JSON on stdout: one object for one card, an array of "
                   "them for several.")
def info(cards: tuple[Path, ...], as_json: bool) -> None:
    """Describe each CARD: metadata, surface, grid and every texture.

    A CARD of - is read from standard input. An invalid card is still described, with a count
    of its problems (hcard validate lists them), and the exit status is then 1.

    \b
    Examples:
      hcard info card.hcard
      hcard info a.hcard b.hcard.json --json
      hcard encode photo.png -o - | hcard info -
    """
    summaries = []
    any_failing = False
    for card in cards:
        name = "<stdin>" if str(card) == STDIN else str(card)
        parsed, data, problems = check_card_file(card)
        errors = [p for p in problems if p.severity == "error"]
        error_count = problem_count(errors)
        any_failing |= bool(errors)
        if parsed is None:
            if as_json:
                summaries.append({"file": name, "valid": False, "error": errors[0].reason})
            else:
                click.echo(printable(f"Error: {name}: {errors[0]}"), err=True)
            continue
        form = "JSON" if looks_like_json(data) else "binary"
        if as_json:
            summary = {"file": name, "form": form.lower(), "bytes": len(data),
                       "valid": not errors, "errors": error_count,
                       "warnings": problem_count(problems) - error_count}
            summary.update(card_summary(parsed))
            summaries.append(summary)
            continue
        click.echo(printable(f"{name}: hcard card, {form}, {len(data)} bytes"))
        for line in describe_card(parsed):
            click.echo(printable(line))
        if errors:
            click.echo(printable(f"{name}: invalid: {error_count} error(s) (hcard validate "
                                 f"{name} lists them)"), err=True)
    if as_json:
        click.echo(json.dumps(summaries[0] if len(summaries) == 1 else summaries, indent=2))
    if any_failing:
        raise SystemExit(EXIT_FAILED)


def _read_problem(exc: CardError) -> Problem:
    """A card that cannot be read or parsed as one problem: rule V1 for its version, F6 for
    its size, F7 for the rest (spec/README.md section 8)."""
    rule = "V1" if exc.field_path.startswith("version") else (
        "F6" if "size limit" in exc.reason else "F7")
    return Problem(exc.field_path, exc.reason, "error", rule)


def check_card_file(card: Path) -> tuple[pb.Card | None, bytes, list[Problem]]:
    """Read, parse and validate one card file: the card (None when it does not parse), its
    bytes and its problems."""
    data = b""
    try:
        data = read_card_file(card)
        parsed = card_from_bytes(data, source=card)
        check_version(parsed, source=card)
    except CardError as exc:
        return None, data, [_read_problem(exc)]
    return parsed, data, validate(parsed)


@click.command(name="validate")
@verbosity_options
@click.argument("cards", nargs=-1, required=True, type=CARD)
@click.option("--json", "as_json", is_flag=True,
              help="Print the findings as JSON on stdout: one object for one card, an array of "
                   "them for several.")
@click.option("--strict", is_flag=True, help="Treat warnings as errors.")
def validate_cmd(cards: tuple[Path, ...], as_json: bool, strict: bool) -> None:
    """Check each CARD against the spec; list problems by rule.

    Each problem names its rule and the field it is in. A CARD of - is read from standard
    input.

    Exits 0 when every card is valid, 1 when one has errors (or warnings, with --strict) or
    cannot be read.

    \b
    Examples:
      hcard validate card.hcard
      hcard validate cards/*.hcard --strict
      hcard encode photo.png -o - | hcard validate -
      hcard validate card.json --json | jq '.problems[] | select(.rule == "G6")'
    """
    reports = []
    any_failing = False
    for card in cards:
        name = "<stdin>" if str(card) == STDIN else str(card)
        parsed, data, problems = check_card_file(card)
        failing = [p for p in problems if strict or p.severity == "error"]
        any_failing |= bool(failing)
        reports.append({
            "file": name,
            "valid": not failing,
            "problem_count": problem_count(problems),
            "problems": [{"path": p.path, "reason": p.reason, "severity": p.severity,
                          "rule": p.rule, "count": p.count} for p in problems],
        })
        if as_json:
            continue
        for p in problems:
            rule = f" {p.rule}" if p.rule else ""
            click.echo(printable(f"{name}: {p.severity}{rule}: {p}"), err=True)
        if parsed is not None and not failing:
            form = "JSON" if format_for_path(card) == "json" or looks_like_json(data) else "binary"
            click.echo(printable(
                f"{name}: valid hcard {parsed.version.major}.{parsed.version.minor} card ({form}, "
                f"{len(parsed.textures)} textures, {parsed.grid.cols} x {parsed.grid.rows} taxtels)"
            ))
        elif failing and parsed is not None:  # an unreadable card's one line says it all
            errors = problem_count([p for p in failing if p.severity == "error"])
            click.echo(printable(f"{name}: invalid: {problem_count(failing)} problem(s), "
                                 f"{errors} error(s)"), err=True)
    if as_json:
        click.echo(json.dumps(reports[0] if len(reports) == 1 else reports, indent=2))
    if any_failing:
        raise SystemExit(EXIT_FAILED)


COMMANDS = [info, validate_cmd]
