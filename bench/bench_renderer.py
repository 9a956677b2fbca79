"""Renderer throughput: frames per second and ratio to real time at 10 kHz.

Run: ``python bench/bench_renderer.py [--seconds 20] [--repeat 3] [--palettes 1 16 256]``

Cards of 1, 16 and 256 textures (the format's maximum) with 16 components each (spatial
gratings of mixed orientation and locking plus a temporal component) on a 24 x 16 grid of 5 mm
taxtels (every texture of the largest palette on at least one), the track a 50 Hz zig-zag
stroke at 120 mm/s crossing many taxtels. Prints, per palette, batch throughput, the floor (a
float32 NumPy cosine of the same frames and components, measured in the same run) and the
ratio to it, and the streaming cost of a 5 ms block; then the verdicts against the goals
(>= 1500x real time and <= 2x the floor at 256 textures, <= 0.1 ms per block at any palette).
Single process, single thread (OMP/OPENBLAS_NUM_THREADS=1).
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
COMPONENTS = 16
"""Components per texture: the format's maximum."""
GOAL_REALTIME = 1500.0
"""Goal: batch rendering at the largest palette, times real time."""
GOAL_FLOOR_RATIO = 2.0
"""Goal: batch time over the float32 cosine floor of the same frames and components."""
GOAL_BLOCK_MS = 0.1
"""Goal: streaming cost of one 5 ms block at any palette size, ms."""


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
    cols, rows = int(width_mm / 5), int(height_mm / 5)
    index = (np.arange(cols * rows) % n_textures).astype(int)
    return build.card(width_mm, height_mm, taxtel_mm=5.0, textures=textures, texture_index=index)


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


def cosine_floor(frames: int, components: int, repeat: int) -> float:
    """Seconds for the plain NumPy floor of a batch: ``frames`` x ``components`` float32 phases
    from 6 phase inputs (one matmul), their cosine and the sum over components."""
    rng = np.random.default_rng(1)
    inputs = rng.uniform(-50, 50, (frames, 6)).astype(np.float32)
    weights = rng.uniform(-1, 1, (6, components)).astype(np.float32)
    amplitude = rng.uniform(0, 0.05, components).astype(np.float32)

    def floor() -> None:
        turns = inputs @ weights
        turns -= np.rint(turns)
        turns *= np.float32(2 * np.pi)
        np.cos(turns, out=turns)
        _ = turns @ amplitude

    return best_of(repeat, floor)


def stream_costs(renderer: Renderer, track, repeat: int) -> np.ndarray:
    """Seconds per 5 ms block of a stream fed the track's samples (the run of median cost)."""
    block = int(0.005 * FRAME_RATE_HZ)
    blocks_per_sample = int(FRAME_RATE_HZ / 50 / block)

    def run_stream() -> list[float]:
        stream = renderer.stream(t0=float(track.t[0]))
        costs = []
        for i in range(len(track) - 1):
            stream.push(track.t[i], track.x[i], track.y[i], track.fn[i], track.contact[i])
            for _ in range(blocks_per_sample):
                start = time.perf_counter()
                stream.render(block)
                costs.append(time.perf_counter() - start)
        return costs

    return np.array(min((run_stream() for _ in range(repeat)), key=np.median))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="track length, s")
    parser.add_argument("--repeat", type=int, default=3, help="runs; the best is reported")
    parser.add_argument("--palettes", type=int, nargs="+", default=[1, 16, 256],
                        help="palette sizes to measure (the format allows up to 256)")
    args = parser.parse_args()

    track = zigzag_track(args.seconds)
    print(f"track {args.seconds:g} s at 50 Hz, {COMPONENTS} components per texture, "
          f"10 kHz frames")
    print(f"{'textures':>8} {'batch x real time':>18} {'floor x real time':>18} "
          f"{'ratio to floor':>15} {'5 ms block median':>18} {'p99':>9}")
    verdicts = []
    frames = len(Renderer(bench_card(1), RenderOptions(frame_rate_hz=FRAME_RATE_HZ)).render(track))
    # one floor for every palette (the same frames and components), measured with more runs
    floor = cosine_floor(frames, COMPONENTS, 3 * args.repeat)
    for palette in args.palettes:
        card = bench_card(palette)
        hybrid = Renderer(card, RenderOptions(frame_rate_hz=FRAME_RATE_HZ))
        n = len(hybrid.render(track))
        elapsed = best_of(args.repeat, lambda hybrid=hybrid: hybrid.render(track))
        costs = stream_costs(hybrid, track, args.repeat)
        realtime = n / elapsed / FRAME_RATE_HZ
        ratio = elapsed / floor
        median_ms = float(np.median(costs)) * 1e3
        print(f"{palette:>8} {realtime:>17.0f}x {n / floor / FRAME_RATE_HZ:>17.0f}x "
              f"{ratio:>14.2f}x {median_ms:>15.3f} ms {np.percentile(costs, 99) * 1e3:>6.3f} ms")
        if palette == max(args.palettes):
            verdicts += [
                f"batch at {palette} textures: {realtime:.0f}x real time (goal >= "
                f"{GOAL_REALTIME:.0f}x: {'met' if realtime >= GOAL_REALTIME else 'NOT met'})",
                f"batch at {palette} textures: {ratio:.2f}x the float32 cosine floor (goal <= "
                f"{GOAL_FLOOR_RATIO:g}x: {'met' if ratio <= GOAL_FLOOR_RATIO else 'NOT met'})",
            ]
        verdicts.append(f"streaming at {palette} textures: {median_ms:.3f} ms per 5 ms block "
                        f"(goal <= {GOAL_BLOCK_MS} ms: "
                        f"{'met' if median_ms <= GOAL_BLOCK_MS else 'NOT met'})")
    position = Renderer(bench_card(16), RenderOptions(frame_rate_hz=FRAME_RATE_HZ,
                                                       mode="position-only"))
    p_elapsed = best_of(args.repeat, lambda: position.render(track))
    print(f"batch position-only at 16 textures: "
          f"{len(position.render(track)) / p_elapsed / FRAME_RATE_HZ:.0f}x real time")
    # eight times the speed: the fine gratings pass 0.8 of the band limit (the gain branch)
    fast = make_track(track.t / 8, track.x, track.y)
    fast_renderer = Renderer(bench_card(16), RenderOptions(frame_rate_hz=FRAME_RATE_HZ))
    fast_frames = len(fast_renderer.render(fast))
    f_elapsed = best_of(args.repeat, lambda: fast_renderer.render(fast))
    print(f"batch at 16 textures, a stroke 8x as fast (band-limit gain active): "
          f"{fast_frames / f_elapsed / FRAME_RATE_HZ:.0f}x real time")
    for line in verdicts:
        print(line)


if __name__ == "__main__":
    main()
