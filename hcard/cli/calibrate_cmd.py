"""``hcard calibrate``: the calibration protocol, and the loop that fits a device's model to
recordings, finds the effects it lacks, and verifies the fitted profile on the device.

    hcard calibrate plan --device ev -o plan/          # protocol + verification cards and tracks
    hcard play plan/protocol.hcard --track plan/protocol.csv --device URI -o rec.csv
    hcard calibrate rec.csv -o calib/ --verify URI     # fit, report, play held-out textures

DATA are measurement CSV files (each with its ``.json`` sidecar, spec/measurement-format.md)
or directories of them; ``hcard play`` writes such recordings. The base model is the device
profile the recordings name (sidecar ``profile``), a profile file (``--profile``) or a bare
predictor (``--model``). The loop (:mod:`hcard.calibration.loop`) prints one line per fit; the
report (Markdown, JSON, PNG figures) and the fitted device profile go to the output directory.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import click

from hcard.calibration.lab.column_map import ColumnMap, read_column_map
from hcard.calibration.lab.detect import LAB_SUFFIXES
from hcard.calibration.lab.propose import propose
from hcard.calibration.lab.reading import open_lab_file, read_recording
from hcard.calibration.measurement import Measurement, MeasurementError
from hcard.calibration.plan import (
    DEFAULT_DURATION_S,
    DEFAULT_VERIFY_DURATION_S,
    DEVICE_CLASSES,
    Plan,
    protocol,
    verification,
)
from hcard.cli.errors import EXIT_FAILED, UserErrorGroup, option_values
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.options import plugin_option, quantity_option
from hcard.cli.search_options import search_options
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.errors import HcardError, UsageError
from hcard.file_errors import writing
from hcard.physics import Predictor, PredictorError
from hcard.physics.profile import DeviceProfile
from hcard.physics.sweep import split_assignment
from hcard.plugins.registry import get_registry


class CalibrateUsageError(UsageError):
    """Options of ``hcard calibrate`` that do not fit together."""


def recording_paths(data: tuple[Path, ...], lab: bool = False) -> list[Path]:
    """The recordings named by DATA: files as given, directories by their ``*.csv`` (sorted),
    or with a column map (``lab``) by every suffix of a lab file (spec/lab-recordings.md LR9,
    :data:`~hcard.calibration.lab.detect.LAB_SUFFIXES`)."""
    paths: list[Path] = []
    suffixes = LAB_SUFFIXES if lab else (".csv",)
    for item in data:
        if item.is_dir():
            found = sorted(p for p in item.iterdir()
                           if p.is_file() and p.suffix.lower() in suffixes)
            if not found:
                raise MeasurementError(f"{item}: no {'/'.join(suffixes)} recordings in this "
                                       "directory")
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


def _contact_threshold(text: str | None) -> float | None:
    """``--contact-threshold`` in N (``"15mN"`` -> 0.015), or None for the per-recording
    default; checked before any recording is read."""
    if text is None:
        return None
    value = quantity_option(text, "N", "--contact-threshold")
    if not math.isfinite(value) or value <= 0.0:
        raise CalibrateUsageError(f"--contact-threshold {text!r}: must be a positive force")
    return value


class DefaultCommandGroup(UserErrorGroup):
    """A group whose first argument, when it names no subcommand, goes to its default
    subcommand: ``hcard calibrate rec.csv`` is ``hcard calibrate run rec.csv``."""

    default_command = "run"

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ctx.help_option_names:
            args = [self.default_command, *args]
        return super().parse_args(ctx, args)


@click.group("calibrate", cls=DefaultCommandGroup)
@verbosity_options
def calibrate_group() -> None:
    """Fit a model to recordings, find what it lacks, verify it.

    \b
    hcard calibrate plan --device uv|ev|coupled -o DIR   the protocol (card + track) and the
                                                           held-out verification textures
    hcard calibrate [run] RECORDINGS... [-o DIR] [--verify URI]
                                                           the loop; `run` may be left out

    \b
    Examples:
      hcard calibrate plan --device ev -o plan/
      hcard calibrate rec.csv -o calib/
      hcard calibrate rec.csv -o calib/ --verify usbip://127.0.0.1:3240/1-1
    """


# -- map ---------------------------------------------------------------------------------------
@calibrate_group.command("map")
@verbosity_options
@click.argument("file", type=INPUT_FILE)
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the proposed map here (default: print it).")
def map_command(file: Path, output: Path | None) -> None:
    """Propose a column map for the lab file FILE (.mat, HDF5, CSV/TSV).

    Prints, on standard error, what it could not decide (e.g. "channel ai3: unknown
    quantity, set quantity"); edit the map, then calibrate with it (spec/lab-recordings.md).

    \b
    Examples:
      hcard calibrate map rig1/p03_trial1.mat -o rig1.json
      hcard calibrate --map rig1.json rig1/ -o calib/
    """
    lab = open_lab_file(file)
    try:
        proposal = propose(lab)
    finally:
        lab.close()
    text = json.dumps(proposal.column_map, indent=2) + "\n"
    if output is None:
        click.echo(text, nl=False)
    else:
        with writing(output, MeasurementError):
            output.write_text(text, encoding="utf-8")
        click.echo(f"wrote {output}", err=True)
    if proposal.sample_rate_hz is not None:
        click.echo(f"sample rate from the time variable: {proposal.sample_rate_hz:.6g} Hz",
                   err=True)
    for line in proposal.undecided:
        click.echo(f"undecided: {line}", err=True)


# -- plan ---------------------------------------------------------------------------------------
PROTOCOL_CARD, PROTOCOL_TRACK = "protocol.hcard", "protocol.csv"
VERIFY_CARD, VERIFY_TRACK = "verify.hcard", "verify.csv"
PLAN_JSON = "plan.json"


def write_plan(directory: Path, device: str, plan: Plan, check: Plan) -> list[Path]:
    """Write the protocol and verification cards and tracks and ``plan.json`` into
    ``directory`` (each file atomically); the paths written."""
    from hcard.atomic import write_atomically
    from hcard.card_io import save
    from hcard.track import track_to_csv

    with writing(directory, HcardError, "create"):
        directory.mkdir(parents=True, exist_ok=True)
    written = []
    for card_name, track_name, part in ((PROTOCOL_CARD, PROTOCOL_TRACK, plan),
                                        (VERIFY_CARD, VERIFY_TRACK, check)):
        save(part.card, directory / card_name)
        write_atomically(directory / track_name, track_to_csv(part.track).encode())
        written += [directory / card_name, directory / track_name]
    description = {
        "device": device,
        "protocol": {"card": PROTOCOL_CARD, "track": PROTOCOL_TRACK, "lanes": list(plan.lanes),
                     "duration_s": float(plan.track.t[-1] - plan.track.t[0]),
                     "sessions": [{"lane": lane, "force_n": force, "speeds_mm_s": list(speeds)}
                                  for lane, force, speeds in plan.sessions]},
        "verification": {"card": VERIFY_CARD, "track": VERIFY_TRACK, "lanes": list(check.lanes),
                         "duration_s": float(check.track.t[-1] - check.track.t[0]),
                         "sessions": [{"lane": lane, "force_n": force,
                                       "speeds_mm_s": list(speeds)}
                                      for lane, force, speeds in check.sessions]},
        "spec": "spec/calibration.md section 6",
    }
    write_atomically(directory / PLAN_JSON, (json.dumps(description, indent=2) + "\n").encode())
    return [*written, directory / PLAN_JSON]


@calibrate_group.command("plan")
@verbosity_options
@click.option("--device", "device", type=click.Choice(DEVICE_CLASSES), required=True,
              help="What the device renders: uv (E-ViTa), ev (the coupled stimulator with its "
                   "plate off) or coupled (both).")
@click.option("-o", "--output", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Directory for the cards, tracks and plan.json.")
@click.option("--duration", default=f"{DEFAULT_DURATION_S:g}s", show_default=True,
              help="Length of the protocol track (the last session plays to its end).")
@click.option("--verify-duration", default=f"{DEFAULT_VERIFY_DURATION_S:g}s",
              show_default=True, help="Length of the verification track.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the order of forces and speeds.")
@click.option("--separate", "separate", metavar="A,B",
              help="Instead: the experiment that separates effects A and B where a calibration "
                   "could not (separate.hcard, separate.csv, design.json); --duration then "
                   "overrides the designed length.")
@click.option("--from", "from_dir", type=click.Path(file_okay=False, path_type=Path),
              metavar="CALIB_DIR",
              help="--separate: design from this calibration's output (its profile.json and "
                   "report.json: fitted values, noise) instead of the device class's profile.")
def plan_command(device: str, output: Path, duration: str, verify_duration: str,
                 seed: int, separate: str | None, from_dir: Path | None) -> None:
    """Write the calibration protocol for a device class, and the held-out verification.

    The protocol card holds lanes of target levels (an amplitude staircase, UV steps, a voltage
    staircase and square wave, bipolar steps, by device class); its track strokes each lane
    there and back at several speeds and normal forces, with lifts and rests between (the
    thesis's protocols, chapters 2-4). Play it with `hcard play`, calibrate the recording, and
    verify the profile on the held-out textures (other levels, forces and speeds) with
    `hcard calibrate ... --verify URI` (spec/calibration.md section 6).

    \b
    Examples:
      hcard calibrate plan --device uv -o plan/
      hcard calibrate plan --device coupled -o plan/ --duration 2min --seed 3
      hcard calibrate plan --device coupled --separate air-layer,finger-geometry \
          --from calib/ -o separate/
    """
    if separate is not None:
        given = None
        source = click.get_current_context().get_parameter_source("duration")
        if source is not click.core.ParameterSource.DEFAULT:
            given = quantity_option(duration, "s", "--duration")
        written, lines = plan_separation(separate, device, output, from_dir, given, seed)
        for path in written:
            click.echo(str(path))
        for line in lines:
            click.echo(line)
        click.echo(f"next: hcard play {output / SEPARATE_CARD} --track "
                   f"{output / SEPARATE_TRACK} --device URI -o separate.csv, then calibrate "
                   "it with the first recordings")
        return
    if from_dir is not None:
        raise CalibrateUsageError("--from designs a separating experiment; give --separate A,B")
    seconds = quantity_option(duration, "s", "--duration")
    verify_seconds = quantity_option(verify_duration, "s", "--verify-duration")
    plan = protocol(device, duration_s=seconds, seed=seed)
    check = verification(device, duration_s=verify_seconds, seed=seed + 1)
    for path in write_plan(output, device, plan, check):
        click.echo(str(path))
    click.echo(f"protocol: {len(plan.sessions)} sessions over lanes {', '.join(plan.lanes)}, "
               f"{plan.track.t[-1]:.1f} s; verification: {len(check.sessions)} sessions, "
               f"{check.track.t[-1]:.1f} s")
    click.echo(f"next: hcard play {output / PROTOCOL_CARD} --track {output / PROTOCOL_TRACK} "
               f"--device URI -o rec.csv")


SEPARATE_CARD, SEPARATE_TRACK, DESIGN_JSON = "separate.hcard", "separate.csv", "design.json"


def plan_separation(pair_text: str, device: str, output: Path, from_dir: Path | None,
                    duration_s: float | None, seed: int, *, max_duration_s: float | None = None
                    ) -> tuple[list[Path], list[str]]:
    """Design the experiment separating the effects ``pair_text`` (``"A,B"``) on ``device``,
    from a calibration folder or the class's profile, and write its card, track and
    ``design.json`` into ``output``; the paths written and the design in a few lines. A design
    longer than ``max_duration_s`` (s) is made that long instead, and the lines say so."""
    from hcard.calibration.separation import design, separating_plan
    from hcard.calibration.separation_inputs import (
        check_device,
        effect_pair,
        from_class,
        from_folder,
    )

    a, b = effect_pair(pair_text)
    if from_dir is not None:
        pair, noise = from_folder(from_dir, a, b)
        check_device(device, pair)
    else:
        pair, noise = from_class(device, a, b)
    found = design(pair, noise, duration_s=duration_s)
    shortened: list[str] = []
    if max_duration_s is not None and found.duration_s > max_duration_s:
        shortened = [f"shortened to {max_duration_s:.0f} s (--settle-time) from the "
                     f"{found.duration_s:.0f} s it needs"]
        found = design(pair, noise, duration_s=max_duration_s)
    plan = separating_plan(found, seed=seed)
    return write_separation(output, device, found, plan), [*found.describe(), *shortened]


def write_separation(directory: Path, device: str, found: Any, plan: Plan) -> list[Path]:
    """Write a separating experiment's card, track and ``design.json`` (with the sessions)."""
    from hcard.atomic import write_atomically
    from hcard.card_io import save
    from hcard.track import track_to_csv

    with writing(directory, HcardError, "create"):
        directory.mkdir(parents=True, exist_ok=True)
    save(plan.card, directory / SEPARATE_CARD)
    write_atomically(directory / SEPARATE_TRACK, track_to_csv(plan.track).encode())
    description = {
        **found.to_dict(),
        "device": device,
        "card": SEPARATE_CARD,
        "track": SEPARATE_TRACK,
        "lanes": list(plan.lanes),
        "track_duration_s": float(plan.track.t[-1] - plan.track.t[0]),
        "sessions": [{"lane": lane, "force_n": force, "speeds_mm_s": list(speeds)}
                     for lane, force, speeds in plan.sessions],
    }
    write_atomically(directory / DESIGN_JSON,
                     (json.dumps(description, indent=2) + "\n").encode())
    return [directory / SEPARATE_CARD, directory / SEPARATE_TRACK, directory / DESIGN_JSON]


# -- the loop -----------------------------------------------------------------------------------
def _base_of(measurements: list[Measurement], model_name: str | None,
             profile_path: Path | None, finger_name: str = "finger-friction"
             ) -> tuple[Predictor, DeviceProfile | None, str]:
    """The base to calibrate: a bare predictor (``--model``), a profile file (``--profile``),
    or the profile the recordings name in their sidecars, with the finger model
    ``finger_name`` (``"none"``: a constant friction coefficient); and the voltage form of the
    data."""
    from hcard.calibration.device_model import profile_model

    forms = {m.voltage_form for m in measurements}
    if len(forms) > 1:
        raise MeasurementError("recordings differ in their voltage_form (envelope and "
                               "instantaneous); calibrate them apart")
    form = forms.pop()
    if model_name is not None and profile_path is not None:
        raise CalibrateUsageError("give --model or --profile, not both")
    if model_name is not None:
        return plugin_option("predictor", model_name, "--model"), None, form
    if profile_path is not None:
        profile = DeviceProfile.load(profile_path)
    else:
        contents = [m.conditions.get("profile", {}) or {} for m in measurements]
        named = [c.get("content") for c in contents]
        if not all(isinstance(c, dict) for c in named):
            raise CalibrateUsageError(
                "the recordings name no device profile (sidecar 'profile.content'); give "
                "--model NAME (a predictor) or --profile FILE (a device profile)")
        if any(c != named[0] for c in named[1:]):
            raise CalibrateUsageError(
                "the recordings were made with different device profiles; calibrate them "
                "apart, or give --profile")
        source = measurements[0].source or "recording"
        profile = DeviceProfile.from_dict(named[0], source=f"{source}.json: profile.content")
    finger = None if finger_name == "none" else plugin_option("predictor", finger_name,
                                                              "--finger")
    return profile_model(profile, envelope=form == "envelope", finger=finger), profile, form


def _verification_files(measurements: list[Measurement], card: Path | None,
                        track: Path | None) -> tuple[Path, Path]:
    """The held-out card and track: as given, else ``verify.hcard``/``verify.csv`` next to the
    card the recordings played (sidecar ``card.path``, resolved against the sidecar's folder
    and inside it: spec/measurement-format.md MF13)."""
    if card is not None and track is not None:
        return card, track
    played = measurements[0].files.get("card.path")
    if played is not None:
        folder = played.parent
        card = card or folder / VERIFY_CARD
        track = track or folder / VERIFY_TRACK
        if card.exists() and track.exists():
            return card, track
    raise CalibrateUsageError(
        "--verify needs the held-out card and track: give --verify-card and --verify-track "
        "(hcard calibrate plan writes verify.hcard and verify.csv)")


@calibrate_group.command("run")
@verbosity_options
@click.argument("data", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--map", "map_path", type=INPUT_FILE, metavar="RIG.json",
              help="Read DATA (.mat, HDF5, CSV/TSV with the lab's column names) through this "
                   "column map (spec/lab-recordings.md).")
@click.option("--model", "-m", "model_name",
              help="Calibrate this bare predictor (see `hcard predict --list`) instead of the "
                   "recordings' device profile.")
@click.option("--profile", "profile_path", type=INPUT_FILE,
              help="Calibrate this device profile (default: the one the recordings' sidecars "
                   "name).")
@click.option("--finger", "finger_name", default="finger-friction", show_default=True,
              metavar="MODEL",
              help="With a device profile: the bare finger's friction model that the relative "
                   "friction multiplies (fitted with it); 'none': a constant coefficient.")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Candidate effect (repeatable); default: every installed calibration effect.")
@click.option("--exclude", "excluded", multiple=True, metavar="NAME",
              help="Leave this effect out of the candidates (repeatable).")
@click.option("--free", "free_text", metavar="P1,P2",
              help="Base parameters to fit (default: the model's calibrated parameters).")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="Start or fixed value of a base parameter, with unit (repeatable).")
@search_options("the model")
@click.option("--output", "-o", type=click.Path(file_okay=False, path_type=Path),
              default=Path("calibration"), show_default=True,
              help="Directory for report.md, report.json, profile.json and the figures.")
@click.option("--verify", "verify_uri", metavar="URI",
              help="Play the held-out textures on this device without and with the fitted "
                   "profile and report the rendered friction error of each.")
@click.option("--verify-card", type=INPUT_FILE,
              help="Held-out card for --verify (default: verify.hcard next to the played card).")
@click.option("--verify-track", type=INPUT_FILE,
              help="Its finger track (default: verify.csv next to it).")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.001),
              help="--verify: longest wait for any answer from the device, s.")
@click.option("--no-figures", is_flag=True, help="Skip the PNG figures.")
@click.option("--no-rezero", is_flag=True,
              help="Do not re-measure the lateral-force zero at each lift (spec/calibration.md "
                   "K4).")
@click.option("--contact-threshold", "contact_threshold", metavar="FORCE",
              help="Normal force at and above which the finger touches, e.g. 15mN (default: "
                   "per recording, the larger of 10 mN and 5 standard deviations of the lifted "
                   "normal-force noise).")
@click.option("--bootstrap", "bootstrap", default=50, show_default=True,
              type=click.IntRange(min=0),
              help="Stroke-block bootstrap refits for the final model's uncertainties (0: the "
                   "fit's Jacobian uncertainties only).")
@click.option("--settle", is_flag=True,
              help="When the verdict is ambiguous between two effects: design the experiment "
                   "that separates them, play it on the --verify device, calibrate all "
                   "recordings together and report the settled verdict (spec/calibration.md "
                   "K34).")
@click.option("--settle-time", "settle_time", default="120s", show_default=True,
              metavar="DURATION",
              help="Most recording time the separating experiments of --settle may take "
                   "together, e.g. 90s or 5min (an experiment that needs more is played "
                   "shortened and says so).")
@click.option("--strict", is_flag=True,
              help="Exit with status 1 (a failed check) when structure is left that no effect "
                   "explains.")
def calibrate_command(
    data: tuple[Path, ...],
    map_path: Path | None,
    model_name: str | None,
    profile_path: Path | None,
    finger_name: str,
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
    verify_uri: str | None,
    verify_card: Path | None,
    verify_track: Path | None,
    timeout: float,
    no_figures: bool,
    no_rezero: bool,
    contact_threshold: str | None,
    bootstrap: int,
    strict: bool,
    settle: bool,
    settle_time: str,
) -> None:
    """Fit the device's model to the recordings DATA, add the effects it lacks, report.

    The loop fits the base model on the training strokes, tries each candidate effect, keeps
    the one with the best held-out criterion while it cuts the held-out error significantly,
    and says "no effect needed" or "structured residual not explained by any known effect"
    when that is the answer. The report leads with the held-out model error before and after;
    with --verify it also gives the friction the device rendered on held-out textures without
    and with the fitted profile, measured by its force sensor.

    \b
    Examples:
      hcard calibrate run rec.csv -o calib/
      hcard calibrate run recordings/ --model ev-kaczmarek --effect air-layer -o calib/
      hcard calibrate run rec.csv --profile profile.json --test-fraction 30% --strict
    """
    # imported here: the loop, its filters (scipy.signal, scipy.stats) and the report
    # (matplotlib) cost about a second, which every other hcard command need not pay
    from hcard.calibration.dataset import prepare
    from hcard.calibration.loop import calibrate, with_bootstrap
    from hcard.calibration.profile import profile_of
    from hcard.calibration.report.writer import write_report
    from hcard.calibration.results import NOT_EXPLAINED, LoopSettings

    started = time.perf_counter()
    if bootstrap == 1:
        raise CalibrateUsageError("--bootstrap needs at least 2 refits (0: none)")
    held_out = _fraction(test_fraction, "--test-fraction")
    threshold_n = _contact_threshold(contact_threshold)
    budget_s = _settle_budget(settle_time)
    settings = LoopSettings(
        min_improvement=_fraction(min_improvement, "--min-improvement"),
        max_effects=max_effects,
    )
    registry = get_registry()
    library = registry.calibration_effects
    names = list(effects) or list(library)
    unknown = sorted((set(names) | set(excluded)) - set(library))
    if unknown:
        raise CalibrateUsageError(
            f"unknown effect(s) {', '.join(unknown)}; installed: {', '.join(library) or 'none'}"
        )
    if model_name is not None:
        plugin_option("predictor", model_name, "--model")  # the error lists the models
    if finger_name != "none":
        plugin_option("predictor", finger_name, "--finger")
    if profile_path is not None and model_name is not None:
        raise CalibrateUsageError("give --model or --profile, not both")
    if verify_uri is not None and model_name is not None:
        raise CalibrateUsageError("--verify plays a device profile; it needs the recordings' "
                                  "profile or --profile, not --model")
    candidates = [library[name] for name in names if name not in set(excluded)]

    def say(text: str) -> None:
        if not quiet():
            click.echo(f"[{time.perf_counter() - started:6.1f} s] {text}", err=True)

    column_map: ColumnMap | None = read_column_map(map_path) if map_path else None
    paths = recording_paths(data, lab=column_map is not None)
    measurements = [read_recording(path, column_map) for path in paths]
    base, base_profile, voltage_form = _base_of(measurements, model_name, profile_path,
                                                finger_name)
    if verify_uri is not None:
        verify_files = _verification_files(measurements, verify_card, verify_track)
    if base_profile is None and voltage_form == "envelope":
        click.echo(f"warning: the recordings' voltage is a carrier's envelope; {base.name} "
                   "takes it as an instantaneous voltage (the device's own profile, the default "
                   "base, averages over the carrier)", err=True)
    base = _with_start(base, params)
    free = _free_parameters(base, free_text)
    say(f"read {len(paths)} recording(s), {sum(len(m) for m in measurements)} samples; base "
        f"{'profile ' + base_profile.name if base_profile else 'model ' + base.name}")
    prepared = prepare(measurements, split=split, test_fraction=held_out, seed=seed,
                       rezero=not no_rezero,
                       contact_threshold_n=threshold_n)
    for text in prepared.warnings:
        click.echo(f"warning: {text}", err=True)
    result = calibrate(prepared, base, candidates, free=free, settings=settings, progress=say)
    separation: dict[str, Any] | None = None
    if settle and verify_uri is None:
        raise CalibrateUsageError("--settle plays the separating experiment on the --verify "
                                  "device; give --verify URI")
    experiments: list[dict[str, Any]] = []
    recorded = len(measurements)
    while (settle and _ambiguous_pair(result) is not None
           and len(experiments) < MAX_SEPARATING_EXPERIMENTS
           and budget_s >= MIN_SEPARATING_S):
        extra, done = _settle(result, base_profile, voltage_form, output, verify_uri or "",
                              timeout, seed, say, len(experiments) + 1, budget_s)
        budget_s -= done["duration_s"]
        measurements = [*measurements, extra]
        prepared = prepare(measurements, split=split, test_fraction=held_out, seed=seed,
                           rezero=not no_rezero, contact_threshold_n=threshold_n)
        say("calibrating all recordings together; the runner-up judged on the separating "
            "recordings (K34)")
        result = calibrate(prepared, base, candidates, free=free, settings=settings,
                           progress=say, separating=prepared.recording >= recorded)
        done["after"] = _comparison_figures(result)
        experiments.append(done)
    if experiments:
        separation = {**experiments[0], "after": experiments[-1]["after"],
                      "experiments": experiments}
    if bootstrap >= 2:
        say(f"stroke-block bootstrap of the final model: {bootstrap} refits")
        result = with_bootstrap(result, bootstrap, seed=seed, progress=say)
    profile = profile_of(result, base_profile, voltage_form=voltage_form)
    rendering: dict[str, Any] | None = None
    if verify_uri is not None:
        say(f"verifying on {verify_uri}: held-out textures without and with the fitted profile")
        verified = _verify(verify_uri, verify_files, profile, timeout, output)
        rendering = verified.to_dict()
        profile = profile.replace(calibration={**(profile.calibration or {}),
                                               "rendering": rendering})
    say("writing the report")
    files = write_report(result, output, figures=not no_figures, profile=profile,
                         rendering=rendering)
    if separation is not None:
        _record_separation(files.json, separation)
    click.echo(result.summary)
    if separation is not None:
        b, a = separation["before"], separation["after"]
        click.echo(f"separating experiment ({separation['recording']}): before, {b['text']}; "
                   f"after, {a['text']}")
    elif _ambiguous_pair(result) is not None:
        first, second = _ambiguous_pair(result) or ("", "")
        click.echo(f"to separate them: hcard calibrate plan --device coupled --separate "
                   f"{first},{second} --from {output} -o separate/ (or run again with --settle "
                   "--verify URI)")
    for name in result.effects_added:
        fitted = ", ".join(
            f"{short} = {value:.4g} ± {sigma:.2g} {unit}".rstrip()
            for short, (value, sigma, unit) in result.effect_parameters(name).items()
        )
        click.echo(f"  {name}: {fitted}")
    click.echo(f"held-out model error: {_error(result.before.test_rmse, result.unit)} before, "
               f"{_error(result.after.test_rmse, result.unit)} after")
    if rendering is not None:
        click.echo(f"rendered friction error on held-out textures: {rendering['text']}")
    click.echo(
        f"report: {files.markdown}  (also {files.json.name}, {files.profile.name}"
        f"{', ' + ', '.join(p.name for p in files.figures) if files.figures else ''})"
    )
    if strict and result.verdict == NOT_EXPLAINED:
        sys.exit(EXIT_FAILED)


def _ambiguous_pair(result: Any) -> tuple[str, str] | None:
    """The two single effects an ambiguous verdict lies between, else None."""
    from hcard.calibration.results import AMBIGUOUS

    runner = result.comparison
    if result.verdict != AMBIGUOUS or runner is None:
        return None
    if len(runner.chosen) != 1 or len(runner.runner_up) != 1:
        return None
    return runner.chosen[0], runner.runner_up[0]


def _comparison_figures(result: Any) -> dict[str, Any]:
    runner = result.comparison
    figures: dict[str, Any] = {"verdict": result.verdict,
                               "effects": list(result.effects_added)}
    if runner is not None:
        figures.update(runner_up=list(runner.runner_up),
                       criterion_margin=runner.criterion_margin,
                       rmse_margin=runner.rmse_margin, ambiguous=runner.ambiguous)
    chosen = " + ".join(result.effects_added) or "base model"
    figures["text"] = (f"{chosen} ({result.verdict}"
                       + (f"; runner-up {' + '.join(runner.runner_up)}: held-out criterion "
                          f"{runner.criterion_margin:+.1f}, held-out RMSE "
                          f"{100 * runner.rmse_margin:+.1f} %" if runner is not None else "")
                       + ")")
    return figures


MAX_SEPARATING_EXPERIMENTS = 3
"""Separating experiments ``--settle`` plays at most, each designed from the run before it
(whose measured margins make the next one longer where the last one fell short)."""


MIN_SEPARATING_S = 10.0
"""Shortest separating experiment --settle plays, s (the design's own floor)."""


def _settle_budget(text: str) -> float:
    """``--settle-time`` in seconds (> 0), or a usage error naming the option."""
    from hcard.quantities import UnitError, parse_quantity

    try:
        seconds = parse_quantity(text, "s")
    except UnitError as exc:
        raise CalibrateUsageError(f"--settle-time {text!r}: {exc}") from None
    if not (math.isfinite(seconds) and seconds > 0):
        raise CalibrateUsageError(f"--settle-time {text!r}: must be a duration > 0, e.g. 120s")
    return seconds


def _settle(result: Any, base_profile: DeviceProfile | None, voltage_form: str, output: Path,
            uri: str, timeout: float, seed: int, say: Any, number: int, budget_s: float
            ) -> tuple[Measurement, dict[str, Any]]:
    """Design the ``number``-th separating experiment from ``result`` (at most ``budget_s``
    seconds long), play it on ``uri``; the recording and what was done (spec/calibration.md
    K34)."""
    from hcard.calibration.profile import profile_of
    from hcard.calibration.report.writer import write_report
    from hcard.device.record_play import play_and_record

    first, second = _ambiguous_pair(result) or ("", "")
    suffix = "" if number == 1 else f"-{number}"
    folder = output / f"before-separation{suffix}"
    say(f"ambiguous between {first} and {second}: writing this run to {folder}")
    write_report(result, folder, figures=False,
                 profile=profile_of(result, base_profile, voltage_form=voltage_form))
    say("designing the separating experiment")
    device = "coupled"
    written, lines = plan_separation(f"{first},{second}", device, output / f"separate{suffix}",
                                     folder, None, seed, max_duration_s=budget_s)
    for line in lines:
        say(line)
    from hcard.card_io import load
    from hcard.track import read_track_csv

    recording = output / f"separate-recording{suffix}.csv"
    say(f"playing the separating experiment on {uri}")
    play_and_record(uri, load(written[0]), read_track_csv(written[1]), recording,
                    card_path=str(written[0]), track_path=str(written[1]), timeout_s=timeout)
    design_json = json.loads(written[2].read_text(encoding="utf-8"))
    return read_recording(recording, None), {
        "design": f"separate{suffix}/{DESIGN_JSON}",
        "recording": recording.name,
        "before_folder": folder.name,
        "before": _comparison_figures(result),
        "conditions": design_json["conditions"],
        "expected": design_json["expected"],
        "duration_s": design_json["duration_s"],
    }


def _record_separation(report_json: Path, separation: dict[str, Any]) -> None:
    """Add the separating experiment to report.json (``separation``)."""
    from hcard.atomic import write_atomically

    content = json.loads(report_json.read_text(encoding="utf-8"))
    content["separation"] = separation
    write_atomically(report_json, (json.dumps(content, indent=2, allow_nan=False) + "\n")
                     .encode())


def _error(value: float, unit: str) -> str:
    from hcard.calibration.results import format_error

    return format_error(value, unit)


def _with_start(base: Predictor, params: tuple[str, ...]) -> Predictor:
    """``base`` with the ``--param`` start values."""
    known = {p.name: p for p in base.parameters}
    start: dict[str, float] = {}
    for text in params:
        with option_values():
            name, value = split_assignment(text, "--param")
        if name not in known:
            raise CalibrateUsageError(
                f"--param {text!r}: {base.name} has no parameter {name!r}; parameters: "
                f"{', '.join(known)}"
            )
        start[name] = quantity_option(value, known[name].unit, f"--param {name}")
    with option_values(PredictorError):  # a start value outside the parameter's bounds
        return base.with_params(**start)


def _free_parameters(base: Predictor, free_text: str | None) -> list[str] | None:
    """The ``--free`` parameter names, checked (None: the model's calibrated ones)."""
    if free_text is None:
        return None
    known = {p.name for p in base.parameters}
    free = [name.strip() for name in free_text.split(",") if name.strip()]
    wrong = sorted(set(free) - known)
    if wrong or not free:
        raise CalibrateUsageError(
            f"--free {free_text!r}: unknown parameter(s) {', '.join(wrong) or '(none given)'}"
            f"; parameters of {base.name}: {', '.join(sorted(known))}"
        )
    return free


def _verify(uri: str, files: tuple[Path, Path], profile: DeviceProfile, timeout: float,
            output: Path) -> Any:
    """Play the held-out card along its track without and with ``profile``; the recordings
    go to ``output`` as ``verify-before.csv`` and ``verify-after.csv``."""
    from hcard.calibration.measurement import write_measurement
    from hcard.card_io import load
    from hcard.device.verify import verify
    from hcard.track import read_track_csv

    card_path, track_path = files
    card, track = load(card_path), read_track_csv(track_path)
    verified = verify(uri, card, track, profile.to_json(), timeout_s=timeout,
                      track_path=str(track_path), card_path=str(card_path))
    output.mkdir(parents=True, exist_ok=True)
    for name, recorded in zip(("verify-before.csv", "verify-after.csv"), verified.recordings,
                              strict=True):
        write_measurement(recorded, output / name)
    return verified


COMMANDS = [calibrate_group]

from hcard.cli.calibrate_population_cmd import population_command  # noqa: E402

calibrate_group.add_command(population_command)
