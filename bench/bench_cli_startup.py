"""Start-up time of the ``hcard`` command against the interpreter's own, in one run.

Run: ``python bench/bench_cli_startup.py [--repeat 7]``

Times (median wall time of ``--repeat`` runs, each a fresh process) ``python -c pass``,
``python -c "import numpy"``, ``hcard --help`` / ``info`` / ``validate`` on a small card and
``hcard plugins`` (every plugin discovered, none imported), and prints each with its excess
over ``python -c pass`` and over ``import numpy``. The hcard commands run the console script's
own code (:data:`console_script.ENTRY`), not a shell shim, so a pyenv or conda wrapper does not
count. Target (these commands under 0.3 s): printed with whether it is met.

Then the exit of the process, from the command's return to the end of the process, for
``hcard -q encode`` of a 1024 x 1024 image (the heaviest imports: numpy, Pillow, protobuf) run
as the console script and through the bare click group (:data:`console_script.WITHOUT_FAST_EXIT`,
the interpreter's full garbage-collection passes at exit), beside a process that only decodes
the image with Pillow.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_images import write_image
from console_script import ENTRY, WITHOUT_FAST_EXIT

TARGET_S = 0.3
"""Start-up a card command must stay under, s."""

RETURNED = "\nreturned at "
"""What :func:`exit_time`'s child prints on standard error when its code has run."""


def wall_time(argv: list[str], repeat: int) -> float:
    """Median wall time of ``argv`` over ``repeat`` fresh processes, s."""
    times = []
    for _ in range(repeat):
        tic = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - tic)
    return statistics.median(times)


def exit_time(code: str, args: list[str], repeat: int) -> float:
    """Median seconds from the end of ``code`` (run as ``python -c code args...``) to the end of
    its process, over ``repeat`` fresh processes (bytecode caching allowed, as installed)."""
    probe = (f"import sys, time\ntry:\n    {code}\n"  # simple statements: one line
             f"finally:\n    sys.stderr.write({RETURNED!r} + repr(time.time()))\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times = []
    for _ in range(repeat + 1):  # the first run writes the bytecode
        done = subprocess.run([sys.executable, "-c", probe, *args], env=env, check=False,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            raise SystemExit(f"python -c {code!r} failed:\n{done.stderr}")
        ended = time.time()
        times.append(ended - float(done.stderr.rsplit(RETURNED, 1)[1]))
    return statistics.median(times[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=7, help="runs per command (median)")
    args = parser.parse_args()
    from hcard import build
    from hcard.card_io import save

    with tempfile.TemporaryDirectory() as tmp:
        card = Path(tmp) / "card.hcard"
        save(build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
            build.texture(1.0, channel="uv", name="plain"),
            build.texture(0.5, channel="uv", name="slip")], texture_index=[0, 1],
            title="bench"), card)
        py = sys.executable
        runs = {
            "python -c pass": [py, "-c", "pass"],
            "python -c 'import numpy'": [py, "-c", "import numpy"],
            "hcard --help": [py, "-c", ENTRY, "--help"],
            "hcard info CARD": [py, "-c", ENTRY, "info", str(card)],
            "hcard validate CARD": [py, "-c", ENTRY, "validate", str(card)],
            "hcard plugins": [py, "-c", ENTRY, "plugins"],
        }
        measured = {name: wall_time(argv, args.repeat) for name, argv in runs.items()}
    bare, numpy_s = measured["python -c pass"], measured["python -c 'import numpy'"]
    print(f"median of {args.repeat} runs each")
    for name, seconds in measured.items():
        print(f"{name:28s} {seconds:6.3f} s   +{seconds - bare:6.3f} s over python, "
              f"{seconds / numpy_s:5.2f} x import numpy")
    worst = max(measured[n] for n in measured if n.startswith("hcard"))
    print(f"target: these commands under {TARGET_S} s: slowest {worst:.3f} s -> "
          f"{'met' if worst < TARGET_S else 'NOT met'}")
    with tempfile.TemporaryDirectory() as tmp:
        image = write_image(Path(tmp) / "gratings.png", "gratings", 1024)
        encode = ["-q", "encode", str(image), "-o", str(Path(tmp) / "card.hcard")]
        decode = f"from PIL import Image; Image.open({str(image)!r}).load()"
        exits = {
            "hcard encode (console script)": exit_time(ENTRY, encode, args.repeat),
            "hcard encode (bare click group)": exit_time(WITHOUT_FAST_EXIT, encode, args.repeat),
            "Pillow decode only": exit_time(decode, [], args.repeat),
        }
    print("process exit after the command returned (1024 x 1024 gratings image):")
    for name, seconds in exits.items():
        print(f"  {name:32s} {seconds * 1e3:6.1f} ms")


if __name__ == "__main__":
    main()
