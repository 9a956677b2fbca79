"""``hcard calibrate``: fit a model to tribometer recordings, find the effects it lacks, report.

    hcard calibrate rec_0.csv rec_1.csv --model dimensionless-group -o calib/
    hcard calibrate recordings/ --model ev-kaczmarek --effect charge-leakage --effect air-layer

DATA are measurement CSV files (each with its ``.json`` sidecar, spec/measurement-format.md) or
directories of them. The loop (:mod:`hcard.calibration.loop`) prints one line per fit; the
report (Markdown, JSON, PNG figures) and the fitted profile go to the output directory.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from hcard.calibration.dataset import SPLITS, prepare
from hcard.calibration.loop import NOT_EXPLAINED, LoopSettings, calibrate
from hcard.calibration.measurement import MeasurementError, read_measurement
from hcard.calibration.report import write_report
from hcard.errors import HcardError
from hcard.physics.sweep import quantity, split_assignment
from hcard.plugins.registry import get_registry


class CalibrateUsageError(HcardError):
    """Options of ``hcard calibrate`` that do not fit together."""


def recording_paths(data: tuple[Path, ...]) -> list[Path]:
    """The CSV files named by DATA: files as given, directories by their ``*.csv`` (sorted)."""
    paths: list[Path] = []
    for item in data:
        if item.is_dir():
            found = sorted(item.glob("*.csv"))
            if not found:
                raise MeasurementError(f"{item}: no .csv recordings in this directory")
            paths.extend(found)
        elif item.exists():
            paths.append(item)
        else:
            raise MeasurementError(f"{item}: no such file or directory")
    return paths


def _fraction(text: str, what: str) -> float:
    """``"5%"`` or ``"0.05"`` -> 0.05."""
    try:
        value = float(text[:-1]) / 100.0 if text.strip().endswith("%") else float(text)
    except ValueError:
        raise CalibrateUsageError(
            f"{what} {text!r}: expected a fraction (0.05) or percent (5%)"
        ) from None
    if not 0.0 < value < 1.0:
        raise CalibrateUsageError(f"{what} {text!r}: must lie between 0 and 1 (0 % and 100 %)")
    return value


@click.command("calibrate")
@click.argument("data", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "--model",
    "-m",
    "model_name",
    required=True,
    help="The predictor to calibrate (see `hcard predict --list`).",
)
@click.option(
    "--effect",
    "effects",
    multiple=True,
    metavar="NAME",
    help="Candidate effect (repeatable); default: every installed calibration effect.",
)
@click.option(
    "--exclude",
    "excluded",
    multiple=True,
    metavar="NAME",
    help="Leave this effect out of the candidates (repeatable).",
)
@click.option(
    "--free",
    "free_text",
    metavar="P1,P2",
    help="Base parameters to fit (default: the model's calibrated parameters).",
)
@click.option(
    "--param",
    "params",
    multiple=True,
    metavar="NAME=VALUE",
    help="Start or fixed value of a base parameter, with unit (repeatable).",
)
@click.option(
    "--split",
    type=click.Choice(SPLITS),
    default="stroke",
    show_default=True,
    help="Hold out whole strokes, or the last time block of each recording.",
)
@click.option(
    "--test-fraction", default="25%", show_default=True, help="Share of strokes (or time) held out."
)
@click.option("--seed", default=0, show_default=True, help="Seed of the stroke draw.")
@click.option(
    "--min-improvement",
    default="5%",
    show_default=True,
    help="Held-out RMSE fall an added effect must bring.",
)
@click.option(
    "--max-effects",
    default=4,
    show_default=True,
    type=click.IntRange(min=0),
    help="Most effects added.",
)
@click.option(
    "--output",
    "-o",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("calibration"),
    show_default=True,
    help="Directory for report.md, report.json, profile.json and the figures.",
)
@click.option("--no-figures", is_flag=True, help="Skip the PNG figures.")
@click.option(
    "--no-rezero",
    is_flag=True,
    help="Do not re-measure the lateral-force zero at each lift (spec/calibration.md K4).",
)
@click.option(
    "--strict",
    is_flag=True,
    help="Exit with status 2 when structure is left that no effect explains.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress lines, only the summary.")
def calibrate_command(
    data: tuple[Path, ...],
    model_name: str,
    effects: tuple[str, ...],
    excluded: tuple[str, ...],
    free_text: str | None,
    params: tuple[str, ...],
    split: str,
    test_fraction: str,
    seed: int,
    min_improvement: str,
    max_effects: int,
    output: Path,
    no_figures: bool,
    no_rezero: bool,
    strict: bool,
    quiet: bool,
) -> None:
    """Fit MODEL to the tribometer recordings DATA, add the effects it lacks, report.

    The loop fits MODEL on the training strokes, tries each candidate effect, keeps the one
    with the best held-out criterion while it cuts the held-out error significantly, and says
    "no effect needed" or "structured residual not explained by any known effect" when that is
    the answer. The report leads with the held-out error before and after.
    """
    started = time.perf_counter()
    held_out = _fraction(test_fraction, "--test-fraction")
    settings = LoopSettings(
        min_improvement=_fraction(min_improvement, "--min-improvement"),
        max_effects=max_effects,
    )
    registry = get_registry()
    base = registry.get("predictor", model_name)  # the error lists the installed models
    library = registry.calibration_effects
    names = list(effects) or list(library)
    unknown = sorted((set(names) | set(excluded)) - set(library))
    if unknown:
        raise CalibrateUsageError(
            f"unknown effect(s) {', '.join(unknown)}; installed: {', '.join(library) or 'none'}"
        )
    candidates = [library[name] for name in names if name not in set(excluded)]

    known = {p.name: p for p in base.parameters}
    start: dict[str, float] = {}
    for text in params:
        name, value = split_assignment(text, "--param")
        if name not in known:
            raise CalibrateUsageError(
                f"--param {text!r}: {model_name} has no parameter {name!r}; parameters: "
                f"{', '.join(known)}"
            )
        start[name] = quantity(value, known[name].unit, f"--param {name}")
    base = base.with_params(**start)
    free = None
    if free_text is not None:
        free = [name.strip() for name in free_text.split(",") if name.strip()]
        wrong = sorted(set(free) - set(known))
        if wrong or not free:
            raise CalibrateUsageError(
                f"--free {free_text!r}: unknown parameter(s) {', '.join(wrong) or '(none given)'}"
                f"; parameters of {model_name}: {', '.join(known)}"
            )

    def say(text: str) -> None:
        if not quiet:
            click.echo(f"[{time.perf_counter() - started:6.1f} s] {text}", err=True)

    paths = recording_paths(data)
    measurements = []
    for path in paths:
        measurement = read_measurement(path)
        measurement.conditions.setdefault("_source", str(path))
        measurements.append(measurement)
    say(f"read {len(paths)} recording(s), {sum(len(m) for m in measurements)} samples")
    prepared = prepare(
        measurements,
        split=split,
        test_fraction=held_out,
        seed=seed,
        rezero=not no_rezero,
    )
    result = calibrate(prepared, base, candidates, free=free, settings=settings, progress=say)
    say("writing the report")
    files = write_report(result, output, figures=not no_figures)
    click.echo(result.summary)
    for name in result.effects_added:
        fitted = ", ".join(
            f"{short} = {value:.4g} ± {sigma:.2g} {unit}".rstrip()
            for short, (value, sigma, unit) in result.effect_parameters(name).items()
        )
        click.echo(f"  {name}: {fitted}")
    click.echo(
        f"report: {files.markdown}  (also {files.json.name}, {files.profile.name}"
        f"{', ' + ', '.join(p.name for p in files.figures) if files.figures else ''})"
    )
    if strict and result.verdict == NOT_EXPLAINED:
        sys.exit(2)


COMMANDS = [calibrate_command]
