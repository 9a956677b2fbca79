"""``hcard calibrate population``: many recordings labelled by participant (session, device)
to one model with per-participant parameters and their population (spec/calibration.md
section 7, K19-K25).

    hcard calibrate population recordings/ -o population/ --model dimensionless-group
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from hcard.calibration.population.grouping import GROUPINGS
from hcard.cli.executor_options import executor_options, options_of
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.search_options import search_options
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.plugins.registry import get_registry


@click.command("population")
@verbosity_options
@click.argument("data", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--map", "maps", multiple=True, metavar="[GLOB=]RIG.json",
              help="Read lab files (.mat, HDF5, CSV/TSV) through this column map "
              "(spec/lab-recordings.md); repeat with GLOB= for a study on several rigs, the "
              "first pattern that matches a file's path choosing its map.")
@click.option("--by", type=click.Choice(GROUPINGS), default="participant", show_default=True,
              help="Sidecar label the recordings are grouped by (session: session.label).")
@click.option("--model", "-m", "model_name", help="Calibrate this bare predictor.")
@click.option("--profile", "profile_path", type=INPUT_FILE,
              help="Calibrate this device profile (default: the one the recordings name).")
@click.option("--finger", "finger_name", default="finger-friction", show_default=True,
              metavar="MODEL", help="With a device profile: the bare finger's friction model.")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Candidate effect (repeatable); default: every installed effect.")
@click.option("--exclude", "excluded", multiple=True, metavar="NAME",
              help="Leave this effect out of the candidates (repeatable).")
@click.option("--free", "free_text", metavar="P1,P2", help="Base parameters to fit.")
@search_options("the population")
@click.option("--output", "-o", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Directory for population.md, population.json, forest.png.")
@click.option("--no-figures", is_flag=True, help="Skip the forest plot.")
@click.option("--json", "as_json", is_flag=True, help="Print population.json to stdout.")
@executor_options
def population_command(data: tuple[Path, ...], maps: tuple[str, ...], by: str,
                       model_name: str | None,
                       profile_path: Path | None, finger_name: str, effects: tuple[str, ...],
                       excluded: tuple[str, ...], free_text: str | None, split: str,
                       test_fraction: str, seed: int, min_improvement: str, max_effects: int,
                       output: Path, no_figures: bool, as_json: bool, scheduler: str | None,
                       workers: int | None) -> None:
    """Fit every participant's recordings alone and pool the parameters into a population.

    Two-stage mixed effects: each participant (sidecar `participant`, or --by) is fitted on
    its own training strokes; each parameter's estimates are pooled by a normal random-effects
    model (REML mean and spread, Knapp-Hartung and Q-profile 95 % intervals, shrunken
    per-participant estimates). Effects are chosen for the population by the summed held-out
    criterion; a participant whose own decision differs is flagged. Each participant is also
    predicted as one never seen, with the population mean of the others.

    Every participant's fits are tasks on a local Dask cluster (--workers), on the cluster of
    --scheduler ADDRESS, or in this process (--workers 0); each task reads its own
    participant's recordings, and the result is the same wherever it ran.

    \b
    Examples:
      hcard calibrate population recordings/ -o population/ --model dimensionless-group
      hcard calibrate population a.csv b.csv c.csv -o pop/ --by session --effect load-index
      hcard calibrate population study/ -o pop/ -m dimensionless-group --scheduler tcp://h:8786
      hcard calibrate population rig1/ rig2/ -o pop/ -m dimensionless-group \
          --map 'rig1/*=rig1.json' --map 'rig2/*=rig2.json'
    """
    # the CLI helpers of `hcard calibrate run` are imported here: calibrate_cmd imports this
    # module to attach the command to its group
    from hcard.calibration.lab.rigs import RigMaps
    from hcard.calibration.population.grouping import group_recordings, without_samples
    from hcard.calibration.population.population_fit import fit_population
    from hcard.calibration.population.report import population_document, write_population_report
    from hcard.cli.calibrate_cmd import (
        CalibrateUsageError,
        _base_of,
        _fraction,
        _free_parameters,
        recording_paths,
    )
    from hcard.executor import Executor

    started = time.perf_counter()
    held_out = _fraction(test_fraction, "--test-fraction")
    improvement = _fraction(min_improvement, "--min-improvement")
    library = get_registry().calibration_effects
    names = list(effects) or list(library)
    unknown = sorted((set(names) | set(excluded)) - set(library))
    if unknown:
        raise CalibrateUsageError(
            f"unknown effect(s) {', '.join(unknown)}; installed: {', '.join(library) or 'none'}")
    candidates = [library[name] for name in names if name not in set(excluded)]

    def say(text: str) -> None:
        if not quiet():
            click.echo(f"[{time.perf_counter() - started:6.1f} s] {text}", err=True)

    rigs = RigMaps.parse(maps)
    recordings = [rigs.file(path) for path in recording_paths(data, lab=bool(rigs))]
    # one recording in memory at a time: its labels and conditions are kept, not its samples
    measurements = [without_samples(recording.read()) for recording in recordings]
    groups = group_recordings(measurements, by)
    base, _, _ = _base_of(measurements, model_name, profile_path, finger_name)
    say(f"read {len(measurements)} recording(s) of {len(groups)} {by}s; base {base.name}")
    # the tasks get file names (and maps) and read their participant's recordings where they
    # run
    where = {id(m): recording for m, recording in zip(measurements, recordings, strict=True)}
    files = {label: [where[id(m)] for m in ms] for label, ms in groups.items()}
    del measurements, groups
    options = options_of(scheduler, workers)
    say(f"fitting {options.describe()}")
    with Executor(options) as executor:
        result = fit_population(files, base, candidates,
                                free=_free_parameters(base, free_text), split=split,
                                test_fraction=held_out, seed=seed,
                                min_improvement=improvement, max_effects=max_effects, by=by,
                                progress=say, executor=executor)
    report = write_population_report(result, output, figures=not no_figures)
    for part in result.failed:
        click.echo(f"warning: {by} {part.label} left out: {part.error}", err=True)
    if as_json:
        click.echo(json.dumps(population_document(result), indent=2, allow_nan=False))
        return
    for name, pop in result.population.items():
        click.echo(f"{name}: mu {pop.mu:.4g} [{pop.mu_interval[0]:.4g}, "
                   f"{pop.mu_interval[1]:.4g}], tau {pop.tau:.4g} [{pop.tau_interval[0]:.4g}, "
                   f"{pop.tau_interval[1]:.4g}] over {pop.k} {by}s")
    click.echo(f"effects: {', '.join(result.effects) or 'none'}; held-out error "
               f"{result.mean_error('held_out_rmse'):.4g} {result.unit} own fit, "
               f"{result.mean_error('never_seen_rmse'):.4g} {result.unit} never seen")
    flagged = [p for p in result.fitted if p.flags]
    for part in flagged:
        click.echo(f"  {part.label}: " + "; ".join(f"{why} {effect}"
                                                  for effect, why in part.flags.items()))
    click.echo(f"report: {report.markdown}  (also {report.json.name}"
               f"{', ' + ', '.join(p.name for p in report.figures) if report.figures else ''})")
