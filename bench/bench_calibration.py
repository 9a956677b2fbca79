"""The calibration loop on 100,000 samples with the full effect library, on one core.

Run: ``python bench/bench_calibration.py [--samples 100000] [--repeat 1]``

For each scenario the reference device's tribometer simulation records ``--samples`` samples at
1 kHz (lifts included) with hidden effects, tribometer noise (1.5 mN) and a drifting zero (3 mN);
the loop then runs with every installed calibration effect as a candidate. Prints, per scenario,
the wall time of :func:`hcard.calibration.loop.calibrate` (best of ``--repeat``), the number of
fits, what it found and the held-out RMSE before and after. The process is pinned to one CPU
and BLAS to one thread. Aim: under 60 s per scenario.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from hcard.calibration.dataset import prepare
from hcard.calibration.loop import CalibrationResult, calibrate
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=1)
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
    print(f"{len(library)} effects in the library; {args.samples} samples per scenario; 1 CPU")
    for label, device, model, hidden in SCENARIOS:
        recordings = synthesize(
            device,
            hidden,
            protocol=protocol,
            lateral_noise_n=1.5e-3,
            normal_noise_n=1.5e-3,
            drift_n=3e-3,
            seed=7,
        )
        best = float("inf")
        result: CalibrationResult | None = None
        for _ in range(args.repeat):
            tic = time.perf_counter()
            data = prepare(recordings)
            result = calibrate(data, registry.get("predictor", model), library)
            best = min(best, time.perf_counter() - tic)
        assert result is not None
        fits = 1 + sum(c.test_rmse is not None for c in result.candidates)
        added = ", ".join(result.effects_added) or "none"
        print(
            f"{label:44s} {best:6.1f} s  {fits:2d} fits  added: {added:40s} "
            f"held-out RMSE {result.before.test_rmse * 1e3:6.2f} -> "
            f"{result.after.test_rmse * 1e3:5.2f} mN  ({result.verdict})"
        )


if __name__ == "__main__":
    main()
