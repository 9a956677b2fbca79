"""Device simulation speed: ratio of simulated to wall-clock time, 10 kHz frames, physics on.

Run: ``python bench/bench_device_sim.py [--seconds 20] [--repeat 3] [--block 1000 50]``

The internal finger strokes back and forth across the plate, its speed swelling from 30 to
180 mm/s and back on every 0.7 s stroke (a moderate stroke), sampled by the 50 Hz touch panel;
the card is a UV grating (E-ViTa) or a bipolar grating (coupled stimulator). Every step runs the
streaming renderer, the model-based rendering, the 60 kHz PI plate loop, the EV amplifier, the
sensors and the finger physics. Prints, per device and block size, the best ratio to real time
(goal: at least 10x by CPU time at 5 ms steps, for both devices; the last lines give the
verdicts, with the ratio to the goal) and the RMS relative error of the friction felt
against the target (the 8 % JND). Single process, single thread; the CPU-time ratio is the
one-core figure when other processes share the machine. Each ``step()`` call costs a fixed
~0.25-0.3 ms besides its frames (split out from the two block sizes measured in the same run),
so small steps (firmware wake-ups) run closer to real time.
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from hcard import build
from hcard.track import FingerTrack, make_track
from hcard_device.sim import DeviceConfig, DeviceSimulation, SimBlock

GOAL_BLOCK = 50
"""Frames per step of the goal: 5 ms at 10 kHz, a real-time server's wake-up."""
GOAL_RATIO = 10.0
"""Goal: simulated time per CPU time at :data:`GOAL_BLOCK`-frame steps, for both devices."""
STROKE_S = 0.7
"""Duration of one stroke across the plate, s."""


def back_and_forth(seconds: float, width_mm: float, y_mm: float) -> FingerTrack:
    """Strokes alternating in direction, each with the speed 30 -> 180 -> 30 mm/s."""
    t = np.arange(0.0, seconds + 1e-9, 1e-3)
    phase = (t % STROKE_S) / STROKE_S
    speed = 30.0 + 150.0 * 0.5 * (1 - np.cos(2 * np.pi * phase))
    direction = np.where((t // STROKE_S) % 2 == 0, 1.0, -1.0)
    velocity = speed * direction
    x = np.concatenate(([0.0], np.cumsum((velocity[1:] + velocity[:-1]) / 2 * np.diff(t))))
    x += (width_mm - np.ptp(x)) / 2 - x.min()
    return make_track(t, x, np.full_like(t, y_mm), 0.5)


def cards() -> dict[str, tuple[DeviceConfig, object]]:
    uv = build.texture(0.7, [build.grating_period(3.0, 0.15)], channel="uv", name="grating")
    bipolar = build.texture(
        0.95, [build.grating_period(4.0, 0.15)], channel="bipolar", name="bumps"
    )
    evita, coupled = DeviceConfig.evita(), DeviceConfig.coupled()
    return {
        "e-vita, UV grating": (
            evita, build.card(*evita.surface_mm, taxtel_mm=evita.surface_mm, textures=[uv])
        ),
        "coupled, bipolar grating": (
            coupled,
            build.card(*coupled.surface_mm, taxtel_mm=coupled.surface_mm, textures=[bipolar]),
        ),
    }


def run(
    config: DeviceConfig, card: object, seconds: float, block: int
) -> tuple[float, float, float]:
    """Wall-clock and CPU seconds of ``seconds`` of simulation in steps of ``block`` frames,
    and the RMS relative friction error after the first 50 ms."""
    sim = DeviceSimulation(config, seed=0)
    sim.load_card(card)
    sim.use_internal_finger(back_and_forth(seconds, config.surface_mm[0], config.surface_mm[1] / 2))
    sim.start()
    frames = int(seconds * config.frame_rate_hz)
    blocks = []
    start, cpu = time.perf_counter(), time.process_time()
    for done in range(0, frames, block):
        blocks.append(sim.step(min(block, frames - done)))
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    out = SimBlock.concatenate(blocks)
    on = out.contact & (out.t_s > 0.05)
    error = float(np.sqrt(np.mean(((out.friction[on] - out.target[on]) / out.target[on]) ** 2)))
    return elapsed, cpu, error


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds")
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (best is kept)")
    parser.add_argument(
        "--block", type=int, nargs="+", default=[1000, 50], help="frames per step()"
    )
    args = parser.parse_args()
    print(f"{args.seconds:g} s simulated at 10 kHz frames, 60 kHz PI loop, physics on; goal: "
          f">= {GOAL_RATIO:g}x real time by CPU time at {GOAL_BLOCK}-frame (5 ms) steps, both "
          "devices")
    verdicts = []
    for name, (config, card) in cards().items():
        per_step: dict[int, float] = {}
        for block in args.block:
            results = [run(config, card, args.seconds, block) for _ in range(args.repeat)]
            wall = min(r[0] for r in results)
            cpu = min(r[1] for r in results)
            per_step[block] = cpu / math.ceil(args.seconds * config.frame_rate_hz / block)
            print(
                f"{name:26s} step({block:5d}): {args.seconds / wall:6.1f}x real time "
                f"(wall; {args.seconds / cpu:.1f}x by CPU time, {cpu * 1e3 / args.seconds:.1f} "
                f"ms CPU per simulated s), felt friction RMS error {results[0][2]:.3f} (JND 0.08)"
            )
            if block == GOAL_BLOCK:
                ratio = args.seconds / cpu
                verdicts.append(f"{name}: {ratio:.1f}x at {GOAL_BLOCK}-frame steps (goal >= "
                                f"{GOAL_RATIO:g}x: {'met' if ratio >= GOAL_RATIO else 'NOT met'}"
                                f", {ratio / GOAL_RATIO:.2f} of the goal)")
        if len(per_step) >= 2:
            # cost of one step = fixed + per frame x frames, from the smallest and largest block
            small, large = min(per_step), max(per_step)
            per_frame = (per_step[large] - per_step[small]) / (large - small)
            fixed = per_step[small] - per_frame * small
            print(f"{'':26s} cost of a step: {fixed * 1e6:.0f} us fixed + {per_frame * 1e6:.2f} "
                  f"us per frame (the floor of a {GOAL_BLOCK}-frame step at this per-frame cost: "
                  f"{1.0 / (per_frame * config.frame_rate_hz):.0f}x real time)")
    for line in verdicts:
        print(line)


if __name__ == "__main__":
    main()
