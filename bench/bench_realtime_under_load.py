"""Benchmark: real-time tests on a loaded machine (device protocol PI4, spec/conformance.md QT3).

Run from the repository root::

    python bench/bench_realtime_under_load.py [--burners 2] [--repeat 10] NODEID [NODEID ...]

Starts ``--burners`` CPU burners (each a ``yes`` process writing to /dev/null: one busy core
each, as ``yes >/dev/null &`` in a shell), runs every pytest node id ``--repeat`` times, each run
in a fresh ``python -m pytest`` process, and prints, per node id, the runs that passed, the
wall time of its runs (mean and longest) and the 1-minute load average over them; then the
whole measurement's wall time and load average. The burners are stopped (by their process
ids) however the measurement ends, Ctrl-C and SIGTERM included. A node id may be a file, a directory
(``tests`` runs the suite) or a test; ``--burners 0`` measures the idle figure of the same
runs.

Goal: every run passes (``R of R``) with two burners on a 2-core machine: a real-time verdict
that depends on an idle machine is a defect, and a test that hides one is another (the tests
retry a run the machine could not keep and fail saying so, ``tests/helpers/realtime.py``). The
figure is the passes per node id; the floor is the same runs with ``--burners 0`` (``--baseline``
measures it first, in the same invocation, and prints the loaded-to-idle time ratio).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LOAD_SAMPLE_S = 5.0
"""Period of the load-average samples, s."""


@dataclass
class Figures:
    """The runs of one node id.

    Attributes:
        node: the pytest node id.
        passed: runs that exited 0.
        seconds: wall time of each run, s.
        failures: the last lines of each failed run's output.
    """

    node: str
    passed: int = 0
    seconds: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


class LoadSampler:
    """Samples the 1-minute load average every :data:`LOAD_SAMPLE_S` on a daemon thread."""

    def __init__(self) -> None:
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="load-sampler")

    def _run(self) -> None:
        while True:
            self.samples.append(os.getloadavg()[0])
            if self._stop.wait(LOAD_SAMPLE_S):
                return

    def __enter__(self) -> LoadSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def text(self, since: int = 0) -> str:
        """Mean and highest load average of the samples from index ``since`` on."""
        chosen = self.samples[since:] or [os.getloadavg()[0]]
        return f"load {sum(chosen) / len(chosen):.1f} mean, {max(chosen):.1f} max"


def start_burners(count: int) -> list[subprocess.Popen[bytes]]:
    """``count`` processes that each keep one CPU busy (``yes`` to /dev/null)."""
    burner = shutil.which("yes")
    if count and burner is None:
        raise SystemExit("Error: yes: not found (coreutils); cannot start burners")
    return [subprocess.Popen([str(burner)], stdout=subprocess.DEVNULL) for _ in range(count)]


def stop_burners(burners: list[subprocess.Popen[bytes]]) -> None:
    """Stop each burner by its process id and reap it."""
    for process in burners:
        if process.poll() is None:
            os.kill(process.pid, signal.SIGTERM)
    for process in burners:
        process.wait(10)


def run_node(node: str, timeout_s: float) -> tuple[bool, float, str]:
    """Run one pytest node id in a fresh process group: (passed, wall time in s, output tail).
    The group is killed when the run ends in any way but its own (a timeout, Ctrl-C), so no
    device server or guest it started outlives it."""
    start = time.monotonic()
    process = subprocess.Popen(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", node],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True)
    try:
        out, _ = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        out = f"timed out after {timeout_s:g} s"
    finally:  # the run's group: the run itself if still going, and whatever it left behind
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    tail = "\n".join(out.strip().splitlines()[-6:])
    return process.returncode == 0, time.monotonic() - start, tail


def measure(nodes: list[str], repeat: int, burners: int,
            timeout_s: float) -> tuple[list[Figures], float]:
    """Run every node ``repeat`` times with ``burners`` burners; the figures and wall time."""
    figures = [Figures(node) for node in nodes]
    processes = start_burners(burners)
    start = time.monotonic()
    try:
        for round_number in range(1, repeat + 1):
            for figure in figures:
                passed, seconds, tail = run_node(figure.node, timeout_s)
                figure.seconds.append(seconds)
                figure.passed += passed
                if not passed:
                    figure.failures.append(tail)
                print(f"  [{burners} burners, run {round_number}/{repeat}] {figure.node}: "
                      f"{'pass' if passed else 'FAIL'} in {seconds:.1f} s "
                      f"(load {os.getloadavg()[0]:.1f})", flush=True)
                if not passed:
                    print("    " + tail.replace("\n", "\n    "), flush=True)
    finally:
        stop_burners(processes)
    return figures, time.monotonic() - start


def report(title: str, figures: list[Figures], wall_s: float, load: str, repeat: int) -> None:
    """Print the figures of one measurement."""
    print(f"\n{title}: wall time {wall_s:.0f} s, {load}")
    width = max(len(f.node) for f in figures)
    for f in figures:
        print(f"  {f.node:<{width}}  passed {f.passed:>2} of {repeat}  "
              f"mean {sum(f.seconds) / len(f.seconds):6.1f} s  longest {max(f.seconds):6.1f} s")
        if f.failures:
            print(f"    {len(f.failures)} failed run(s): their output is above")


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns 0 when every run of the loaded measurement passed, else 1."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("nodes", nargs="+", metavar="NODEID", help="pytest node ids to run")
    parser.add_argument("--burners", type=int, default=2, help="CPU burners (default 2)")
    parser.add_argument("--repeat", type=int, default=10, help="runs of each node id")
    parser.add_argument("--timeout", type=float, default=3600.0,
                        help="longest run of one node id, s")
    parser.add_argument("--baseline", action="store_true",
                        help="measure the same runs with no burner first (the floor)")
    args = parser.parse_args(argv)
    if args.burners < 0 or args.repeat < 1:
        parser.error("--burners must be >= 0 and --repeat >= 1")
    # SIGTERM (kill, a CI timeout) and SIGINT stop it the same way, burners and runs included:
    # a shell's background job ignores SIGINT, and a bench stopped by SIGTERM left its two
    # burners running (an orphaned burner loads every later measurement)
    signal.signal(signal.SIGTERM, _interrupt)
    signal.signal(signal.SIGINT, _interrupt)
    print(f"goal: every run passes ({args.repeat} of {args.repeat}) with {args.burners} "
          f"burners on {os.cpu_count()} CPUs")
    with LoadSampler() as sampler:
        idle: tuple[list[Figures], float] | None = None
        if args.baseline:
            first = len(sampler.samples)
            idle = measure(args.nodes, args.repeat, 0, args.timeout)
            report("floor (no burner)", idle[0], idle[1], sampler.text(first), args.repeat)
        first = len(sampler.samples)
        loaded, wall_s = measure(args.nodes, args.repeat, args.burners, args.timeout)
        report(f"{args.burners} burners", loaded, wall_s, sampler.text(first), args.repeat)
    if idle is not None:
        print(f"ratio loaded / floor wall time: {wall_s / max(idle[1], 1e-9):.2f}")
    return 0 if all(f.passed == args.repeat for f in loaded) else 1


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except KeyboardInterrupt as stopped:
        print(f"stopped ({stopped}); burners and runs ended", file=sys.stderr)
        raise SystemExit(130) from None
