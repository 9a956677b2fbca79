"""Files that belong together are replaced together (hcard/atomic.py ``atomic_outputs``): a card
and its preview (``hcard encode --preview``), a recording's CSV and its sidecar (``hcard play``,
spec/measurement-format.md MF11). A failure while either is written or renamed keeps both old
files. On main ``encode`` replaced the card before a preview that a full disk refused, and
``play`` replaced the CSV before a sidecar that could not be written."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from hcard import atomic, card_io
from hcard.cli.main import cli


def _image(path: Path) -> Path:
    rows, cols = np.indices((120, 160))
    Image.fromarray(((np.sin(rows / 3.0) * np.cos(cols / 5.0) + 1) * 127).astype(np.uint8)).save(
        path)
    return path


def test_encode_on_a_disk_that_refuses_the_preview_keeps_the_old_card_and_preview(
        tmp_path: Path) -> None:
    image, card, preview = _image(tmp_path / "in.png"), tmp_path / "out.hcard", tmp_path / "p.png"
    first = CliRunner().invoke(cli, ["encode", str(image), "-o", str(card), "--width-mm", "40",
                                     "--preview", str(preview)])
    assert first.exit_code == 0, first.output
    old_card, old_preview = card.read_bytes(), preview.read_bytes()
    # The second encode runs where no file may grow past a size between the card's and the
    # preview's: the kernel refuses the preview's bytes (EFBIG), as a full disk refuses them
    # (ENOSPC), after the card's were written.
    limit = (len(old_card) + len(old_preview)) // 2
    assert len(old_card) * 2 < limit < len(old_preview)

    def small_files() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failed write, not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    done = subprocess.run(
        [sys.executable, "-c", "import sys; from hcard.cli.main import main; main(sys.argv[1:])",
         "encode", str(image), "-o", str(card), "--width-mm", "20", "--preview", str(preview)],
        capture_output=True, text=True, preexec_fn=small_files, check=False, timeout=120)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.startswith(f"Error: {card}: cannot write the card and its preview (File "
                                  "too large)")
    assert card.read_bytes() == old_card
    assert card_io.load(card).surface.width_mm == pytest.approx(40.0)
    assert preview.read_bytes() == old_preview
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.png", "out.hcard", "p.png"]


def _failing_replace(monkeypatch: pytest.MonkeyPatch, suffix: str) -> None:
    """``os.replace`` in hcard.atomic fails for a target whose name ends in ``suffix``."""
    real = os.replace

    def replace(source: str, target: str | os.PathLike[str]) -> None:
        if str(target).endswith(suffix) and not str(source).endswith("-old.tmp"):
            raise OSError(28, "No space left on device")
        real(source, target)

    monkeypatch.setattr(atomic.os, "replace", replace)


def test_play_that_cannot_write_the_sidecar_keeps_the_old_csv_and_sidecar(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from hcard import build

    card = tmp_path / "card.hcard"
    card_io.save(build.card(20.0, 10.0, taxtel_mm=10.0,
                            textures=[build.texture(0.5, channel="uv")]), card)
    track = tmp_path / "track.csv"
    track.write_text("t_s,x_mm,y_mm\n" + "".join(f"{i * 0.02!r},{2 + i * 0.2!r},5\n"
                                                   for i in range(20)))
    recording = tmp_path / "rec.csv"
    args = ["play", str(card), "--device", "sim://evita", "--track", str(track), "-o",
            str(recording)]
    first = CliRunner().invoke(cli, args)
    assert first.exit_code == 0, first.output
    sidecar = tmp_path / "rec.csv.json"
    old_csv, old_sidecar = recording.read_bytes(), sidecar.read_bytes()
    track.write_text(track.read_text() + "0.4,6,5\n")  # another session: another recording
    _failing_replace(monkeypatch, ".csv.json")
    failed = CliRunner().invoke(cli, args)
    assert failed.exit_code == 1
    assert "Traceback" not in failed.output
    assert failed.output.startswith(f"Error: {recording}: cannot write (No space left on device)")
    assert recording.read_bytes() == old_csv
    assert sidecar.read_bytes() == old_sidecar
    assert sorted(p.name for p in tmp_path.iterdir()) == ["card.hcard", "rec.csv",
                                                          "rec.csv.json", "track.csv"]


def test_a_pair_is_written_whole_or_not_at_all(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    first, second, third = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    first.write_bytes(b"old a")
    atomic.write_atomically_together([(first, b"new a"), (second, b"new b")])
    assert (first.read_bytes(), second.read_bytes()) == (b"new a", b"new b")
    # the third rename fails: the two before it are undone, the new file c never appears
    _failing_replace(monkeypatch, "/c")
    with pytest.raises(OSError, match="No space left"):
        atomic.write_atomically_together([(first, b"newer a"), (second, b"newer b"),
                                          (third, b"c")])
    assert (first.read_bytes(), second.read_bytes()) == (b"new a", b"new b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]
    # an exception while the files are written: nothing changes, no temporary is left
    with pytest.raises(RuntimeError), atomic.atomic_outputs([first, third]) as (one, _):
        one.write(b"half")
        raise RuntimeError("the writer failed")
    assert first.read_bytes() == b"new a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]
