"""Benchmark: card size against the raw 8-bit friction bitmap of the same surface.

Run from the repository root (after ``python examples/make_examples.py``)::

    python bench/bench_card_size.py [--size 4096]

For each example image (``examples/*.png``) and the benchmark image of ``bench_encoder.py``
(generated in a temporary directory), it encodes with the default options and prints the card
size (binary form, bytes), the size of a raw 8-bit friction bitmap at 0.1 mm resolution for the
same surface (``width_mm * 10 x height_mm * 10`` bytes), their ratio, and the reconstruction
error, so that the compression is read together with what it costs.
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
from collections.abc import Callable
from pathlib import Path

from hcard_builtins.image import encode_image

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "examples"


def _bench_image_maker() -> Callable[[Path, int], None]:
    """``make_bench_image`` of ``bench_encoder.py`` (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location("bench_encoder", HERE / "bench_encoder.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.make_bench_image


def row(path: Path, label: str) -> str:
    """One line of the table for the image at ``path``."""
    stats = encode_image(path).stats
    card, raw = stats["card_bytes"], stats["raw_bitmap_bytes"]
    return (
        f"{label:22s} {stats['width_mm']:7.1f} x {stats['height_mm']:<7.1f} "
        f"{stats['textures']:4d} {stats['components']:5d} {card:9d} {raw:11d} "
        f"{raw / card:9.0f}x {stats['rms_error']:8.4f} {stats['rms_error_jnd']:6.2f}"
    )


def main(argv: list[str] | None = None) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096, help="benchmark image side, pixels")
    args = parser.parse_args(argv)
    print(
        f"{'image':22s} {'surface mm':17s} {'tex':>4s} {'comp':>5s} {'card B':>9s} "
        f"{'raw 0.1mm B':>11s} {'raw/card':>10s} {'rms err':>8s} {'x JND':>6s}"
    )
    examples = sorted(EXAMPLES.glob("*.png"))
    if not examples:
        print(f"(no examples in {EXAMPLES}: run python examples/make_examples.py)")
    for path in examples:
        print(row(path, path.name))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.png"
        _bench_image_maker()(path, args.size)
        print(row(path, f"bench {args.size}x{args.size}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
