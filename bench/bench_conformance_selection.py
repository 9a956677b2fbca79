"""What choosing cases before running saves: the conformance suite's pytest plugin, one run.

Run: ``python bench/bench_conformance_selection.py [--repeat 5] [--no-device]``

Times (median wall time of ``--repeat`` runs, each a fresh ``python -m pytest`` process in an
empty folder, as a vendor's CI runs it) the plugin:

* without a driver (the floor: pytest's start-up, nothing conformance-related);
* against ``reference``: ``--collect-only`` (every case of the format and renderer levels
  listed, nothing measured), the whole run, ``-k`` choosing one renderer case, and the same
  case by its node ID;
* unless ``--no-device``, against ``sim://``: ``--collect-only`` of the device level (which
  opens the device for DEVICE_INFO), the whole device level, one device case by node ID
  (``device.friction::dense-grating``).

Every run of a case collects first (the plan: the suite's imports, the manifest and golden
renders, DEVICE_INFO), so each row prints its excess over the floor and a run of one case
prints what it costs beyond collecting, as a fraction of what the whole run costs beyond
collecting. Goal (spec QP6): one case measures a small fraction of the run it is chosen from,
under a quarter; printed with whether it is met.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLUGIN = ("-p", "hcard_conformance.pytest_plugin", "-p", "no:cacheprovider",
          "-p", "no:hypothesispytest", "-q")
"""The plugin, without the cache and without Hypothesis's pytest plugin (a dev dependency of
this repository that a vendor's pytest need not have: it imports Hypothesis for its terminal
summary, ~2 s of every run here)."""
REFERENCE = "--hcard-driver=reference"
ONE_CASE = "renderer.friction_error::single-grating@fast-stroke"
ONE_DEVICE_CASE = "device.friction::dense-grating"
GOAL_FRACTION = 0.25
"""Largest fraction of the whole run's time beyond collecting that a run of one case may take
beyond collecting."""


def wall_time(args: list[str], folder: Path, repeat: int) -> float:
    """Median wall time of ``python -m pytest PLUGIN args`` in ``folder``, s; raises when a
    run fails (a bench of a broken run measures nothing)."""
    times = []
    for _ in range(repeat):
        tic = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "pytest", *PLUGIN, *args], cwd=folder,
                              capture_output=True, text=True, check=False)
        times.append(time.perf_counter() - tic)
        if done.returncode not in (0, 5):  # 5: no tests (the floor)
            raise SystemExit(f"pytest {' '.join(args)} exited {done.returncode}:\n"
                             f"{done.stdout[-2000:]}")
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per command (median)")
    parser.add_argument("--no-device", action="store_true", help="skip the sim:// runs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        floor = wall_time([], folder, args.repeat)
        print(f"floor (pytest, plugin without a driver): {floor:6.2f} s")
        rows = [("collect-only, reference", [REFERENCE, "--collect-only"], None),
                ("whole run, reference", [REFERENCE], None),
                ("-k one renderer case", [REFERENCE, "-k",
                                          "friction_error and single-grating and fast-stroke"],
                 ("collect-only, reference", "whole run, reference")),
                ("node ID of that case", [REFERENCE, ONE_CASE],
                 ("collect-only, reference", "whole run, reference"))]
        if not args.no_device:
            device = ["--hcard-driver=sim://", "--hcard-level=device"]
            rows += [("collect-only, sim:// device", [*device, "--collect-only"], None),
                     ("device level, sim://", device, None),
                     ("node ID of one device case", ["--hcard-driver=sim://", ONE_DEVICE_CASE],
                      ("collect-only, sim:// device", "device level, sim://"))]
        measured: dict[str, float] = {}
        for name, argv, against in rows:
            seconds = wall_time(argv, folder, args.repeat)
            measured[name] = seconds
            line = f"{name:28s} {seconds:6.2f} s  (+{seconds - floor:5.2f} s over the floor)"
            if against is not None:
                collect, whole = (measured[k] for k in against)
                fraction = (seconds - collect) / max(whole - collect, 1e-9)
                verdict = "met" if fraction < GOAL_FRACTION else "NOT met"
                line += (f"; beyond a whole collection {seconds - collect:+.2f} s, "
                         f"{fraction:.0%} of the whole run's {whole - collect:.2f} s "
                         f"(goal < {GOAL_FRACTION:.0%}: {verdict})")
            print(line)


if __name__ == "__main__":
    main()
