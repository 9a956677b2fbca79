"""Benchmark: the spring-slider predictor (thesis Eqs. 2.19-2.28) over many parameter points.

Run from the repository root, on one core::

    OPENBLAS_NUM_THREADS=1 python bench/bench_spring_slider.py [--points 100000] [--repeats 3]

It draws ``--points`` random points, uniformly in the ranges of the sweep of
tests/builtins/test_ultrasonic.py: peak-to-peak amplitude 1-5 um, frequency 20-60 kHz, sliding speed
5-100 mm/s, mu0 0.25-1 and normal force 0.1-1 N (kn = 3.9 MN/m, kl = 1.5 MN/m, instantaneous
lateral recovery), and evaluates the relative
friction of all of them in one call of
:func:`hcard_builtins.physics.ultrasonic.relative_friction` (the vectorised core of
``SpringSlider.forward``; it takes mu0 per point, which the predictor holds as a parameter). It
prints the best and median wall time of ``--repeats`` runs and points per second. The aim is
under 10 s for 100,000 points on one core.

``--inverse N`` also times the amplitude inverse (velocity compensation through the
spring-slider, used by device profiles whose UV model is it) for N frames: targets 0.2-0.8 at
20-100 mm/s, 38.22 kHz, 0.5 N, in one call; it costs about 40-50 forward evaluations a frame.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import statistics
import time

import numpy as np

from hcard_builtins.physics.ultrasonic import SpringSlider, relative_friction

AIM_SECONDS = 10.0


def random_points(count: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Uniform random inputs in the model's parameter ranges (SI units), deterministic for
    ``seed``."""
    rng = np.random.default_rng(seed)
    return {
        "amplitude": rng.uniform(1e-6, 5e-6, count),
        "frequency": rng.uniform(20e3, 60e3, count),
        "speed": rng.uniform(5e-3, 0.1, count),
        "normal_force": rng.uniform(0.1, 1.0, count),
        "mu0": rng.uniform(0.25, 1.0, count),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--inverse", type=int, default=0, help="frames for the inverse timing")
    args = parser.parse_args()

    defaults = SpringSlider().params
    points = random_points(args.points, args.seed)
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        result = relative_friction(
            points["amplitude"], points["frequency"], points["speed"], points["normal_force"],
            normal_stiffness=defaults["normal_stiffness"],
            lateral_stiffness=defaults["lateral_stiffness"],
            mu0=points["mu0"],
        )
        times.append(time.perf_counter() - start)
    if not (np.all(np.isfinite(result)) and np.all((result >= 0) & (result <= 1))):
        raise SystemExit("benchmark: relative friction outside [0, 1]")
    best, median = min(times), statistics.median(times)
    print(f"spring-slider: {args.points} points, {args.repeats} runs")
    print(f"  best   {best:.3f} s  ({args.points / best:,.0f} points/s)")
    print(f"  median {median:.3f} s  ({args.points / median:,.0f} points/s)")
    print(f"  mu' range {result.min():.3f} .. {result.max():.3f}, mean {result.mean():.3f}")
    verdict = "meets" if best < AIM_SECONDS * args.points / 100_000 else "misses"
    print(f"  {verdict} the aim of {AIM_SECONDS:g} s per 100,000 points")
    if args.inverse > 0:
        time_inverse(args.inverse, args.seed)


def time_inverse(frames: int, seed: int) -> None:
    """Time ``SpringSlider.inverse`` for ``frames`` targets and check it lands on them."""
    rng = np.random.default_rng(seed)
    target = rng.uniform(0.2, 0.8, frames)
    speed = rng.uniform(0.02, 0.1, frames)
    slider = SpringSlider()
    start = time.perf_counter()
    amplitude = slider.inverse(target, speed=speed, frequency=38_220.0, normal_force=0.5)
    elapsed = time.perf_counter() - start
    reached = slider.forward(amplitude=amplitude, speed=speed, frequency=38_220.0,
                             normal_force=0.5)
    gap = np.abs(reached - target)
    print(f"spring-slider inverse: {frames} frames in {elapsed:.3f} s "
          f"({frames / elapsed:,.0f} frames/s); |mu'(w) - target| median {np.median(gap):.1e}, "
          f"{int(np.sum(gap > 1e-3))} frames off by > 1e-3 (targets in the jump at w_c)")


if __name__ == "__main__":
    main()
