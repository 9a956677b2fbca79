"""Benchmark: reconstruction error and card size on the generated image set, in one run.

Run from the repository root::

    python bench/bench_fidelity.py [--size 4096] [--seeds 0] [--kinds photo gratings text edges]

For each image of ``bench_images`` (photo-like, gratings, text, edges; ``--size`` pixels square
at 0.1 mm, generated with each seed) it encodes with the default options, with ``--max-error
1``, and with ``--max-error 1 --taxtel-mm 2.5`` (the spec's advice for position maps of edges
and shapes: smaller taxtels), and prints side by side: the card size against the raw 8-bit
bitmap of the surface at 0.1 mm, the image's RMS, 95th percentile and maximum of the absolute
error in JND (the card evaluated position-locked at the pixel centres), the taxtels over 1 JND
(by reason, with a target), and the encode time. The goal: the image's 95th percentile
below 1 JND with a card at most 1/100 of the bitmap; the verdict is printed per row.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from hcard_builtins.image import encode_image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_images import KINDS, write_image

GOAL_P95_JND = 1.0
"""Goal: the image's 95th percentile of the absolute error below this, JND."""
GOAL_SIZE_RATIO = 100.0
"""Goal: the raw 0.1 mm bitmap at least this many times the card."""
CONFIGURATIONS = (
    ("default", {}),
    ("-e 1", {"max_error": 1.0}),
    ("-e 1 -t 2.5", {"max_error": 1.0, "taxtel_mm": 2.5}),
)
"""Encoder options of each row: ``-e`` is ``--max-error``, ``-t`` ``--taxtel-mm``."""


def row(kind: str, seed: int, label: str, path: Path, options: dict) -> str:
    """One line of the table: ``label`` options on the image at ``path``."""
    started = time.perf_counter()
    result = encode_image(path, **options)
    seconds = time.perf_counter() - started
    stats = result.stats
    ratio = stats["raw_bitmap_bytes"] / stats["card_bytes"]
    p95 = stats["p95_error_jnd"]
    met = p95 < GOAL_P95_JND and ratio >= GOAL_SIZE_RATIO
    target = stats.get("target")
    if target is None:
        over = f"{stats['taxtels_over_jnd']} rms>1 (no target)"
    else:
        reasons = ", ".join(f"{n} {name}" for name, n in target["reasons"].items() if n)
        over = f"{target['taxtels_over']} ({reasons or 'none'})"
    return (f"{kind:9s} {seed:4d} {label:12s} {stats['textures']:4d} {stats['components']:5d} "
            f"{stats['card_bytes']:8d} 1/{ratio:<6.0f} {stats['rms_error_jnd']:5.2f} "
            f"{p95:5.2f} {stats['max_error_jnd']:5.2f}  {'meets' if met else 'MISSES':6s} "
            f"{seconds:6.2f}  {over}")


def main(argv: list[str] | None = None) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096, help="image side, pixels")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="random seeds")
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    args = parser.parse_args(argv)
    print(f"goal: image p95 < {GOAL_P95_JND:g} JND with card <= 1/{GOAL_SIZE_RATIO:g} of the "
          f"0.1 mm bitmap; {args.size} x {args.size} pixels ({args.size / 10:g} mm square), "
          "5 mm taxtels unless -t (--taxtel-mm); -e: --max-error")
    print(f"{'image':9s} {'seed':>4s} {'options':12s} {'tex':>4s} {'comp':>5s} {'card B':>8s} "
          f"{'size':7s} {'rms':>5s} {'p95':>5s} {'max':>5s}  {'goal':6s} {'enc s':>6s}  "
          "taxtels over 1 JND (target reasons)")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            for seed in args.seeds:
                path = write_image(Path(tmp) / f"{kind}-{seed}.png", kind, args.size, seed)
                for label, options in CONFIGURATIONS:
                    print(row(kind, seed, label, path, options))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
