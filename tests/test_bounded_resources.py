"""Bounded time and memory on hostile input (spec/README.md section 4, "Bounds"): every card
command on a card under the 16 MiB limit finishes within :data:`TIME_BOUND_S` and peaks under
``MEMORY_PER_INPUT_BYTE`` x the input size + :data:`MEMORY_CONSTANT_MB`, with one clear error,
whatever the card's structure; measured in a fresh process as a user runs it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from hostile_cards import HOSTILE_CARDS

from hcard import limits

TIME_BOUND_S = 20.0
"""Longest a card command may take on any card under the size limit, s (a shared CI machine;
measured 0.6-2.6 s here)."""
MEMORY_PER_INPUT_BYTE = 32
"""Peak memory per byte of input a card command may use beyond the constant (measured: 460-590
MB on the 16 MiB hostile cards, most of it the protobuf runtime's 8.4 million message
objects)."""
MEMORY_CONSTANT_MB = 250
"""Memory a card command may use whatever the input, MB (the interpreter, numpy, protobuf)."""

_RUN = (
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
    and what it wrote to stderr."""
    done = subprocess.run([sys.executable, "-c", _RUN, *args], capture_output=True, text=True,
                          timeout=4 * TIME_BOUND_S, check=False)
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


@pytest.fixture(scope="module")
def hostile(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("hostile")
    paths = {}
    for name, build_card in HOSTILE_CARDS.items():
        data = build_card()
        assert len(data) <= limits.MAX_CARD_BYTES
        paths[name] = directory / f"{name}.hcard"
        paths[name].write_bytes(data)
    return paths


@pytest.mark.parametrize("name", sorted(HOSTILE_CARDS))
@pytest.mark.parametrize("command", ["validate", "info", "render"])
def test_a_hostile_card_gets_a_bounded_refusal(hostile: dict[str, Path], name: str,
                                               command: str, tmp_path: Path) -> None:
    path = hostile[name]
    args = [command, str(path)]
    if command == "render":
        track = tmp_path / "track.csv"
        track.write_text("t_s,x_mm,y_mm\n0,1,5\n0.1,3,5\n0.2,5,5\n")
        args += ["--track", str(track), "-o", str(tmp_path / "out.csv")]
    measured, stderr = run_measured(*args)
    assert measured["code"] == 1, stderr[-2000:]
    assert "Traceback" not in stderr
    assert len(stderr) < 20_000  # a bounded report: listed problems and counts by rule
    assert str(path) in stderr
    assert measured["seconds"] < TIME_BOUND_S
    bound_kb = (MEMORY_PER_INPUT_BYTE * path.stat().st_size) / 1024 + MEMORY_CONSTANT_MB * 1024
    assert measured["peak_kb"] < bound_kb, (measured, bound_kb)
