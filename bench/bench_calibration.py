"""``hcard calibrate``'s parts on 60,000-sample recordings, each against its baseline or floor,
measured side by side in one run, on one core.

Run: ``python bench/bench_calibration.py [--samples 60000] [--repeat 3] [--quick]``

For each scenario the reference device's tribometer simulation records ``--samples`` samples at
1 kHz (lifts included) with hidden effects, tribometer noise (1.5 mN) and a drifting zero (3 mN),
and the parts of the command are timed (wall seconds, median of ``--repeat``, alternating the
two sides of each comparison):

- **loop**: ``prepare`` + ``calibrate`` with every installed effect as a candidate, screened
  (the default, :mod:`hcard.calibration.screening`) against the baseline: every candidate
  fitted on every training sample (``screen_samples=0``). Goal: the same answers (effects,
  verdict, accepted fit to the bit, runner-up) in less time; the ratio is the speed-up.
- **figures**: ``residuals.png`` and ``fit.png`` of that result, built and encoded. Goal: under
  0.3 s each. Floor: a blank figure of the same pixel size, encoded; baseline: the same figure
  drawn by the report module of commit :data:`BEFORE` (matplotlib's constrained layout and
  automatic ticks), read from the repository's history when there is one.
- **CSV read**: ``read_measurement`` of the recording written by ``write_measurement``, against
  its floor: ``numpy.loadtxt`` of the same rows. The reader once took 0.61 s for 60k
  rows.

``--quick``: the first scenario only. The process is pinned to one CPU and BLAS to one thread.
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_answers import differences

from hcard.calibration.dataset import prepare
from hcard.calibration.loop import calibrate
from hcard.calibration.measurement import (
    Measurement,
    read_measurement,
    write_measurement,
)
from hcard.calibration.report import figures, files
from hcard.calibration.results import CalibrationResult, LoopSettings
from hcard.plugins.registry import get_registry
from hcard_device.sim.tribometer import Protocol, synthesize

SCENARIOS = (
    # (label, device, model, hidden effects)
    (
        "UV plate, speed + occlusion hidden",
        "uv",
        "dimensionless-group",
        {"ultrasonic-speed": {"speed_exponent": -0.6}, "occlusion-drift": {"gain": 0.5}},
    ),
    (
        "coupled UV+EV, leakage + load index hidden",
        "coupled",
        "coupled",
        {"charge-leakage": {"time_constant": 10e-3}, "load-index": {"load_index": 0.8}},
    ),
    ("EV plate, air layer hidden", "ev", "ev-kaczmarek", {"air-layer": {"air_gap": 10e-6}}),
    ("UV plate, clean", "uv", "dimensionless-group", {}),
)

FIGURE_GOAL_S = 0.3
"""The goal for each report figure, s."""
BEFORE = "16b8560"
"""The commit whose report module drew the figures with constrained layout (the baseline)."""


def one_time(work: Callable[[], object]) -> float:
    """Wall time of one call of ``work``, s."""
    tic = time.perf_counter()
    work()
    return time.perf_counter() - tic


def same_answers(screened: CalibrationResult, baseline: CalibrationResult) -> str:
    """``"yes"``, or what differs (:func:`calibration_answers.differences`)."""
    found = differences(baseline, screened)
    return "yes" if not found else "NO: " + ", ".join(found)


def report_before() -> ModuleType | None:
    """The report module (then ``hcard/calibration/report.py``, now the package
    :mod:`hcard.calibration.report`) as it was before its figures were made faster (commit
    :data:`BEFORE`, read from the repository's history), or None without git or history."""
    root = Path(__file__).resolve().parents[1]
    try:
        source = subprocess.run(
            ["git", "-C", str(root), "show", f"{BEFORE}:hcard/calibration/report.py"],
            capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    # it imported the result types from the loop module, which now holds only the search
    source = source.replace("from hcard.calibration.loop import CalibrationResult, ModelFit",
                            "from hcard.calibration.results import CalibrationResult, ModelFit")
    module = ModuleType("report_before")
    sys.modules[module.__name__] = module  # its dataclasses look their module up
    exec(compile(source, f"{BEFORE}:hcard/calibration/report.py", "exec"), module.__dict__)
    return module


def blank_png(size_inches: tuple[float, float]) -> bytes:
    """An empty figure of this size, encoded as the report encodes its figures: what any figure
    costs at least."""
    fig = Figure(figsize=size_inches, dpi=figures.DPI)
    FigureCanvasAgg(fig)
    return figures.figure_png(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=60_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="the first scenario only")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    registry = get_registry()
    library = list(registry.calibration_effects.values())
    protocol = Protocol(
        duration_s=args.samples / 1000.0,
        force_range_n=(0.1, 2.0),
        voltage_range_v=(500.0, 2000.0),
    )
    before = report_before()
    print(f"{len(library)} effects in the library; {args.samples} samples per scenario; 1 CPU; "
          f"median of {args.repeat} (wall s)")
    for label, device, model, hidden in SCENARIOS[:1] if args.quick else SCENARIOS:
        recordings = synthesize(device, hidden, protocol=protocol, lateral_noise_n=1.5e-3,
                                normal_noise_n=1.5e-3, drift_n=3e-3, seed=7)
        base = registry.get("predictor", model)
        print(f"\n{label}")

        results: dict[int, CalibrationResult] = {}
        times: dict[int, list[float]] = {0: [], -1: []}
        for _ in range(args.repeat):
            for samples, key in ((LoopSettings().screen_samples, -1), (0, 0)):
                tic = time.perf_counter()
                data = prepare(recordings)
                results[key] = calibrate(data, base, library,
                                         settings=LoopSettings(screen_samples=samples))
                times[key].append(time.perf_counter() - tic)
        screened, baseline = results[-1], results[0]
        loop, loop_base = statistics.median(times[-1]), statistics.median(times[0])
        fits = sum(c.test_rmse is not None for c in screened.candidates)
        kept = sum(c.screened for c in screened.candidates)
        print(f"  loop         {loop:6.2f} s  baseline (every candidate on every training "
              f"sample) {loop_base:6.2f} s  x{loop_base / loop:4.2f} faster; same answers: "
              f"{same_answers(screened, baseline)}; {kept} of {fits} candidates left "
              f"screened; added {', '.join(screened.effects_added) or 'none'}")

        print_figures(screened, args.repeat, before)
        print_csv_read(recordings[0], loop, args.repeat)


def print_figures(result: CalibrationResult, repeat: int, before: ModuleType | None) -> None:
    """Each report figure of ``result`` (drawn and encoded as ``write_report`` does) against
    the goal, the same figure drawn by the report module ``before``, and the floor."""
    for name in (files.RESIDUALS_PNG, files.FIT_PNG):
        drawer = {files.RESIDUALS_PNG: "residuals_figure", files.FIT_PNG: "fit_figure"}[name]
        now = getattr(figures, drawer)
        size = tuple(now(result).get_size_inches())
        runs: dict[str, list[float]] = {"measured": [], "before": [], "floor": []}
        for _ in range(repeat):  # alternately
            runs["measured"].append(one_time(lambda d=now: figures.figure_png(d(result))))
            if before is not None:
                old = getattr(before, drawer)
                runs["before"].append(one_time(lambda d=old: before._png(d(result))))
            runs["floor"].append(one_time(lambda s=size: blank_png(s)))
        measured = statistics.median(runs["measured"])
        floor = statistics.median(runs["floor"])
        verdict = "met" if measured < FIGURE_GOAL_S else "NOT met"
        line = (f"  {name:13s}{measured:6.3f} s  goal < {FIGURE_GOAL_S} s: {verdict}; floor "
                f"(blank figure, same size) {floor:6.3f} s, x{measured / floor:4.1f} of it")
        if runs["before"]:
            previous = statistics.median(runs["before"])
            line += f"; before ({BEFORE}) {previous:6.3f} s, x{previous / measured:4.2f} faster"
        print(line)


def print_csv_read(recording: Measurement, loop_s: float, repeat: int) -> None:
    """``read_measurement`` of ``recording`` written to a file, against ``numpy.loadtxt``."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        write_measurement(recording, path)
        text = path.read_text()
        body = text[text.index("\n") + 1:]
        reads, floors = [], []
        for _ in range(repeat):  # alternately
            reads.append(one_time(lambda: read_measurement(path)))
            floors.append(one_time(lambda: np.loadtxt(io.StringIO(body), delimiter=",",
                                                      ndmin=2, comments=None)))
    read, floor = statistics.median(reads), statistics.median(floors)
    rows = body.count("\n")
    print(f"  CSV read     {read:6.3f} s  floor (numpy.loadtxt of the same {rows} rows) "
          f"{floor:6.3f} s, x{read / floor:4.2f} of it; {read / (loop_s + read):.0%} of "
          "read + loop")

if __name__ == "__main__":
    main()
