"""Preview time at 16, 64 and 256 textures (the format's maximum) against an empty figure.

Run: ``python bench/bench_preview.py [--repeat 5] [--palettes 16 64 256] [--no-command]``

Cards of 16, 64 and 256 textures of 1 to 16 components (spatial gratings of mixed frequency and
orientation, one in five temporal), every channel and locking, on a 128 x 96 grid of 1.25 mm
taxtels (160 x 120 mm, every texture on at least one taxtel); the largest palette also with an
error map of the grid. In process, warm (one untimed run first): the median of ``--repeat`` runs
of :func:`hcard.preview.picture.render_preview` (figure, drawing, PNG encoding and the file write)
against its floor, an empty matplotlib figure of the same size and resolution saved to a PNG
file, the two run alternately so that both see the same load on a shared machine. As whole
commands (fresh processes, also alternating): ``hcard preview CARD -o OUT.png`` against a
process that imports matplotlib and saves the same empty figure. Prints each time, its ratio to
the floor and the verdict against the goal (preview of a 256-texture card under 1 s, in
process). Single thread (OMP/OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hcard import build
from hcard.card_io import save
from hcard.preview.picture import preview_figure, render_preview
from hcard.v1 import card_pb2 as pb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from console_script import ENTRY

GOAL_S = 1.0
"""Goal: in-process preview of a 256-texture card (figure and PNG), seconds."""
DPI = 120
"""The command's default resolution."""
FLOOR_COMMAND = (
    "import sys; from matplotlib.figure import Figure; "
    "from matplotlib.backends.backend_agg import FigureCanvasAgg; "
    f"f = Figure(figsize=(float(sys.argv[1]), float(sys.argv[2])), dpi={DPI}); FigureCanvasAgg(f); "
    f"f.savefig(sys.argv[3], format='png', dpi={DPI})"
)
"""A process that imports matplotlib and saves an empty figure (arguments: inches, path)."""


def bench_card(n_textures: int) -> pb.Card:
    """``n_textures`` textures of 1-16 components on a 128 x 96 grid of 1.25 mm taxtels."""
    rng = np.random.default_rng(3)
    channels, lockings = ("uv", "ev", "bipolar"), ("position", "velocity", "auto")
    textures = []
    for t in range(n_textures):
        components = []
        for _ in range(int(rng.integers(1, 17))):
            if rng.random() < 0.2:
                components.append(build.temporal(float(rng.uniform(20, 400)),
                                                 float(rng.uniform(0.01, 0.08))))
            else:
                components.append(build.spatial(
                    float(rng.uniform(0.05, 3.0)), float(rng.uniform(0.01, 0.08)),
                    phase=float(rng.uniform(0, 2 * math.pi)),
                    orientation=float(rng.uniform(-math.pi / 2, math.pi / 2))))
        channel = channels[t % 3]
        baseline = {"uv": 0.7, "ev": 1.3, "bipolar": 1.0}[channel]
        textures.append(build.texture(baseline, components, channel=channel,
                                      locking=lockings[(t // 3) % 3], name=f"texture-{t}"))
    cols, rows = 128, 96
    index = rng.integers(0, n_textures, cols * rows)
    index[:n_textures] = np.arange(n_textures)
    return build.card(160.0, 120.0, taxtel_mm=1.25, textures=textures, texture_index=index,
                      title=f"bench, {n_textures} textures")


def bench_error_map(card: pb.Card) -> np.ndarray:
    """A smooth error field over the grid, 0-2.5 JND, with a patch above 1 JND."""
    rows, cols = card.grid.rows, card.grid.cols
    y, x = np.mgrid[0:rows, 0:cols]
    return 1.25 + 1.25 * np.sin(x / 9.0) * np.cos(y / 7.0)


def paired_medians(measured: Callable[[], object], floor: Callable[[], object],
                   repeat: int) -> tuple[float, float, float, float]:
    """Median wall times of ``measured`` and ``floor`` and median CPU times of this process
    (meaningful in process only) of each, seconds: ``repeat`` runs of each, alternating, after
    one untimed run of each."""
    measured()
    floor()
    wall: tuple[list[float], list[float]] = ([], [])
    cpu: tuple[list[float], list[float]] = ([], [])
    for _ in range(repeat):
        for k, fn in enumerate((measured, floor)):
            start, start_cpu = time.perf_counter(), time.process_time()
            fn()
            wall[k].append(time.perf_counter() - start)
            cpu[k].append(time.process_time() - start_cpu)
    return (statistics.median(wall[0]), statistics.median(wall[1]), statistics.median(cpu[0]),
            statistics.median(cpu[1]))


def empty_png(width_in: float, height_in: float, path: Path) -> None:
    """The floor: an empty figure of this size at :data:`DPI` saved as a PNG file."""
    fig = Figure(figsize=(width_in, height_in), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.savefig(path, format="png", dpi=DPI)


def run(argv: list[str]) -> Callable[[], object]:
    """A call that runs ``argv`` as a fresh process (and fails if it fails)."""
    return lambda: subprocess.run(argv, capture_output=True, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per measurement (median)")
    parser.add_argument("--palettes", type=int, nargs="+", default=[16, 64, 256],
                        help="palette sizes (the format allows up to 256)")
    parser.add_argument("--no-command", action="store_true",
                        help="skip the whole-command measurement")
    args = parser.parse_args()
    print(f"median of {args.repeat} warm runs; {DPI} dpi; 128 x 96 taxtels; wall time (CPU time "
          f"of this process, less sensitive to a shared machine's load)")
    print(f"{'case':>20} {'preview':>16} {'floor':>16} {'ratio':>14}   picture")
    verdict = ""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.png"
        for palette in args.palettes:
            card = bench_card(palette)
            cases = [(f"{palette} textures", None)]
            if palette == max(args.palettes):
                cases.append((f"{palette} + error map", bench_error_map(card)))
            for label, error_map in cases:
                figure = preview_figure(card, dpi=DPI, error_map=error_map)
                width_in, height_in = figure.get_size_inches()
                seconds, floor, cpu, cpu_floor = paired_medians(
                    lambda card=card, e=error_map: render_preview(card, out, error_map=e),
                    lambda w=width_in, h=height_in: empty_png(w, h, out), args.repeat)
                print(f"{label:>20} {seconds:6.3f}s ({cpu:.3f}s) {floor:6.3f}s ({cpu_floor:.3f}s)"
                      f" {seconds / floor:5.2f}x ({cpu / cpu_floor:.2f}x)   "
                      f"{width_in:g} x {height_in:.2f} in")
                if palette == max(args.palettes) and error_map is None:
                    verdict = (f"goal: preview of a {palette}-texture card under {GOAL_S:g} s "
                               f"in process: {seconds:.3f} s ({seconds / GOAL_S:.2f}x the goal)"
                               f" -> {'met' if seconds < GOAL_S else 'NOT met'}")
        if not args.no_command:
            palette = max(args.palettes)
            card = bench_card(palette)
            width_in, height_in = preview_figure(card, dpi=DPI).get_size_inches()
            path = Path(tmp) / "bench.hcard"
            save(card, path)
            whole, floor, _, _ = paired_medians(
                run([sys.executable, "-c", ENTRY, "preview", str(path), "-o", str(out)]),
                run([sys.executable, "-c", FLOOR_COMMAND, str(width_in), str(height_in),
                     str(out)]), args.repeat)
            print(f"whole command, {palette} textures: hcard preview {whole:.3f} s, python + "
                  f"matplotlib + empty figure {floor:.3f} s, ratio {whole / floor:.2f}x "
                  f"(the goal is in process)")
    print(verdict)


if __name__ == "__main__":
    main()
