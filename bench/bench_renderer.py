"""Renderer throughput: frames per second and ratio to real time at 10 kHz, each figure beside
its floor measured in the same run.

Run: ``python bench/bench_renderer.py [--seconds 20] [--repeat 5] [--palettes 1 16 256]``

Cards of 1, 16 and 256 textures (the format's maximum) with 16 components each (spatial
gratings of mixed orientation and locking plus a temporal component) on a 24 x 16 grid of 5 mm
taxtels (every texture of the largest palette on at least one), the track a 50 Hz zig-zag
stroke at 120 mm/s crossing many taxtels.

The floor of a batch rendering is a plain NumPy float32 cosine of the same frames and
components: one matmul from 6 phase inputs, the reduction to one turn, the cosine and the sum
over components. The floor of a streaming 5 ms block is the same for the block's 50 frames.
Rounds alternate the figures and their floors, and each keeps its best round, so both see the
same machine load. Verdicts against the goals: batch >= 1500x real time and <= 2x its floor at
the largest palette, a 5 ms block <= 0.1 ms at every palette, and the cost of the largest
palette within 1.25x that of 16 textures (the same grid of taxtels, every neighbour another
texture: only the palette size differs; one texture on every taxtel has no texture changes and
is printed beside). Single process, single thread (OMP/OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Callable

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from hcard import build
from hcard.render import Renderer, RenderOptions
from hcard.track import FingerTrack, make_track

FRAME_RATE_HZ = 10_000.0
COMPONENTS = 16
"""Components per texture: the format's maximum."""
BLOCK_FRAMES = 50
"""Frames of a streaming block: 5 ms at 10 kHz."""
GOAL_REALTIME = 1500.0
"""Goal: batch rendering at the largest palette, times real time."""
GOAL_FLOOR_RATIO = 2.0
"""Goal: batch time over the float32 cosine floor of the same frames and components."""
GOAL_BLOCK_MS = 0.1
"""Goal: streaming cost of one 5 ms block at any palette size, ms."""
GOAL_PALETTE_RATIO = 1.25
"""Goal: batch time at the largest palette over that of 16 textures on the same grid (cost
independent of the palette size, within the noise of a shared machine)."""
PALETTE_REFERENCE = 16
"""The palette the largest is compared with."""


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


def zigzag_track(seconds: float, rate_hz: float = 50.0) -> FingerTrack:
    """A stroke bouncing across a 120 x 80 mm surface at about 120 mm/s."""
    t = np.arange(int(seconds * rate_hz) + 1) / rate_hz
    x = 60 + 55 * np.sin(2 * np.pi * t / 2.9)
    y = 40 + 35 * np.sin(2 * np.pi * t / 4.3)
    return make_track(t, x, y)


def timed(fn: Callable[[], object]) -> float:
    """Seconds of one call of ``fn``."""
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def cosine_floor(frames: int, components: int) -> Callable[[], None]:
    """The plain NumPy floor of ``frames`` x ``components``: float32 phases from 6 phase inputs
    (one matmul), the reduction to one turn, the cosine and the sum over components."""
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

    return floor


def stream_costs(renderer: Renderer, track: FingerTrack) -> np.ndarray:
    """Seconds per 5 ms block of a stream fed the track's samples."""
    blocks_per_sample = int(FRAME_RATE_HZ / 50 / BLOCK_FRAMES)
    stream = renderer.stream(t0=float(track.t[0]))
    costs = []
    for i in range(len(track) - 1):
        stream.push(track.t[i], track.x[i], track.y[i], track.normal_force[i], track.contact[i])
        for _ in range(blocks_per_sample):
            start = time.perf_counter()
            stream.render(BLOCK_FRAMES)
            costs.append(time.perf_counter() - start)
    return np.array(costs)


def block_floor_costs(blocks: int) -> np.ndarray:
    """Seconds of the cosine floor of each of ``blocks`` 5 ms blocks."""
    floor = cosine_floor(BLOCK_FRAMES, COMPONENTS)
    return np.array([timed(floor) for _ in range(blocks)])


def verdict(met: bool) -> str:
    return "met" if met else "NOT met"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="track length, s")
    parser.add_argument("--repeat", type=int, default=5, help="rounds; the best is reported")
    parser.add_argument("--palettes", type=int, nargs="+", default=[1, 16, 256],
                        help="palette sizes to measure (the format allows up to 256)")
    args = parser.parse_args()

    track = zigzag_track(args.seconds)
    options = RenderOptions(frame_rate_hz=FRAME_RATE_HZ)
    renderers = {p: Renderer(bench_card(p), options) for p in args.palettes}
    frames = len(renderers[args.palettes[0]].render(track))
    # eight times the speed: the fine gratings pass 0.8 of the band limit (the gain branch)
    fast = make_track(track.t / 8, track.x, track.y)
    extra = {
        "position-only, 16 textures": (
            Renderer(bench_card(16), RenderOptions(frame_rate_hz=FRAME_RATE_HZ,
                                                   mode="position-only")), track),
        "8x faster stroke (band-limit gain active), 16 textures": (
            Renderer(bench_card(16), options), fast),
    }
    floors = {frames: cosine_floor(frames, COMPONENTS)}
    for renderer, extra_track in extra.values():
        n = len(renderer.render(extra_track))
        floors.setdefault(n, cosine_floor(n, COMPONENTS))
    batch = {p: math.inf for p in args.palettes}
    others = {name: math.inf for name in extra}
    floor_s = {n: math.inf for n in floors}
    streams: dict[int, np.ndarray] = {}
    block_floor = np.full(1, math.inf)
    for _ in range(args.repeat):  # each figure beside its floor, every round
        for p, renderer in renderers.items():
            batch[p] = min(batch[p], timed(lambda r=renderer: r.render(track)))
            floor_s[frames] = min(floor_s[frames], timed(floors[frames]))
        for name, (renderer, extra_track) in extra.items():
            others[name] = min(others[name],
                               timed(lambda r=renderer, t=extra_track: r.render(t)))
        for n, floor in floors.items():
            floor_s[n] = min(floor_s[n], timed(floor))
        for p, renderer in renderers.items():
            costs = stream_costs(renderer, track)
            if p not in streams or np.median(costs) < np.median(streams[p]):
                streams[p] = costs
        block = block_floor_costs(len(streams[args.palettes[0]]))
        if np.median(block) < np.median(block_floor):
            block_floor = block

    def realtime(n: int, seconds: float) -> float:
        return n / seconds / FRAME_RATE_HZ

    floor_rt = realtime(frames, floor_s[frames])
    block_floor_ms = float(np.median(block_floor)) * 1e3
    print(f"track {args.seconds:g} s at 50 Hz ({frames} frames at 10 kHz), {COMPONENTS} "
          f"components per texture, best of {args.repeat} rounds")
    print(f"batch floor (float32 cosine of the same frames): {floor_rt:.0f}x real time; "
          f"5 ms block floor: {block_floor_ms:.4f} ms (median)")
    print(f"{'textures':>8} {'batch x real time':>18} {'ratio to floor':>15} "
          f"{'5 ms block median':>18} {'ratio to floor':>15} {'p99':>9}")
    for p in args.palettes:
        median_ms = float(np.median(streams[p])) * 1e3
        print(f"{p:>8} {realtime(frames, batch[p]):>17.0f}x {batch[p] / floor_s[frames]:>14.2f}x "
              f"{median_ms:>15.3f} ms {median_ms / block_floor_ms:>14.1f}x "
              f"{np.percentile(streams[p], 99) * 1e3:>6.3f} ms")
    for name, (renderer, extra_track) in extra.items():
        n = len(renderer.render(extra_track))
        print(f"batch, {name}: {realtime(n, others[name]):.0f}x real time, "
              f"{others[name] / floor_s[n]:.2f}x its floor")
    largest, smallest = max(args.palettes), min(args.palettes)
    rt = realtime(frames, batch[largest])
    ratio = batch[largest] / floor_s[frames]
    print(f"batch at {largest} textures: {rt:.0f}x real time (goal >= {GOAL_REALTIME:.0f}x: "
          f"{verdict(rt >= GOAL_REALTIME)}); floor {floor_rt:.0f}x")
    print(f"batch at {largest} textures: {ratio:.2f}x the float32 cosine floor (goal <= "
          f"{GOAL_FLOOR_RATIO:g}x: {verdict(ratio <= GOAL_FLOOR_RATIO)})")
    for p in args.palettes:
        median_ms = float(np.median(streams[p])) * 1e3
        print(f"streaming at {p} textures: {median_ms:.3f} ms per 5 ms block (goal <= "
              f"{GOAL_BLOCK_MS} ms: {verdict(median_ms <= GOAL_BLOCK_MS)}); "
              f"{median_ms / block_floor_ms:.1f}x its floor of {block_floor_ms:.4f} ms")
    if PALETTE_REFERENCE in batch and largest != PALETTE_REFERENCE:
        spread = batch[largest] / batch[PALETTE_REFERENCE]
        print(f"palette independence: batch at {largest} textures takes {spread:.2f}x the time "
              f"at {PALETTE_REFERENCE} on the same grid (goal <= {GOAL_PALETTE_RATIO:g}x: "
              f"{verdict(spread <= GOAL_PALETTE_RATIO)}); "
              + (f"{batch[largest] / batch[smallest]:.2f}x the time of {smallest} texture on "
                 "every taxtel (no texture changes)" if smallest < PALETTE_REFERENCE else ""))


if __name__ == "__main__":
    main()
