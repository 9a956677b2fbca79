"""Saving (hcard.atomic): the rename reaches the disk (the directory is flushed), a killed
writer's temporary file does not survive it forever, a symbolic link stays a link, and an
encode whose preview fails keeps the previous card."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from hcard import card_io
from hcard.atomic import STALE_AFTER_S, remove_stale_temporaries, write_atomically
from hcard.cli.main import cli
from hcard.errors import CardError


def _dead_pid() -> int:
    """The pid of a process that has exited."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_the_directory_is_flushed_after_the_rename(tmp_path: Path, monkeypatch) -> None:
    flushed: list[int] = []
    real_fsync = os.fsync

    def recording_fsync(fd: int) -> None:
        flushed.append(stat.S_IFMT(os.fstat(fd).st_mode))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", recording_fsync)
    write_atomically(tmp_path / "card.hcard", b"abc")
    assert flushed == [stat.S_IFREG, stat.S_IFDIR]  # the data, then the directory's entry
    assert (tmp_path / "card.hcard").read_bytes() == b"abc"


def test_a_killed_writers_temporary_file_is_removed_by_the_next_write(tmp_path: Path) -> None:
    target = tmp_path / "card.hcard"
    dead = _dead_pid()
    old = time.time() - 2 * STALE_AFTER_S
    leftovers = {
        "stale": tmp_path / f".card.hcard.{dead}.k3j2h1ab.tmp",
        "fresh": tmp_path / f".card.hcard.{dead}.q9w8e7rt.tmp",  # its writer may be starting
        "alive": tmp_path / f".card.hcard.{os.getppid()}.z1x2c3vb.tmp",  # a running writer
        "other": tmp_path / f".other.hcard.{dead}.k3j2h1ab.tmp",  # another file's
    }
    for path in leftovers.values():
        path.write_bytes(b"partial")
    for name in ("stale", "alive", "other"):
        os.utime(leftovers[name], (old, old))
    write_atomically(target, b"new")
    assert not leftovers["stale"].exists()
    assert all(leftovers[name].exists() for name in ("fresh", "alive", "other"))
    assert target.read_bytes() == b"new"
    assert remove_stale_temporaries(target, now=time.time() + 2 * STALE_AFTER_S) == [
        leftovers["fresh"]]


def test_a_writer_killed_mid_write_leaves_the_old_file_and_a_removable_leftover(
        tmp_path: Path) -> None:
    """kill -9 between the temporary file and the rename: the target keeps its old bytes."""
    target = tmp_path / "card.hcard"
    target.write_bytes(b"old")
    script = (
        "import os, sys, tempfile\n"
        "import hcard.atomic as a\n"
        "def stop(*args, **kwargs):\n"
        "    os.kill(os.getpid(), 9)\n"
        "a.os.replace = stop\n"
        f"a.write_atomically({str(target)!r}, b'new' * 1000)\n"
    )
    killed = subprocess.run([sys.executable, "-c", script], check=False)
    assert killed.returncode == -9
    (leftover,) = tmp_path.glob(".card.hcard.*.tmp")
    assert target.read_bytes() == b"old"
    assert remove_stale_temporaries(target, now=time.time() + 2 * STALE_AFTER_S) == [leftover]


def test_a_symbolic_link_stays_a_link_and_its_file_is_replaced(tmp_path: Path) -> None:
    real = tmp_path / "cards" / "real.hcard"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.hcard"
    link.symlink_to(real)
    write_atomically(link, b"new")
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_bytes() == b"new"
    dangling = tmp_path / "dangling.hcard"
    dangling.symlink_to(tmp_path / "cards" / "later.hcard")
    write_atomically(dangling, b"made")
    assert dangling.is_symlink()
    assert (tmp_path / "cards" / "later.hcard").read_bytes() == b"made"


def test_an_encode_whose_preview_fails_keeps_the_previous_card(tmp_path: Path,
                                                               monkeypatch) -> None:
    image = tmp_path / "in.png"
    Image.fromarray((np.indices((40, 40)).sum(axis=0) % 2 * 255).astype(np.uint8)).save(image)
    card = tmp_path / "out.hcard"
    runner = CliRunner()
    first = runner.invoke(cli, ["encode", str(image), "-o", str(card), "--width-mm", "40"])
    assert first.exit_code == 0, first.output
    before = card.read_bytes()
    import hcard.preview.picture

    def broken_figure(*args, **kwargs):
        raise CardError("the preview cannot be drawn (injected)")

    monkeypatch.setattr(hcard.preview.picture, "preview_figure", broken_figure)
    failed = runner.invoke(cli, ["encode", str(image), "-o", str(card), "--width-mm", "20",
                                 "--preview", str(tmp_path / "p.png")])
    assert failed.exit_code == 1
    assert "the preview cannot be drawn" in failed.output
    assert card.read_bytes() == before
    assert card_io.load(card).surface.width_mm == pytest.approx(40.0)
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("name", ["card.png", "card.JPG", "card.tiff"])
def test_encode_refuses_to_write_a_card_under_an_image_name(tmp_path: Path, name: str) -> None:
    image = tmp_path / "in.png"
    Image.fromarray(np.zeros((8, 8), dtype=np.uint8)).save(image)
    result = CliRunner().invoke(cli, ["encode", str(image), "-o", str(tmp_path / name)])
    assert result.exit_code == 2
    assert "a card is not an image" in result.output and "--preview" in result.output
    assert not (tmp_path / name).exists()


def test_encode_writes_the_card_to_standard_output_and_the_summary_to_stderr(
        tmp_path: Path) -> None:
    image = tmp_path / "in.png"
    Image.fromarray((np.indices((40, 40)).sum(axis=0) % 2 * 255).astype(np.uint8)).save(image)
    result = CliRunner().invoke(cli, ["encode", str(image), "-o", "-", "--width-mm", "40"])
    assert result.exit_code == 0, result.output
    card = card_io.card_from_bytes(result.stdout_bytes)
    assert card.surface.width_mm == pytest.approx(40.0)
    assert "wrote       <stdout> (binary" in result.stderr
    assert not Path("-").exists()
    piped = CliRunner().invoke(cli, ["info", "-"], input=result.stdout_bytes)
    assert piped.exit_code == 0 and "surface: 40 x 40 mm" in piped.stdout
