"""Renderer throughput: frames per second and ratio to real time at 10 kHz.

Run: ``python bench/bench_renderer.py [--seconds 20] [--repeat 3]``

The card has a 4 x 4 palette of textures with 8 components each (spatial gratings of mixed
orientation and locking plus temporal components), the track a 50 Hz zig-zag stroke at
120 mm/s crossing many taxtels. Prints batch throughput, the streaming cost of a 5 ms block
(aim: at most 0.5 ms) and the position-only baseline. Single process, single thread
(set OMP/OPENBLAS_NUM_THREADS=1 for a one-core figure).
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
from hcard.render import Renderer, RenderOptions
from hcard.track import make_track

FRAME_RATE_HZ = 10_000.0
COMPONENTS = 8


def bench_card(n_textures: int = 16, width_mm: float = 120.0, height_mm: float = 80.0):
    """A card whose every texture has ``COMPONENTS`` components."""
    rng = np.random.default_rng(7)
    textures = []
    for t in range(n_textures):
        comps = []
        for c in range(COMPONENTS):
            if c == COMPONENTS - 1:
                comps.append(build.temporal(float(rng.uniform(50, 300)), 0.02))
            else:
                comps.append(
                    build.spatial(
                        float(rng.uniform(0.05, 2.0)),
                        float(rng.uniform(0.01, 0.05)),
                        phase=float(rng.uniform(0, 2 * math.pi)),
                        orientation=float(rng.uniform(-math.pi / 2, math.pi / 2)),
                    )
                )
        textures.append(build.texture(0.7, comps, channel="bipolar", locking="auto", name=f"t{t}"))
    cols, rows = int(width_mm / 10), int(height_mm / 10)
    index = (np.arange(cols * rows) % n_textures).astype(int)
    return build.card(width_mm, height_mm, taxtel_mm=10.0, textures=textures, texture_index=index)


def zigzag_track(seconds: float, rate_hz: float = 50.0):
    """A stroke bouncing across a 120 x 80 mm surface at about 120 mm/s."""
    t = np.arange(int(seconds * rate_hz) + 1) / rate_hz
    x = 60 + 55 * np.sin(2 * np.pi * t / 2.9)
    y = 40 + 35 * np.sin(2 * np.pi * t / 4.3)
    return make_track(t, x, y)


def best_of(repeat: int, fn) -> float:
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="track length, s")
    parser.add_argument("--repeat", type=int, default=3, help="runs; the best is reported")
    args = parser.parse_args()

    card = bench_card()
    track = zigzag_track(args.seconds)
    hybrid = Renderer(card, RenderOptions(frame_rate_hz=FRAME_RATE_HZ))
    frames = hybrid.render(track)
    n = len(frames)
    elapsed = best_of(args.repeat, lambda: hybrid.render(track))
    fps = n / elapsed
    print(f"card: 16 textures x {COMPONENTS} components; track {args.seconds:g} s at 50 Hz")
    print(
        f"batch hybrid:   {n} frames in {elapsed * 1e3:.1f} ms = {fps / 1e6:.2f} Mframes/s "
        f"= {fps / FRAME_RATE_HZ:.0f}x real time at 10 kHz (aim >= 1000x)"
    )

    position = Renderer(card, RenderOptions(frame_rate_hz=FRAME_RATE_HZ, mode="position-only"))
    p_elapsed = best_of(args.repeat, lambda: position.render(track))
    print(f"batch position-only baseline: {n / p_elapsed / FRAME_RATE_HZ:.0f}x real time")

    block = int(0.005 * FRAME_RATE_HZ)
    blocks_per_sample = int(FRAME_RATE_HZ / 50 / block)

    def run_stream() -> list[float]:
        stream = hybrid.stream(t0=float(track.t[0]))
        costs = []
        for i in range(len(track) - 1):
            stream.push(track.t[i], track.x[i], track.y[i], track.fn[i], track.contact[i])
            for _ in range(blocks_per_sample):
                start = time.perf_counter()
                stream.render(block)
                costs.append(time.perf_counter() - start)
        return costs

    costs = np.array(min((run_stream() for _ in range(args.repeat)), key=np.median))
    print(
        f"streaming 5 ms blocks ({block} frames): median {np.median(costs) * 1e3:.3f} ms, "
        f"p99 {np.percentile(costs, 99) * 1e3:.3f} ms (aim <= 0.5 ms)"
    )


if __name__ == "__main__":
    main()
