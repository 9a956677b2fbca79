"""The calibration loop with and without screening, side by side: the same answers, and how
much faster.

Run: ``python bench/bench_calibration_screening.py [--seeds 1,2] [--nuisances]
[--only TEXT] [--screen-samples 4000] [--sessions 10]``

The recordings come from ``tests/helpers/independent_recordings.py`` (every effect written
from the thesis formulas, without the effect plugins' code), ``--sessions`` sessions long (10:
about 60 s at 1 kHz, as a lab's recording; the loop screens from 16000 training samples on):
every scenario of its set (clean,
each in-library effect alone, pairs, one out-of-library effect) for each seed, with white and
AR(1) 0.9 sensor noise, and with ``--nuisances`` also with all of them (a drifting sensor
offset, a stroke column through the lifts, 2 % dropped samples). Each recording goes through
the loop twice in one process, alternately: with screening (``LoopSettings.screen_samples``)
and without (0: every candidate fitted on every training sample, the baseline).

Per run it prints both wall times and their ratio, then what must be equal and whether it is:

- the effects added and the verdict;
- the accepted model's fitted parameters (bit for bit) and held-out RMSE;
- the runner-up and the criterion margin to it, where it may decide the verdict (it is
  counted apart otherwise: among rivals far from the final model the screening may name
  another one whose criterion lies within its tolerance band);
- the ranking of each round's single-effect candidates by held-out RMSE: ``same``, or the
  largest relative gap (in the baseline) between two candidates the screening ranks the other
  way round (the screened figures of candidates far from every decision may differ by up to
  the tolerance);
- the largest relative difference between a screened candidate's held-out RMSE and the
  baseline's figure for it, against ``SCREEN_TOLERANCE``.

The summary counts the runs whose answers differ (the goal: none) and the total time ratio. One
CPU, BLAS on one thread.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the root: tests.helpers

from calibration_answers import differences, runner_up

from hcard.calibration.loop import calibrate
from hcard.calibration.results import CalibrationResult, LoopSettings
from hcard.calibration.screening import SCREEN_SAMPLES, SCREEN_TOLERANCE
from hcard.plugins.registry import get_registry
from tests.helpers import independent_recordings as ir


def rankings(result: CalibrationResult) -> dict[int, list[tuple[float, str]]]:
    """Each round's single-effect candidates as (held-out RMSE, name), best first."""
    rounds: dict[int, list[tuple[float, str]]] = {}
    for c in result.candidates:
        if " + " not in c.effect and c.test_rmse is not None:
            rounds.setdefault(c.round, []).append((c.test_rmse, c.effect))
    return {k: sorted(v) for k, v in rounds.items()}


def rank_gap(baseline: CalibrationResult, screened: CalibrationResult) -> float:
    """0 when every round ranks its candidates alike, else the largest relative gap of
    held-out RMSE (baseline figures) between two candidates ranked the other way round."""
    mine = rankings(screened)
    worst = 0.0
    for number, ranked in rankings(baseline).items():
        order = {name: i for i, (_, name) in enumerate(mine.get(number, []))}
        for i, (low, first) in enumerate(ranked):
            for high, second in ranked[i + 1:]:
                if first in order and second in order and order[first] > order[second]:
                    worst = max(worst, high / low - 1.0)
    return worst


def screened_deviation(baseline: CalibrationResult,
                       screened: CalibrationResult) -> tuple[float, str]:
    """Largest relative difference of a screened candidate's held-out RMSE from the
    baseline's figure for the same candidate, and that candidate (round: effects)."""
    reference = {(c.round, c.effect): c.test_rmse for c in baseline.candidates}
    worst, which = 0.0, ""
    for c in screened.candidates:
        full = reference.get((c.round, c.effect))
        if c.screened and c.test_rmse is not None and full:
            deviation = abs(c.test_rmse / full - 1.0)
            if deviation > worst:
                worst, which = deviation, f"{c.round}: {c.effect}"
    return worst, which


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1", help="comma-separated seeds")
    parser.add_argument("--nuisances", action="store_true",
                        help="also record each run with every nuisance")
    parser.add_argument("--only", default="", help="scenarios whose name contains this")
    parser.add_argument("--screen-samples", type=int, default=SCREEN_SAMPLES)
    parser.add_argument("--sessions", type=int, default=10,
                        help="sessions of the protocol (10: about 60 s at 1 kHz, 30000 "
                             "training samples)")
    args = parser.parse_args()
    protocol = ir.Protocol(sessions=args.sessions)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    registry = get_registry()
    library = list(registry.calibration_effects.values())
    seeds = [int(s) for s in args.seeds.split(",")]
    kinds = [ir.NO_NUISANCE, ir.ALL_NUISANCES] if args.nuisances else [ir.NO_NUISANCE]
    print(f"screening on about {args.screen_samples} training samples, tolerance "
          f"{SCREEN_TOLERANCE:.0%}; baseline: every candidate on every training sample; 1 CPU")
    totals = [0.0, 0.0]
    runs = differing = renamed = 0
    worst_renamed = 0.0
    worst_deviation = worst_gap = 0.0
    for scenario in ir.SCENARIOS:
        if args.only not in scenario.name:
            continue
        base = registry.get("predictor", ir.BASE_MODEL[scenario.device])
        for seed in seeds:
            for noise in (ir.WHITE, ir.COLOURED):
                for nuisances in kinds:
                    data = ir.calibration_data(scenario, seed, noise=noise, nuisances=nuisances,
                                               protocol=protocol)
                    seconds = []
                    results = []
                    for samples in (0, args.screen_samples):
                        tic = time.perf_counter()
                        results.append(calibrate(data, base, library,
                                                 settings=LoopSettings(screen_samples=samples)))
                        seconds.append(time.perf_counter() - tic)
                    baseline, screened = results
                    found = differences(baseline, screened)
                    gap = rank_gap(baseline, screened)
                    deviation, which = screened_deviation(baseline, screened)
                    runs += 1
                    differing += bool(found)
                    named = runner_up(baseline), runner_up(screened)
                    if named[0] != named[1] and None not in named:
                        renamed += 1
                        worst_renamed = max(worst_renamed, abs(named[0][1] - named[1][1]))
                    worst_gap = max(worst_gap, gap)
                    worst_deviation = max(worst_deviation, deviation)
                    totals[0] += seconds[0]
                    totals[1] += seconds[1]
                    label = f"{scenario.name}, seed {seed}, {noise.label}, {nuisances.label}"
                    print(
                        f"{label:62s} {seconds[0]:6.2f} s -> {seconds[1]:6.2f} s "
                        f"(x{seconds[0] / seconds[1]:4.2f})  added "
                        f"{', '.join(screened.effects_added) or 'none':34s} "
                        f"{'same answers' if not found else 'DIFFERENT: ' + '; '.join(found)}; "
                        f"runner-up {'same' if named[0] == named[1] else named}; "
                        f"ranking {'same' if gap == 0 else f'swaps within {gap:.2%}'}; "
                        f"screened figures within {deviation:.2%} ({which or '-'})",
                        flush=True,
                    )
    if not runs:
        print("no scenario matches --only")
        return
    print(f"runs with different answers: {differing} of {runs} -> "
          f"{'goal met' if differing == 0 else 'goal NOT met'} (goal: none)")
    print(f"runner-up named differently (no rival near the final model): {renamed} of {runs}, "
          f"criterion margins differing by at most {worst_renamed:.3g}")
    print(f"screened figures within {worst_deviation:.2%} of the baseline's (tolerance "
          f"{SCREEN_TOLERANCE:.0%}: {'within' if worst_deviation <= SCREEN_TOLERANCE else 'BEYOND'}"
          f"); candidates ranked the other way round differ by at most {worst_gap:.2%}")
    ratio = totals[0] / totals[1] if totals[1] > 0 else math.nan
    print(f"loop time: baseline {totals[0]:.1f} s, screened {totals[1]:.1f} s (x{ratio:.2f})")


if __name__ == "__main__":
    main()
