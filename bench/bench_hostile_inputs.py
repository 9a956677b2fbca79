"""Time and peak memory of the commands on hostile inputs, against the spec's bound and against
the same command on the binary equivalent (or a small valid input: the floor), in one run.

Run: ``python bench/bench_hostile_inputs.py [--skip-tracks]``

Each command runs in a fresh process (the command line run in-process, as a user runs it) that
prints its exit status, its wall time and its peak memory (max RSS). The bound (spec/README.md
section 4): 20 s and 32 bytes per input byte plus 250 MB. The inputs are the generators of
tests/helpers/hostile_cards.py: 16 MiB JSON cards of 5.6 million ``{}`` components or textures (and
their binary equivalents, 8.4 million empty ones), a card whose description is 16 MiB of control
characters, a track spanning 1e305 s, PNGs declaring 8000 x 8000 pixels of 16-bit RGBA and
64,000,000 x 1 pixels, and tracks of 10^7 samples (over the limit of spec/track-format.md TK8)
and of 2^22 (at it).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the root: tests.helpers

from tests.helpers.hostile_cards import (
    control_description,
    empty_components,
    empty_textures,
    json_empty_components,
    json_empty_textures,
    png_declaring,
)

TIME_BOUND_S = 20.0
MEMORY_PER_INPUT_BYTE = 32
MEMORY_CONSTANT_MB = 250.0
MB = 1e6
MEASURE = (
    "import contextlib, io, json, resource, sys, time\n"
    "from hcard.cli.main import cli\n"
    "start = time.perf_counter()\n"
    "try:\n"
    "    with contextlib.redirect_stdout(io.StringIO()):\n"
    "        cli.main(args=sys.argv[1:], prog_name='hcard')\n"
    "except SystemExit as exc:\n"
    "    code = exc.code if isinstance(exc.code, int) else 1\n"
    "else:\n"
    "    code = 0\n"
    "print(json.dumps({'code': code, 's': time.perf_counter() - start,\n"
    "                  'kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}))\n"
)


def measure(args: list[str]) -> tuple[int, float, float]:
    """Exit status, seconds and peak memory (MB) of ``hcard ARGS`` in a fresh process."""
    done = subprocess.run([sys.executable, "-c", MEASURE, *args], capture_output=True,
                          text=True, check=False)
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    return figures["code"], figures["s"], figures["kb"] * 1024 / MB


def write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


def track_file(folder: Path, name: str, samples: int) -> Path:
    """A straight stroke of ``samples`` samples at 10 kHz (one frame a sample)."""
    path = folder / name
    t = np.arange(samples) * 1e-4
    with path.open("w") as out:
        out.write("t_s,x_mm,y_mm\n")
        np.savetxt(out, np.column_stack([t, 1.0 + t % 8.0, np.full(samples, 5.0)]),
                   fmt="%.10g", delimiter=",")
    return path


def report(label: str, args: list[str], input_bytes: int, floor: tuple[float, float] | None,
           ) -> None:
    code, seconds, peak = measure(args)
    bound_mb = (MEMORY_PER_INPUT_BYTE * input_bytes) / MB + MEMORY_CONSTANT_MB
    line = (f"{label:<44} exit {code}  {seconds:6.2f} s ({seconds / TIME_BOUND_S:4.2f} of "
            f"{TIME_BOUND_S:g} s)  {peak:6.0f} MB ({peak / bound_mb:4.2f} of {bound_mb:.0f} MB)")
    if floor is not None:
        line += f"  vs floor {floor[0]:.2f} s, {floor[1]:.0f} MB: x{seconds / floor[0]:.2f} time"
    print(line, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skip-tracks", action="store_true",
                        help="leave out the 10^7- and 2^22-sample tracks (a minute or more)")
    options = parser.parse_args()
    from hcard import build, card_io

    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        small = folder / "small.hcard"
        card_io.save(build.card(10.0, 10.0, taxtel_mm=10.0,
                                textures=[build.texture(0.5, channel="uv")]), small)
        stroke = folder / "stroke.csv"
        stroke.write_text("t_s,x_mm,y_mm\n0,1,5\n0.1,3,5\n0.2,5,5\n")
        out = str(folder / "out.csv")
        cards = {
            "components": (write(folder, "c.json", json_empty_components()),
                           write(folder, "c.hcard", empty_components())),
            "textures": (write(folder, "t.json", json_empty_textures()),
                         write(folder, "t.hcard", empty_textures())),
        }
        print("goal: every hostile input refused (exit 1) within 20 s and 32 B/input byte + "
              "250 MB; JSON as cheap as binary")
        for what, (as_json, as_binary) in cards.items():
            for command in ("validate", "render", "preview"):
                extra = {"render": ["--track", str(stroke), "-o", out],
                         "preview": ["-o", str(folder / "p.png")]}.get(command, [])
                _, floor_s, floor_mb = measure([command, str(as_binary), *extra])
                print(f"{command} binary {what:<28}         {floor_s:6.2f} s  {floor_mb:6.0f} MB")
                report(f"{command} JSON {what} (5.6 M {{}})", [command, str(as_json), *extra],
                       as_json.stat().st_size, (floor_s, floor_mb))
        _, *floor = measure(["info", str(small)])
        described = write(folder, "d.hcard", control_description())
        report("info, description of 16 MiB controls", ["info", str(described)],
               described.stat().st_size, (floor[0], floor[1]))
        far = folder / "far.csv"
        far.write_text("t_s,x_mm,y_mm\n0,1,5\n1e305,2,5\n")
        _, *floor = measure(["render", str(small), "--track", str(stroke), "-o", out])
        report("render, track to t_s = 1e305", ["render", str(small), "--track", str(far),
                                                 "-o", out], far.stat().st_size,
               (floor[0], floor[1]))
        gray = folder / "gray.png"
        gray.write_bytes(png_declaring(256, 256, rows=256))
        _, *floor = measure(["encode", str(gray), "-o", str(folder / "g.hcard")])
        for label, png in (("encode, 8000 x 8000 16-bit RGBA PNG",
                            png_declaring(8000, 8000, bit_depth=16, colour_type=6, rows=8000)),
                           ("encode, 64,000,000 x 1 PNG", png_declaring(64_000_000, 1, rows=1))):
            image = write(folder, "bomb.png", png)
            report(f"{label} ({len(png) / MB:.2f} MB)",
                   ["encode", str(image), "-o", str(folder / "b.hcard")], len(png),
                   (floor[0], floor[1]))
        if not options.skip_tracks:
            for label, samples in (("render, 10^7-sample track (over TK8)", 10_000_000),
                                   ("render, 2^22-sample track (at TK8)", 1 << 22)):
                track = track_file(folder, "long.csv", samples)
                report(label, ["render", str(small), "--track", str(track), "-o",
                               str(folder / "long.npz")], track.stat().st_size, None)


if __name__ == "__main__":
    main()
