"""Benchmark: image encoder time against the time of only decoding the same PNG.

Run from the repository root::

    python bench/bench_encoder.py [--size 4096] [--repeats 5]

It writes a textured grayscale PNG (size x size pixels, 0.1 mm per pixel: gratings of several
periods and orientations, a two-grating mixture, a checkerboard with a grating in its dark
squares, flat areas and noise over everything) into a temporary directory, then times, each
``--repeats`` times:

- decode only: Pillow ``open`` + ``load`` + ``convert("L")``;
- the full encode, decoding included: ``encode_image`` (spectral analysis, palette merging,
  reconstruction error and the card message; writing the file is not included).

It prints the best and median times and their ratio. The aim (issue) is an encode time of at
most 3x the decode-only time on a 4096 x 4096 image.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from hcard_builtins.image import encode_image

PIXELS_PER_MM = 10.0
AIM = 3.0


def make_bench_image(path: Path, size: int = 4096, seed: int = 0) -> None:
    """Write the benchmark PNG (``size`` x ``size`` pixels, 254 dpi) to ``path``.

    Regions of ``size/4`` pixels: gratings of 1.0, 1.6, 2.2 and 0.8 mm at 0, 45, 90 and -30 deg,
    a mixture of 1.2 mm at 30 deg and 0.7 mm at -60 deg, a 10 mm checkerboard whose dark squares
    carry a 1.5 mm grating, flat gray levels and a smooth gradient; gaussian noise of 3 gray
    levels everywhere. Deterministic for a given ``seed``.
    """
    rng = np.random.default_rng(seed)
    block = size // 4
    yy, xx = np.mgrid[0:block, 0:block].astype(np.float32)
    x, y = (xx + 0.5) / PIXELS_PER_MM, (yy + 0.5) / PIXELS_PER_MM

    def wave(period: float, degrees: float) -> np.ndarray:
        t = np.radians(degrees)
        return np.cos(2 * np.pi * (np.cos(t) * x + np.sin(t) * y) / period).astype(np.float32)

    checker = ((x // 10.0) + (y // 10.0)) % 2 == 0
    tiles = [
        128 - 80 * wave(1.0, 0.0),
        128 - 70 * wave(1.6, 45.0),
        128 - 60 * wave(2.2, 90.0),
        128 - 50 * wave(0.8, -30.0),
        128 - 40 * wave(1.2, 30.0) - 30 * wave(0.7, -60.0),
        np.where(checker, 90 - 50 * wave(1.5, 0.0), 220),
        np.full_like(x, 60.0),
        40 + 180 * x / x.max(),
    ]
    flat = np.full_like(x, 200.0)
    layout = [
        tiles[(i * 4 + j) % len(tiles)] if (i + j) % 3 else flat for i in range(4) for j in range(4)
    ]
    rows = [np.concatenate(layout[i * 4 : i * 4 + 4], axis=1) for i in range(4)]
    image = np.concatenate(rows, axis=0)
    image += rng.normal(0.0, 3.0, image.shape).astype(np.float32)
    pixels = np.clip(np.round(image), 0, 255).astype(np.uint8)
    Image.fromarray(pixels).save(path, dpi=(254, 254))


def decode_only(path: Path) -> float:
    """Seconds to open, decode and convert ``path`` to 8-bit gray with Pillow."""
    started = time.perf_counter()
    with Image.open(path) as image:
        image.load()
        image.convert("L")
    return time.perf_counter() - started


def encode_once(path: Path) -> float:
    """Seconds for one full :func:`encode_image` of ``path`` (decode included)."""
    started = time.perf_counter()
    encode_image(path)
    return time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures (the aim is reported, not enforced)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096, help="image side, pixels")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of each step")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.png"
        make_bench_image(path, args.size)
        size_mb = path.stat().st_size / 1e6
        result = encode_image(path)
        decode_only(path)  # warm-up of the file cache
        decode = [decode_only(path) for _ in range(args.repeats)]
        encode = [encode_once(path) for _ in range(args.repeats)]
    stats = result.stats
    print(f"image      {args.size} x {args.size} pixels, PNG {size_mb:.1f} MB")
    print(
        f"card       {stats['cols']} x {stats['rows']} taxtels, {stats['textures']} textures, "
        f"{stats['components']} components, {stats['card_bytes']} bytes, "
        f"rms error {stats['rms_error']:.4f} ({stats['rms_error_jnd']:.2f} JND)"
    )
    for name, times in (("decode", decode), ("encode", encode)):
        best, median = min(times) * 1e3, statistics.median(times) * 1e3
        print(f"{name:10s} best {best:7.1f} ms, median {median:7.1f} ms")
    ratio_best = min(encode) / min(decode)
    ratio_median = statistics.median(encode) / statistics.median(decode)
    verdict = "meets" if ratio_median <= AIM else "misses"
    print(
        f"ratio      encode / decode = {ratio_median:.2f} (median), {ratio_best:.2f} (best); "
        f"{verdict} the aim of {AIM:g}x"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
