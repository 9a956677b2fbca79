"""``hcard conformance``: run the conformance suite against an implementation.

Prints a readable table, writes JUnit XML (``--junit``) and JSON (``--json``) atomically, and
exits 0 when every case passes, 1 when one fails, 2 on a usage or infrastructure error (unknown
driver, device unreachable, vectors missing) (spec/conformance.md Q7).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import click

from hcard.bounded_read import STDIN
from hcard.cli.verbosity import QUIET, VERBOSE, verbosity, verbosity_options
from hcard.errors import HcardError
from hcard.file_errors import writing

LEVEL_NAMES = ("format", "renderer", "device")
TIMING_NAMES = ("real-time", "software-emulation")
"""Names of hcard_conformance.timing.TIMING_CLASSES, the default first (kept here so that
``hcard --help`` does not import the conformance package; a test holds them equal)."""


def _option_value(text: str) -> Any:
    """``KEY=VALUE`` option values: numbers as float, ``true``/``false`` as bool, else text."""
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return float(text)
    except ValueError:
        return text


def _parse_options(pairs: tuple[str, ...]) -> dict[str, Any]:
    options: dict[str, Any] = {}
    tolerances: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{pair!r} is not KEY=VALUE", param_hint="--option")
        key = key.strip()
        if key.startswith("tolerance."):
            tolerances[key.removeprefix("tolerance.")] = _option_value(value)
        else:
            options[key] = _option_value(value)
    if tolerances:
        options["tolerances"] = tolerances
    return options


@click.command()
@verbosity_options
@click.option("--driver", "driver_name", required=True, metavar="NAME",
              help="Implementation under test: 'reference' (hcard.render), a device URI "
                   "(sim://, usbip://HOST:PORT/BUSID, hid://PATH, ...), a negative control "
                   "(control:NAME) or the faulty device (faulty://FAULT?strength=S); see "
                   "conformance/README.md.")
@click.option("--level", "levels", multiple=True, type=click.Choice(LEVEL_NAMES),
              help="Level to run (repeatable); default: all levels.")
@click.option("--check", "select", multiple=True, metavar="PREFIX",
              help="Only checks whose name starts with PREFIX (repeatable).")
@click.option("--junit", "junit_path",
              type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              help="Write JUnit XML here (for CI); - for standard output.")
@click.option("--json", "json_path",
              type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              help="Write the JSON report here (for tools); - for standard output, which "
                   "then holds only the JSON (the table goes to standard error).")
@click.option("--vectors", "vectors_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Vectors directory (default: spec/vectors of this installation).")
@click.option("--option", "option_pairs", multiple=True, metavar="KEY=VALUE",
              help="Option for checks (repeatable); 'tolerance.NAME=VALUE' tightens a "
                   "threshold of the manifest.")
@click.option("--timing", type=click.Choice(TIMING_NAMES), default=None,
              help="What the host keeps of real time (spec/conformance.md 5.2): 'real-time' "
                   "(a bench PC; default) or 'software-emulation' (an emulated guest: "
                   "looser latency and report-loss bounds; rendered friction and dynamics "
                   "not applicable).")
@click.option("--list", "list_cases", is_flag=True,
              help="List the cases a run would measure, CHECK::CASE a line (the pytest "
                   "plugin's node IDs), and measure nothing.")
def conformance(driver_name: str, levels: tuple[str, ...], select: tuple[str, ...],
                junit_path: Path | None, json_path: Path | None, vectors_dir: Path | None,
                option_pairs: tuple[str, ...], timing: str | None, list_cases: bool) -> None:
    """Run the conformance suite against an implementation.

    Exits 0 when every case passes, 1 when one fails, 2 when the driver or vectors cannot be
    used.

    \b
    Examples:
      hcard conformance --driver sim://
      hcard conformance --driver usbip://127.0.0.1:3240/1-1 --junit results.xml
      hcard conformance --driver sim:// --level format --json - | jq .totals
      hcard conformance --driver sim:// --level device --list
    """
    from hcard.atomic import write_atomically
    from hcard_conformance.context import Context
    from hcard_conformance.report import (
        json_bytes,
        junit_setup_error,
        junit_xml,
        table,
        write_json,
        write_junit,
    )
    from hcard_conformance.runner import run_suite

    quiet, verbose = verbosity() == QUIET, verbosity() == VERBOSE
    options = _parse_options(option_pairs)
    if timing is not None:
        options["timing"] = timing
    if str(options.get("timing", TIMING_NAMES[0])) not in TIMING_NAMES:
        raise click.BadParameter(f"unknown timing class {options['timing']!r}; known: "
                                 f"{', '.join(TIMING_NAMES)}", param_hint="--option timing")
    ctx = Context.for_driver(driver_name, vectors_root=vectors_dir, options=options)

    def cannot_start(message: str) -> click.UsageError:
        """The usage error of a run that cannot start, after writing its JUnit file (one
        error case), so that CI shows why (exit 2)."""
        if junit_path is not None and str(junit_path) != STDIN:
            with writing(junit_path, HcardError):
                write_atomically(junit_path, junit_setup_error(driver_name, message))
        elif junit_path is not None:
            click.echo(junit_setup_error(driver_name, message).decode(), nl=False)
        return click.UsageError(message)

    try:
        ctx.manifest  # noqa: B018 - load now: missing vectors are a usage error (exit 2)
    except (OSError, ValueError, KeyError) as exc:
        raise cannot_start(f"cannot read the vectors in {ctx.vectors_root}: {exc}") from None
    if ctx.open_driver is not None:
        try:
            ctx.open_driver().close()
        except (HcardError, OSError, ValueError) as exc:
            raise cannot_start(f"cannot open driver {driver_name!r}: {exc}") from None

    if list_cases:
        _list(ctx, levels or LEVEL_NAMES, select)
        return
    started = time.perf_counter()

    def check_done(chk: Any, results: list[Any], seconds: float) -> None:
        if quiet:
            return
        failed = sum(not r.passed for r in results)
        state = "ok" if not failed else f"{failed} FAILED"
        click.echo(f"[{time.perf_counter() - started:7.2f} s] {chk.name}: {len(results)} "
                   f"case(s), {state} ({seconds:.2f} s)", file=sys.stderr)

    report = run_suite(ctx, levels or LEVEL_NAMES, select=select, check_done=check_done)
    if not report.results:
        raise cannot_start(
            f"no check of level(s) {', '.join(report.levels)} applies to {driver_name!r}"
            + (f" (not applicable: {', '.join(report.not_applicable)})"
               if report.not_applicable else ""))
    to_stdout = STDIN in (str(junit_path), str(json_path))
    click.echo(table(report, verbose=verbose), nl=False, err=to_stdout)
    for path, write, text in ((junit_path, write_junit, junit_xml),
                              (json_path, write_json, json_bytes)):
        if path is not None and str(path) == STDIN:
            click.echo(text(report).decode(), nl=False)
        elif path is not None:
            with writing(path, HcardError):
                write(report, path)
            if not quiet:
                click.echo(f"wrote {path}", file=sys.stderr)
    if not report.passed:
        raise SystemExit(1)


def _list(ctx: Any, levels: tuple[str, ...], select: tuple[str, ...]) -> None:
    """Print the plan of a run (:func:`hcard_conformance.plan.plan_suite`), measuring nothing:
    ``CHECK::CASE`` a line on standard output (``CHECK::(cases)`` for a check that declares
    none, whose cases its run names; ``CHECK::(error)`` for one that cannot say, its error on
    standard error), then the checks that do not apply, on standard error."""
    from hcard_conformance.plan import plan_suite

    plan = plan_suite(ctx, levels, select=select)
    for planned in plan.checks:
        if planned.error is not None:
            click.echo(f"{planned.name}::{planned.error.case}")
            click.echo(f"{planned.name}: ERROR {planned.error.detail}", err=True)
        for case in planned.cases or ():
            click.echo(f"{planned.name}::{case}")
        if not planned.cases and planned.error is None:
            click.echo(f"{planned.name}::(cases)")
    if plan.not_applicable:
        click.echo(f"not applicable: {', '.join(plan.not_applicable)}", err=True)


COMMANDS = [conformance]
