"""Spill folders of ``hcard render -o X.npz`` (hcard/render/output.py) are cleaned: a writer
killed with ``kill -9`` leaves ``.X.npz.PID.XXXXXXXX.spill/``, and the next NPZ writer to the
same output removes it once its process is gone and nothing in it has changed for
``STALE_AFTER_S``. On main the folders (``.X.npz.XXXXXXXX/``, no PID) were never removed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from hcard import build, card_io
from hcard.atomic import STALE_AFTER_S
from hcard.cli.main import cli
from hcard.render.output import frame_writer, remove_stale_spills

_HCARD = "import sys; from hcard.cli.main import main; main(sys.argv[1:])"


def _files(tmp_path: Path, seconds: float) -> tuple[Path, Path]:
    card = tmp_path / "card.hcard"
    card_io.save(build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(0.5, channel="uv", components=[build.spatial(1.0, 0.2)])]), card)
    track = tmp_path / f"track{seconds:g}.csv"
    t = np.arange(0.0, seconds, 0.02)
    x = 2.0 + (t * 10.0) % 16.0  # back and forth across the card at 10 mm/s
    track.write_text("t_s,x_mm,y_mm\n" + "".join(
        f"{a!r},{b!r},5\n" for a, b in zip(t.tolist(), x.tolist(), strict=True)))
    return card, track


def _spills(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.name.endswith(".spill"))


def test_a_killed_renders_spill_folder_is_removed_by_the_next_render(tmp_path: Path) -> None:
    card, long_track = _files(tmp_path, 600.0)  # 6 million frames: seconds of work
    out = tmp_path / "frames.npz"
    writer = subprocess.Popen([sys.executable, "-c", _HCARD, "render", str(card), "--track",
                               str(long_track), "-o", str(out)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:  # until the spill files hold data
            spilled = [f for folder in _spills(tmp_path) for f in folder.iterdir()]
            if spilled and all(f.stat().st_size > 0 for f in spilled):
                break
            assert writer.poll() is None, "the rendering ended before it was killed"
            time.sleep(0.05)
        else:
            raise AssertionError("no spill folder with data appeared")
        writer.send_signal(signal.SIGKILL)
        writer.wait(timeout=30)
    finally:
        if writer.poll() is None:
            writer.kill()
    (left,) = _spills(tmp_path)
    assert left.name.startswith(f".frames.npz.{writer.pid}.")
    assert not out.exists()
    # A render right after the kill keeps it: its files changed less than STALE_AFTER_S ago.
    _, short_track = _files(tmp_path, 1.0)
    args = ["render", str(card), "--track", str(short_track), "-o", str(out)]
    assert CliRunner().invoke(cli, args).exit_code == 0
    assert _spills(tmp_path) == [left]
    # Once they are older, the next render to the same output removes it.
    old = time.time() - 2 * STALE_AFTER_S
    for path in [*left.iterdir(), left]:
        os.utime(path, (old, old))
    assert CliRunner().invoke(cli, args).exit_code == 0
    assert _spills(tmp_path) == []
    # samples 0 .. 0.98 s: 0.98 s at 10 kHz, the frames at both ends included (rule R3)
    assert np.load(out)["t_s"].size == 9801


def test_a_live_writers_spill_folder_and_other_outputs_folders_are_kept(tmp_path: Path) -> None:
    out = tmp_path / "x.npz"
    old = time.time() - 2 * STALE_AFTER_S
    mine = tmp_path / f".x.npz.{os.getpid()}.abcd1234.spill"
    other = tmp_path / ".y.npz.999999999.abcd1234.spill"  # a dead PID, another output
    for folder in (mine, other):
        folder.mkdir()
        os.utime(folder, (old, old))
    assert remove_stale_spills(out) == []
    with frame_writer(out) as writer:
        writer.write([("t_s", np.zeros(3))])
    assert sorted(p.name for p in tmp_path.iterdir()) == [mine.name, other.name, "x.npz"]
