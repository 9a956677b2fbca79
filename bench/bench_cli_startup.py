"""Start-up time of the ``hcard`` command against the interpreter's own, in one run.

Run: ``python bench/bench_cli_startup.py [--repeat 7]``

Times (median wall time of ``--repeat`` runs, each a fresh process) ``python -c pass``,
``python -c "import numpy"``, and ``hcard --help`` / ``info`` / ``validate`` on a small card,
and prints each with its excess over ``python -c pass`` and over ``import numpy``. The hcard
commands run the console script's own code (:data:`ENTRY`), not a shell shim, so a pyenv or
conda wrapper does not count. Target (card commands under
0.3 s): printed with whether it is met.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 0.3
"""Start-up a card command must stay under, s."""

ENTRY = "import sys; from hcard.cli.main import cli; sys.exit(cli())"
"""What the ``hcard`` console script runs."""


def wall_time(argv: list[str], repeat: int) -> float:
    """Median wall time of ``argv`` over ``repeat`` fresh processes, s."""
    times = []
    for _ in range(repeat):
        tic = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - tic)
    return statistics.median(times)


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
        }
        measured = {name: wall_time(argv, args.repeat) for name, argv in runs.items()}
    bare, numpy_s = measured["python -c pass"], measured["python -c 'import numpy'"]
    print(f"median of {args.repeat} runs each")
    for name, seconds in measured.items():
        print(f"{name:28s} {seconds:6.3f} s   +{seconds - bare:6.3f} s over python, "
              f"{seconds / numpy_s:5.2f} x import numpy")
    worst = max(measured[n] for n in measured if n.startswith("hcard"))
    print(f"target: card commands under {TARGET_S} s: slowest {worst:.3f} s -> "
          f"{'met' if worst < TARGET_S else 'NOT met'}")


if __name__ == "__main__":
    main()
