"""How often the calibration loop names the right effect on recordings it was not built from,
against three targets: no wrong effect named, "none" on clean data, and the right effect in
:data:`HIT_TARGET` of the runs whose effects are in the library.

Run: ``python bench/bench_calibration_hit_rates.py [--quick] [--seeds 2] [--only TEXT]``

The recordings come from ``tests/helpers/independent_recordings.py``: every effect written
from the thesis formulas, without the effect plugins' code. The set crosses each scenario (clean,
each in-library effect alone, pairs, one out-of-library effect) with ``--seeds`` seeds, white
and coloured (AR(1) 0.9) sensor noise, and no nuisance or all of them (a drifting sensor offset,
a stroke column through the lifts, 2 % dropped samples). ``--quick``: one seed, no nuisance,
coloured noise only on the clean scenarios.

Each run is scored against what was hidden:

- ``hit``: the loop named exactly the hidden library effects;
- ``partial``: some of them and nothing else (pairs);
- ``undecided``: the verdict is ambiguous between two models and the hidden effects are one
  of them (the loop declined to choose and named the measurement that would); not a hit;
- ``wrong``: it named an effect that was not hidden (an ambiguous verdict between two models
  neither of which is the truth is wrong too);
- ``missed``: it named none although one was hidden;
- clean data: ``none`` when the verdict is "no effect needed", else a false alarm (an effect
  named, or structure reported where there is none);
- out-of-library: right when no effect is named and structure is reported;
- ``ambiguous``: the verdict says the data cannot separate two models (counted besides the
  above).

Prints one line per run, then per scenario class and overall: the rates, the mean run time of
``prepare`` + ``calibrate``, and the targets (no wrong effect; "none" on clean data,
white and coloured; the right effect in >= 90 % of in-library cases) with whether they are met.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the root: tests.helpers

from hcard.calibration.loop import calibrate
from hcard.calibration.results import NO_EFFECT, NOT_EXPLAINED
from hcard.plugins.registry import get_registry
from tests.helpers import independent_recordings as ir

HIT_TARGET = 0.90
"""Share of in-library runs in which the right effect must be named."""


@dataclass(frozen=True)
class Run:
    """One recording through the loop and how it scored.

    Attributes:
        scenario: what was hidden; seed; noise; nuisances: how it was recorded.
        added: effects the loop added; verdict: its verdict.
        runner_up: the effects of the runner-up model (empty when none was compared).
        outcome: ``hit``, ``partial``, ``undecided``, ``wrong``, ``missed``, ``none``,
            ``false alarm``, ``reported`` (out-of-library, structure reported) or
            ``error``.
        ambiguous: whether the verdict says two models cannot be separated.
        seconds: wall time of prepare + calibrate, s.
    """

    scenario: ir.Scenario
    seed: int
    noise: ir.Noise
    nuisances: ir.Nuisances
    added: tuple[str, ...]
    verdict: str
    runner_up: tuple[str, ...]
    outcome: str
    ambiguous: bool
    seconds: float


def is_ambiguous(verdict: str) -> bool:
    """Whether a verdict reports two models the data cannot separate."""
    return "ambiguous" in verdict.lower()


def score(scenario: ir.Scenario, added: tuple[str, ...], verdict: str,
          runner_up: tuple[str, ...] = ()) -> str:
    """The outcome of one run (module docstring)."""
    named = set(added)
    expected = set(scenario.expected)
    if is_ambiguous(verdict) and expected and expected in (named, set(runner_up)):
        return "hit" if named == expected else "undecided"
    if named - expected:
        return "wrong"
    if scenario.kind == "clean":
        return "none" if verdict == NO_EFFECT else "false alarm"
    if scenario.kind == "out-of-library":
        return "reported" if not named and verdict == NOT_EXPLAINED else "missed"
    if named == expected:
        return "hit"
    return "partial" if named else "missed"


def run_one(scenario: ir.Scenario, seed: int, noise: ir.Noise, nuisances: ir.Nuisances,
            protocol: ir.Protocol) -> Run:
    """Generate one recording, run the loop with the whole library on it, score it."""
    registry = get_registry()
    library = list(registry.calibration_effects.values())
    tic = time.perf_counter()
    try:
        data = ir.calibration_data(
            scenario, seed, noise=noise, nuisances=nuisances, protocol=protocol
        )
        result = calibrate(data, registry.get("predictor", ir.BASE_MODEL[scenario.device]),
                           library)
    except Exception as exc:  # a failing run is reported, not hidden
        return Run(scenario, seed, noise, nuisances, (), f"error: {exc}", (), "error", False,
                   time.perf_counter() - tic)
    seconds = time.perf_counter() - tic
    added = tuple(result.effects_added)
    runner_up = tuple(result.comparison.runner_up) if result.comparison is not None else ()
    return Run(scenario, seed, noise, nuisances, added, result.verdict, runner_up,
               score(scenario, added, result.verdict, runner_up),
               is_ambiguous(result.verdict), seconds)


def test_set(quick: bool, seeds: int) -> list[tuple[ir.Scenario, int, ir.Noise, ir.Nuisances]]:
    """The runs of the bench (module docstring)."""
    if quick:
        runs = [(s, 1, ir.WHITE, ir.NO_NUISANCE) for s in ir.SCENARIOS]
        runs += [(s, 1, ir.COLOURED, ir.NO_NUISANCE) for s in ir.CLEAN]
        return runs
    return [
        (scenario, seed, noise, nuisances)
        for scenario in ir.SCENARIOS
        for seed in range(1, seeds + 1)
        for noise in (ir.WHITE, ir.COLOURED)
        for nuisances in (ir.NO_NUISANCE, ir.ALL_NUISANCES)
    ]


def rate(runs: list[Run], outcome: str) -> str:
    """``k/n (p %)`` of ``runs`` with ``outcome``."""
    k = sum(r.outcome == outcome for r in runs)
    return f"{k}/{len(runs)} ({100 * k / len(runs):.0f} %)" if runs else "-"


def summary(runs: list[Run]) -> list[str]:
    """Per scenario class and overall: the rates and the mean time, then the targets."""
    lines = []
    classes: dict[str, list[Run]] = defaultdict(list)
    for r in runs:
        classes[r.scenario.kind].append(r)
        if r.scenario.kind == "clean":
            classes[f"clean, {r.noise.label} noise"].append(r)
    in_library = [r for r in runs if r.scenario.kind in ("single", "pair")]
    order = ["clean", "clean, white noise", f"clean, {ir.COLOURED.label} noise", "single",
             "pair", "out-of-library"]
    groups = [(name, classes[name]) for name in order if classes.get(name)]
    groups += [("in-library (single + pair)", in_library), ("overall", runs)]
    header = (f"{'class':32s} {'runs':>4s}  {'hit':>12s} {'partial':>12s} "
              f"{'undecided':>12s} {'wrong':>12s} "
              f"{'missed':>12s} {'none':>12s} {'false alarm':>12s} {'ambiguous':>10s} "
              f"{'errors':>6s} {'mean s':>6s}")
    lines.append(header)
    for name, group in groups:
        ambiguous = sum(r.ambiguous for r in group)
        errors = sum(r.outcome == "error" for r in group)
        mean = sum(r.seconds for r in group) / len(group)
        lines.append(
            f"{name:32s} {len(group):4d}  {rate(group, 'hit'):>12s} {rate(group, 'partial'):>12s} "
            f"{rate(group, 'undecided'):>12s} {rate(group, 'wrong'):>12s} "
            f"{rate(group, 'missed'):>12s} "
            f"{rate(group, 'none'):>12s} {rate(group, 'false alarm'):>12s} "
            f"{ambiguous:>4d}/{len(group):<5d} {errors:6d} {mean:6.1f}"
        )
    settled = [r for r in runs if r.outcome == "hit" and r.verdict == NOT_EXPLAINED]
    lines.append(f"hits whose verdict still reports structure left: {len(settled)} of "
                 f"{sum(r.outcome == 'hit' for r in runs)}")
    out_of_library = classes.get("out-of-library", [])
    if out_of_library:
        lines.append(f"out-of-library runs with structure reported and no effect named: "
                     f"{rate(out_of_library, 'reported')}")
    wrong = sum(r.outcome == "wrong" for r in runs)
    clean = classes.get("clean", [])
    alarms = sum(r.outcome != "none" for r in clean)
    hits = sum(r.outcome == "hit" for r in in_library)
    hit_share = hits / len(in_library) if in_library else float("nan")
    lines.append("targets:")
    lines.append(f"  no wrong effect named: {wrong} wrong -> {'met' if wrong == 0 else 'NOT met'}")
    lines.append(f"  'none' on clean data (white and coloured): {alarms} of {len(clean)} "
                 f"not 'none' -> {'met' if alarms == 0 else 'NOT met'}")
    lines.append(f"  right effect in >= {HIT_TARGET:.0%} of in-library runs: {hit_share:.0%} -> "
                 f"{'met' if hit_share >= HIT_TARGET else 'NOT met'}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a small set (module docstring)")
    parser.add_argument("--seeds", type=int, default=2, help="seeds per scenario (full set)")
    parser.add_argument("--only", default="", help="only scenarios whose name contains this")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    protocol = ir.Protocol()
    plan = [item for item in test_set(args.quick, args.seeds) if args.only in item[0].name]
    print(f"{len(plan)} runs; protocol: {protocol.sessions} sessions x "
          f"{protocol.strokes_per_session} strokes, {protocol.sample_rate_hz:g} Hz")
    runs = []
    started = time.perf_counter()
    for scenario, seed, noise, nuisances in plan:
        r = run_one(scenario, seed, noise, nuisances, protocol)
        runs.append(r)
        print(f"{scenario.name:36s} seed {seed}  {noise.label:10s} {nuisances.label:58s} "
              f"{r.seconds:5.1f} s  {r.outcome:11s} added: {', '.join(r.added) or 'none':36s} "
              f"{r.verdict[:90]}"
              + (f" (runner-up: {', '.join(r.runner_up)})" if r.ambiguous else ""), flush=True)
    print()
    print("\n".join(summary(runs)))
    print(f"total {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
