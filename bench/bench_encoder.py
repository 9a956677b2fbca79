"""Benchmark: image encoder time against Pillow's decode of the same PNG, in one run.

Run from the repository root::

    python bench/bench_encoder.py [--sizes 1024 2048 4096] [--repeats 5] [--commands 5]

For each size it writes the textured grayscale PNG of ``bench_images.gratings`` (size x size
pixels, 0.1 mm per pixel: gratings of several periods and orientations, a two-grating mixture,
a checkerboard with a grating in its dark squares, flat areas, a gradient and noise over
everything) into a temporary directory, then measures, alternating the two so that both see
the same load:

- in process, ``--repeats`` times each: Pillow ``open`` + ``load`` + ``convert("L")`` (the
  floor) against the full ``encode_image`` with default options (decoding, analysis, palette,
  reconstruction error, card message; writing the file is not included);
- as whole commands, ``--commands`` times each: a fresh ``python -c "from PIL import Image;
  Image.open(p).load()"`` (the floor) against a fresh ``hcard -q encode p -o card.hcard``
  (the console script's own code, ``console_script.ENTRY``, not a shell shim), which includes
  the interpreter's start-up, the imports, writing the card, printing the summary and the
  process's exit. Both run with bytecode caching
  allowed (``PYTHONDONTWRITEBYTECODE`` removed from their environment, one untimed run first),
  as an installed package runs: otherwise every run would recompile hcard's modules.

It prints, per size, the goal (encode at most 3x the decode), the wall-clock medians, their
ratio and the verdict, and the ratio of the best runs; then the same ratio of CPU time (user +
system of the process, or of the child process for commands), which waiting for a busy core
does not inflate (on a shared machine the wall-clock ratio swings with the other load; the
encoder's FFT runs on every core, which adds to its CPU time, not its wall time).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image

from hcard_builtins.image import encode_image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_images import write_image
from console_script import ENTRY

AIM = 3.0
"""Goal: encode time at most this multiple of the decode time."""


def make_bench_image(path: Path, size: int = 4096, seed: int = 0) -> None:
    """Write the benchmark PNG (``size`` x ``size`` pixels, 254 dpi) to ``path``."""
    write_image(path, "gratings", size, seed)


Timing = tuple[float, float]
"""Wall seconds and CPU seconds of one run."""


def decode_only(path: Path) -> Timing:
    """Seconds to open, decode and convert ``path`` to 8-bit gray with Pillow."""
    started, cpu = time.perf_counter(), time.process_time()
    with Image.open(path) as image:
        image.load()
        image.convert("L")
    return time.perf_counter() - started, time.process_time() - cpu


def encode_once(path: Path) -> Timing:
    """Seconds for one full :func:`encode_image` of ``path`` (decode included)."""
    started, cpu = time.perf_counter(), time.process_time()
    encode_image(path)
    return time.perf_counter() - started, time.process_time() - cpu


COMMAND_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
"""Environment of the timed commands: bytecode caching allowed."""


def command_once(argv: list[str]) -> Timing:
    """Seconds of one fresh process running ``argv`` (which must succeed)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env=COMMAND_ENV)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return wall, cpu


def alternate(first, second, repeats: int) -> tuple[list[Timing], list[Timing]]:
    """Run ``first()`` and ``second()`` alternately ``repeats`` times each; their times."""
    a, b = [], []
    for _ in range(repeats):
        a.append(first())
        b.append(second())
    return a, b


def verdict_line(label: str, floor: list[Timing], measured: list[Timing]) -> str:
    """``label``: wall-clock medians of both, their ratio and whether it meets :data:`AIM`;
    the ratio of the best runs, and the ratio of the CPU-time medians."""
    f = statistics.median(t[0] for t in floor)
    m = statistics.median(t[0] for t in measured)
    ratio = m / f
    verdict = "meets" if ratio <= AIM else "MISSES"
    best = min(t[0] for t in measured) / min(t[0] for t in floor)
    cpu = statistics.median(t[1] for t in measured) / statistics.median(t[1] for t in floor)
    return (f"  {label:10s} goal <= {AIM:g}x decode | decode {f * 1e3:7.1f} ms | encode "
            f"{m * 1e3:7.1f} ms | ratio {ratio:5.2f} {verdict:6s} | best runs {best:5.2f} | "
            f"CPU time {cpu:5.2f}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures (the aim is reported, not enforced)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096],
                        help="image sides, pixels")
    parser.add_argument("--repeats", type=int, default=5, help="in-process runs of each")
    parser.add_argument("--commands", type=int, default=5, help="whole-command runs of each")
    args = parser.parse_args(argv)
    py = sys.executable
    print("medians; encode = default options (hcard encode IMAGE -o CARD)")
    for size in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.png"
            card = Path(tmp) / "bench.hcard"
            make_bench_image(path, size)
            result = encode_image(path)  # warm-up (file cache, lazy imports)
            decode_only(path)
            stats = result.stats
            print(f"{size} x {size} pixels, PNG {path.stat().st_size / 1e6:.1f} MB: card "
                  f"{stats['card_bytes']} bytes ({stats['textures']} textures, "
                  f"{stats['components']} components), error p95 {stats['p95_error_jnd']:.2f} "
                  "JND")
            floor, encode = alternate(lambda p=path: decode_only(p),
                                      lambda p=path: encode_once(p), args.repeats)
            print(verdict_line("in process", floor, encode))
            pillow = [py, "-c", f"from PIL import Image; Image.open({str(path)!r}).load()"]
            hcard = [py, "-c", ENTRY, "-q", "encode", str(path), "-o", str(card)]
            command_once(pillow), command_once(hcard)  # untimed: bytecode, file cache
            floor, encode = alternate(lambda a=pillow: command_once(a),
                                      lambda a=hcard: command_once(a), args.commands)
            print(verdict_line("command", floor, encode))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
