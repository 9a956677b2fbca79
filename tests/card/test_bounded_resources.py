"""Bounded time and memory on hostile input (spec/README.md section 4, "Bounds"): every card
command on a card under the 16 MiB limit, binary or JSON, finishes with one clear error within
:data:`TIME_BOUND_S` of CPU and :data:`MEMORY_PER_INPUT_BYTE` x the input size +
:data:`MEMORY_CONSTANT_MB` of memory, whatever the card's structure. The bound itself is what
is tested: the command runs in a fresh process whose CPU time and address space are limited to
the bound (``resource.setrlimit``), so a command past it is killed (SIGXCPU) or fails to
allocate, and its exit status is then not 1. bench/bench_hostile_inputs.py prints the figures.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from hcard import limits
from tests.helpers.hostile_cards import HOSTILE_CARDS

TIME_BOUND_S = 20
"""Most CPU time a card command may take on any card under the size limit, s (spec/README.md
section 4)."""
MEMORY_PER_INPUT_BYTE = 32
"""Memory per byte of input a card command may use beyond the constant (spec/README.md
section 4)."""
MEMORY_CONSTANT_MB = 250
"""Memory a card command may use whatever the input, MB (the interpreter, numpy, protobuf)."""
MB = 1024 * 1024

_RUN = "import sys; from hcard.cli.main import main; main(sys.argv[1:])"
_MEASURED = (
    "import json, resource, sys, time\n"
    "from hcard.cli.main import cli\n"
    "start = time.perf_counter()\n"
    "try:\n"
    "    cli.main(args=sys.argv[1:], prog_name='hcard')\n"
    "except SystemExit as exc:\n"
    "    code = exc.code if isinstance(exc.code, int) else 1\n"
    "else:\n"
    "    code = 0\n"
    "sys.stderr.flush()\n"
    "print(json.dumps({'code': code, 'seconds': time.perf_counter() - start,\n"
    "                  'peak_kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}),\n"
    "      file=sys.__stdout__)\n"
)


def run_measured(*args: str) -> tuple[dict, str]:
    """Run ``hcard ARGS`` in a fresh interpreter; its exit code, time and peak memory (KiB),
    and what it wrote to stderr (for tests that compare two runs' memory)."""
    done = subprocess.run([sys.executable, "-c", _MEASURED, *args], capture_output=True,
                          text=True, timeout=4 * TIME_BOUND_S, check=False)
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def run_bounded(args: list[str], input_bytes: int) -> subprocess.CompletedProcess[str]:
    """``hcard ARGS`` in a fresh interpreter limited to the spec's bounds for an input of
    ``input_bytes``: CPU time and address space (virtual memory, which is at least the
    resident memory the spec bounds)."""
    memory = MEMORY_PER_INPUT_BYTE * input_bytes + MEMORY_CONSTANT_MB * MB

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_CPU, (TIME_BOUND_S, TIME_BOUND_S))
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    # one BLAS thread: each thread reserves address space that is never used here
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-c", _RUN, *args], capture_output=True, text=True,
                          timeout=6 * TIME_BOUND_S, check=False, preexec_fn=limit, env=env)


@pytest.fixture(scope="module")
def hostile(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("hostile")
    paths = {}
    for name, build_card in HOSTILE_CARDS.items():
        data = build_card()
        assert len(data) <= limits.MAX_CARD_BYTES
        suffix = ".json" if name.startswith("json-") else ".hcard"
        paths[name] = directory / f"{name}{suffix}"
        paths[name].write_bytes(data)
    return paths


COMMANDS = ["validate", "info", "render", "preview"]
CASES = [(command, name) for command in COMMANDS for name in sorted(HOSTILE_CARDS)
         if command != "preview" or name.startswith("json-")]
"""Each command on each hostile card; preview reads a card as render does, so it runs on the
JSON cards only, the slow ones to read."""


@pytest.mark.parametrize(("command", "name"), CASES)
def test_a_hostile_card_gets_a_bounded_refusal(hostile: dict[str, Path], name: str,
                                               command: str, tmp_path: Path) -> None:
    path = hostile[name]
    args = [command, str(path)]
    if command == "render":
        track = tmp_path / "track.csv"
        track.write_text("t_s,x_mm,y_mm\n0,1,5\n0.1,3,5\n0.2,5,5\n")
        args += ["--track", str(track), "-o", str(tmp_path / "out.csv")]
    if command == "preview":
        args += ["-o", str(tmp_path / "out.png")]
    done = run_bounded(args, path.stat().st_size)
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    assert "Traceback" not in done.stderr
    assert len(done.stderr) < 20_000  # a bounded report: listed problems and counts by rule
    assert len(done.stdout) < 40_000  # info: at most 1024 characters of a text are shown
    assert str(path) in done.stderr
