"""`hcard calibrate`'s fits and stroke-block bootstrap: one BLAS thread against OpenBLAS's pool.

Run: ``python bench/bench_bootstrap.py [--repeat 3] [--samples 50] [--seed 5 3]``

Each scenario is what ``tests/calibration/test_loop_through_the_device.py`` runs: the 30 s EV
protocol of ``hcard calibrate plan`` played on the simulated coupled stimulator (``--seed`` per
scenario; seed 3 hides an air layer of 10 um in the device), then the calibration loop
(:func:`~hcard.calibration.loop.calibrate`, the command's fits) and the stroke-block bootstrap of
its final model (``--samples`` refits, the command's default). Both run twice per repeat,
alternating, in this process:

- ``old``: the code path before the fits ran on one BLAS thread: OpenBLAS's default pool, one
  thread per CPU (:func:`~hcard.calibration.blas_threads.one_blas_thread` made to set no
  limit, so it changes nothing);
- ``new``: the fits as they run now, on one BLAS thread.

Prints per scenario and stage the median wall time of each path and their ratio (goal: the
new path at least :data:`GOAL_SPEEDUP` times faster; the gain grows with the load other
processes put on the cores, so the load average is printed before and after), the
floor (the time the new path spends in the model's own evaluations, which no change to the
optimiser's linear algebra can remove) and the new path's ratio to it (goal for the bootstrap,
whose time is all refits: at most :data:`GOAL_FLOOR_RATIO`; the loop also analyses residuals
between its fits, so its ratio is shown without a verdict), and the largest deviation of the
new path's numbers from the old ones: fitted values in units of their uncertainty,
uncertainties and the bootstrap's refits relatively, its 95 % intervals in units of their
width. The numbers differ in their last digits where OpenBLAS's threads split a long sum (over
more than 10,000 samples) into one part per thread; the fits then stop a little earlier or
later inside their convergence tolerance.

Do not set OPENBLAS_NUM_THREADS for this bench: the old path is the default pool.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from threadpoolctl import threadpool_info

import hcard.calibration.blas_threads as blas_threads
from hcard.calibration.bootstrap import DEFAULT_SAMPLES, BootstrapResult, stroke_bootstrap
from hcard.calibration.dataset import prepare
from hcard.calibration.loop import calibrate
from hcard.calibration.measurement import read_measurement
from hcard.calibration.results import CalibrationResult
from hcard.cli.main import cli
from hcard.physics import Predictor
from hcard.plugins.registry import get_registry

GOAL_SPEEDUP = 2.0
"""The new path at least this many times faster than the old one. Measured on 2 cores:
1.9-2.3x with the machine otherwise idle (OpenBLAS's second thread then costs each call its
hand-over and takes the core the model evaluations would use), 6-12x at a load average of 2-3
from other processes (each call also waits for its second thread to be scheduled)."""
GOAL_FLOOR_RATIO = 1.5
"""The bootstrap's new path at most this many times the model evaluations it needs."""
EFFECT = "air-layer"
"""The effect hidden in the device for a seed other than 5 (the device test's choice)."""


def invoke(*args: object) -> None:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    if result.exit_code != 0:
        raise SystemExit(result.output)


def recording(work: Path, seed: int) -> Path:
    """Play the 30 s EV protocol on the simulated coupled stimulator (seed 5: no hidden effect,
    otherwise a 10 um air layer, as the device tests do)."""
    plan = work / "plan"
    if not plan.exists():
        invoke("calibrate", "plan", "--device", "ev", "--duration", "30s", "--verify-duration",
               "16s", "-o", plan)
    uri = f"sim://coupled?seed={seed}"
    if seed != 5:
        uri += f"&effect={EFFECT}&{EFFECT}.air_gap=1e-05"
    out = work / f"rec{seed}.csv"
    invoke("play", plan / "protocol.hcard", "--track", plan / "protocol.csv", "--device", uri,
           "-o", out)
    return out


class ModelClock:
    """Time spent in :meth:`Predictor.forward` (the model evaluations), outermost calls only (a
    composite model's inner forwards are inside its own). Every model of a calibration (the
    lateral-force wrapping of a device profile with its effects) takes its ``forward`` from
    :class:`Predictor`."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.calls = 0
        self._depth = 0
        self._patched: list[tuple[type, Callable]] = []

    def watch(self, cls: type) -> None:
        original = cls.forward
        clock = self

        def timed(model, **inputs):
            clock._depth += 1
            tic = time.perf_counter()
            try:
                return original(model, **inputs)
            finally:
                clock._depth -= 1
                if clock._depth == 0:
                    clock.seconds += time.perf_counter() - tic
                    clock.calls += 1

        cls.forward = timed
        self._patched.append((cls, original))

    def release(self) -> None:
        for cls, original in self._patched:
            cls.forward = original
        self._patched.clear()


def old_path(run: Callable[[], object]) -> object:
    """``run`` with :func:`one_blas_thread` setting no limit: OpenBLAS's default pool."""
    limits = blas_threads.threadpool_limits
    blas_threads.threadpool_limits = lambda **_: limits(limits=None)
    try:
        return run()
    finally:
        blas_threads.threadpool_limits = limits


def deviations(new: CalibrationResult | BootstrapResult,
               old: CalibrationResult | BootstrapResult) -> dict[str, float]:
    """Largest differences of ``new``'s numbers from ``old``'s (module docstring)."""
    out: dict[str, float] = {}

    def keep(name: str, value: float) -> None:
        out[name] = max(out.get(name, 0.0), value)

    if isinstance(new, CalibrationResult):
        assert isinstance(old, CalibrationResult)
        if new.effects_added != old.effects_added or new.verdict != old.verdict:
            out["different verdict"] = math.inf
        fits = [(new.before.fit, old.before.fit), (new.after.fit, old.after.fit)]
        for a, b in fits:
            for name in b.free:
                sigma = b.uncertainties[name]
                if math.isfinite(sigma) and sigma > 0:
                    keep("value / sigma", abs(a.params[name] - b.params[name]) / sigma)
                    keep("sigma (rel)", abs(a.uncertainties[name] - sigma) / sigma)
        for a, b in zip(new.candidates, old.candidates, strict=True):
            if a.test_rmse and b.test_rmse:
                keep("held-out RMSE (rel)", abs(a.test_rmse - b.test_rmse) / b.test_rmse)
        return out
    assert isinstance(old, BootstrapResult)
    for name, values in old.values.items():
        sigma = old.uncertainties[name]
        low, high = old.intervals[name]
        keep("refit / sigma", float(np.max(np.abs(new.values[name] - values))) / sigma)
        keep("sigma (rel)", abs(new.uncertainties[name] - sigma) / sigma)
        keep("interval / width", max(abs(new.intervals[name][0] - low),
                                     abs(new.intervals[name][1] - high)) / (high - low))
    if new.capped != old.capped:
        out["different capped count"] = math.inf
    return out


def measure(label: str, run: Callable[[], object], repeat: int, *,
            floor_goal: bool = True) -> object:
    """Time ``run`` on the old and the new path, alternating; print the line."""
    old_s, new_s, floor_s = [], [], []
    new_result = old_result = None
    for _ in range(repeat):
        tic = time.perf_counter()
        old_result = old_path(run)
        old_s.append(time.perf_counter() - tic)
        clock = ModelClock()
        clock.watch(Predictor)
        tic = time.perf_counter()
        try:
            new_result = run()
        finally:
            clock.release()
        new_s.append(time.perf_counter() - tic)
        floor_s.append(clock.seconds)
    old, new, floor = (statistics.median(v) for v in (old_s, new_s, floor_s))
    speedup, over = old / new, new / floor
    print(f"  {label:26s} old {old:7.2f} s  new {new:6.2f} s  old/new {speedup:5.1f}x "
          f"(goal >= {GOAL_SPEEDUP:g}x: {'met' if speedup >= GOAL_SPEEDUP else 'NOT met'})  "
          f"floor {floor:6.2f} s  new/floor {over:4.2f}"
          + (f" (goal <= {GOAL_FLOOR_RATIO:g}: {'met' if over <= GOAL_FLOOR_RATIO else 'NOT met'})"
             if floor_goal else " (fits and residual analyses)"))
    print(f"  {'':26s} runs old {', '.join(f'{s:.2f}' for s in old_s)}; "
          f"new {', '.join(f'{s:.2f}' for s in new_s)}")
    found = deviations(new_result, old_result)  # type: ignore[arg-type]
    print(f"  {'':26s} new vs old: " + (", ".join(f"{k} {v:.2g}" for k, v in found.items())
                                        or "bit-identical"))
    return new_result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--samples", type=int, default=DEFAULT_SAMPLES)
    parser.add_argument("--seed", type=int, nargs="+", default=[5, 3])
    args = parser.parse_args()
    pools = [(Path(info["filepath"]).name, int(info["num_threads"]))
             for info in threadpool_info() if info["user_api"] == "blas"]
    print("OpenBLAS default threads (the old path): "
          + (", ".join(f"{name} {n}" for name, n in pools) or "no OpenBLAS found"))
    if all(n == 1 for _, n in pools):
        print("warning: the default is one thread already (OPENBLAS_NUM_THREADS?): the old "
              "and the new path are the same")
    print("load average (1, 5, 15 min): " + ", ".join(f"{x:.2f}" for x in os.getloadavg()))
    registry = get_registry()
    library = list(registry.calibration_effects.values())
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seed:
            path = recording(Path(tmp), seed)
            data = prepare([read_measurement(path)])
            base = _device_base(path)
            hidden = "none" if seed == 5 else f"{EFFECT} 10 um"
            print(f"coupled stimulator, seed {seed} (hidden effect: {hidden}): {len(data)} "
                  f"samples, {int(np.count_nonzero(data.train))} training")
            result = measure("calibrate (loop fits)",
                             lambda base=base, data=data: calibrate(data, base, library),
                             args.repeat, floor_goal=False)
            assert isinstance(result, CalibrationResult)
            fit = result.after.fit
            measure(f"bootstrap ({args.samples} refits)",
                    lambda fit=fit, data=data: stroke_bootstrap(fit, data, samples=args.samples),
                    args.repeat)
            print("load average (1, 5, 15 min): "
                  + ", ".join(f"{x:.2f}" for x in os.getloadavg()))


def _device_base(path: Path):
    """The base model ``hcard calibrate`` fits to a recording of the simulated device."""
    from hcard.cli.calibrate_cmd import _base_of

    base, _, _ = _base_of([read_measurement(path)], None, None, "finger-friction")
    return base


if __name__ == "__main__":
    main()
