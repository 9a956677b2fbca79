"""Peak memory of ``hcard play`` against the length of the session, in one run.

Run: ``python bench/bench_play_memory.py [--seconds 20 80]``

Plays a card with plain and textured patches along a back-and-forth finger track of each
length on ``sim://evita`` (1000 STATE reports per second of track), each in a fresh process
running the command line in-process, and prints the peak memory (max RSS) of each, the same
for a process that only imports the play command (the floor), and the memory each further
report costs: the slope between the shortest and the longest session. The goal (spec
measurement-format.md, "Recording a session"): at most 200 bytes per report (the packed report
is 58), so that an hour's session stays under a gigabyte.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

GOAL_BYTES_PER_REPORT = 200.0
REPORTS_PER_S = 1000.0
MEASURE = (
    "import json, resource, sys\n"
    "from hcard.cli.main import cli\n"
    "{body}\n"
    "print(json.dumps({{'kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}}))\n"
)
PLAY = ("import contextlib, io\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    cli(sys.argv[1:], standalone_mode=False)")
IMPORT_ONLY = "import hcard.device.play, hcard.device.recording"


def write_inputs(folder: Path, seconds: float) -> tuple[Path, Path]:
    """A two-texture card and a back-and-forth track of ``seconds`` (100 Hz samples)."""
    from hcard import build
    from hcard.card_io import save

    card = folder / "step.hcard"
    save(build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(1.0, channel="uv", name="plain"),
        build.texture(0.5, channel="uv", name="slip")], texture_index=[0, 1]), card)
    t = np.arange(0.0, seconds, 0.01)
    x = 10.0 + 8.0 * np.sin(2 * np.pi * t / 0.8)
    track = folder / f"track{seconds:g}.csv"
    with track.open("w") as out:
        out.write("t_s,x_mm,y_mm,fn_n,contact\n")
        np.savetxt(out, np.column_stack([t, x, np.full_like(t, 5.0), np.full_like(t, 0.5),
                                         np.ones_like(t)]), delimiter=",",
                   fmt=["%.3f", "%.4f", "%.1f", "%.2f", "%d"])
    return card, track


def peak_mb(body: str, args: list[str]) -> float:
    """Peak memory (MB) of a fresh process running ``body`` with ``args``."""
    done = subprocess.run([sys.executable, "-c", MEASURE.format(body=body), *args],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])["kb"] / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, nargs="+", default=[20.0, 80.0],
                        help="track lengths to play, s")
    options = parser.parse_args()
    lengths = sorted(options.seconds)
    with tempfile.TemporaryDirectory() as folder:
        floor = peak_mb(IMPORT_ONLY, [])
        print(f"{'session':>12} {'reports':>9} {'peak MB':>9}")
        print(f"{'import only':>12} {0:>9} {floor:>9.1f}")
        peaks = []
        for seconds in lengths:
            card, track = write_inputs(Path(folder), seconds)
            args = ["play", str(card), "--device", "sim://evita", "--track", str(track),
                    "-o", str(Path(folder) / "rec.csv")]
            peaks.append(peak_mb(PLAY, args))
            print(f"{seconds:>10g} s {seconds * REPORTS_PER_S:>9.0f} {peaks[-1]:>9.1f}")
    if len(lengths) > 1:
        reports = (lengths[-1] - lengths[0]) * REPORTS_PER_S
        slope = (peaks[-1] - peaks[0]) * 1024 * 1024 / reports
        verdict = "met" if slope <= GOAL_BYTES_PER_REPORT else "NOT met"
        print(f"memory per further report: {slope:.0f} bytes (goal <= "
              f"{GOAL_BYTES_PER_REPORT:.0f}: {verdict}; packed report 58 bytes); "
              f"an hour at 1 kHz: {slope * 3.6e6 / 1e9 + peaks[0] / 1024:.2f} GB")


if __name__ == "__main__":
    main()
