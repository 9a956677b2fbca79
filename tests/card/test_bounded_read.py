"""Files that are not regular files (a device, a FIFO) are read up to the format's limit, never
until memory runs out: ``hcard validate /dev/zero`` and ``render --track /dev/zero`` ended in
MemoryError tracebacks."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest
from click.testing import CliRunner

import hcard
from hcard import csv_rows, limits
from hcard.bounded_read import InputTooLarge, read_bounded
from hcard.calibration.measurement import MeasurementError, read_measurement
from hcard.card_io import to_bytes
from hcard.cli.main import cli
from hcard.errors import CardError
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_error import ProfileError
from hcard.track import TrackError, read_track_csv
from tests.helpers.cards import two_texture_card

ZERO = Path("/dev/zero")
needs_dev_zero = pytest.mark.skipif(not ZERO.exists(), reason="no /dev/zero on this system")


def fifo_offering(path: Path, payload: bytes) -> Path:
    """A FIFO at ``path`` whose writer (a thread) offers ``payload`` and closes."""
    os.mkfifo(path)

    def write() -> None:
        try:
            with path.open("wb") as pipe:
                pipe.write(payload)
        except BrokenPipeError:  # the reader stopped at its limit and closed
            pass

    threading.Thread(target=write, daemon=True).start()
    return path


def test_a_regular_file_over_the_limit_is_refused_with_its_size(tmp_path):
    file = tmp_path / "big.bin"
    file.write_bytes(b"x" * 1001)
    with pytest.raises(InputTooLarge) as caught:
        read_bounded(file, 1000)
    assert (caught.value.size, caught.value.limit) == (1001, 1000)
    assert "1001 bytes exceed the limit of 1000 bytes" in str(caught.value)
    file.write_bytes(b"x" * 1000)
    assert len(read_bounded(file, 1000)) == 1000


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_a_fifo_is_read_up_to_the_limit_and_no_further(tmp_path):
    assert read_bounded(fifo_offering(tmp_path / "short", b"a" * 500), 1000) == b"a" * 500
    with pytest.raises(InputTooLarge) as caught:
        read_bounded(fifo_offering(tmp_path / "long", b"b" * 5000), 1000)
    assert caught.value.size is None
    assert "not a regular file" in str(caught.value)


def test_a_directory_is_not_read(tmp_path):
    with pytest.raises(IsADirectoryError):
        read_bounded(tmp_path, 1000)


@needs_dev_zero
def test_dev_zero_as_a_card_is_a_one_line_error_within_the_card_limit():
    with pytest.raises(CardError) as caught:
        hcard.load(ZERO)
    message = str(caught.value)
    assert message.startswith("/dev/zero: ")
    assert f"more than {limits.MAX_CARD_BYTES} bytes" in message and "rule F6" in message


@needs_dev_zero
@pytest.mark.parametrize("command", [["validate"], ["info"], ["render", "--track"]])
def test_the_cli_refuses_dev_zero_without_a_traceback(command, tmp_path, monkeypatch):
    monkeypatch.setattr(csv_rows, "MAX_TEXT_FILE_BYTES", 1 << 20)  # keep the test's memory low
    if command[0] == "render":
        card = tmp_path / "card.hcard"
        card.write_bytes(to_bytes(two_texture_card()))
        args = ["render", str(card), "--track", str(ZERO), "-o", str(tmp_path / "out.csv")]
    else:
        args = [*command, str(ZERO)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output
    assert "/dev/zero" in result.output and "not a regular file" in result.output


@needs_dev_zero
def test_a_track_a_measurement_a_sidecar_and_a_profile_from_dev_zero(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_rows, "MAX_TEXT_FILE_BYTES", 1 << 20)
    with pytest.raises(TrackError, match=r"/dev/zero: more than 1048576 bytes"):
        read_track_csv(ZERO)
    with pytest.raises(MeasurementError, match=r"/dev/zero: more than 1048576 bytes"):
        read_measurement(ZERO)
    with pytest.raises(ProfileError, match=r"/dev/zero: more than 16777216 bytes"):
        DeviceProfile.load(ZERO)
    # a sidecar that is a device: the CSV is fine, its conditions are not
    csv = tmp_path / "rec.csv"
    csv.write_text("t_s,amplitude_um,fn_n,fl_n\n0,1,0.5,0.1\n0.001,1,0.5,0.1\n")
    sidecar = tmp_path / "rec.csv.json"
    sidecar.symlink_to(ZERO)
    with pytest.raises(MeasurementError, match=r"rec\.csv\.json: more than 16777216 bytes"):
        read_measurement(csv)
    sidecar.unlink()
    sidecar.write_text(json.dumps({"device": "tribometer"}))
    assert len(read_measurement(csv).t) == 2
