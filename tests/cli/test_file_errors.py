"""A file that cannot be read or written is one line naming it and why, written once
(:mod:`hcard.file_errors`): each reader of the command line through it, and no second copy of
the translation anywhere in the four packages."""

from __future__ import annotations

import ast
import pathlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import hcard
from hcard import build
from hcard.cli.main import cli
from hcard.errors import TrackError
from hcard.file_errors import (
    read_failure,
    read_reason,
    reading,
    write_failure,
    write_reason,
    writing,
)
from hcard.physics.profile import DeviceProfile
from hcard.track import straight_stroke, track_to_csv
from tests.helpers.repository import REPO

ROOT = REPO
PACKAGE_DIRS = (ROOT / "hcard", ROOT / "builtin_plugins" / "hcard_builtins",
                ROOT / "reference_device" / "hcard_device",
                ROOT / "conformance" / "hcard_conformance")

LINK_ERRORS = {
    "hcard/device/transports/pyusb_driver.py",
    "hcard/device/transports/usbip_link.py",
    "reference_device/hcard_device/usb/connection.py",
    "reference_device/hcard_device/usb/server.py",
}
"""Modules that describe socket and USB errors (``strerror`` of a link, not of a file)."""


def test_each_kind_of_failure_is_one_line_naming_the_file():
    path = Path("dir/card.hcard")
    assert read_failure(path, FileNotFoundError(2, "No such file or directory")) == (
        "dir/card.hcard: no such file")
    assert read_failure(path, FileNotFoundError(2, "x"), missing="the sidecar") == (
        "dir/card.hcard: no such file (the sidecar)")
    assert read_failure(path, IsADirectoryError(21, "Is a directory"), "a card file") == (
        "dir/card.hcard: is a directory, not a card file")
    assert read_failure(path, PermissionError(13, "Permission denied")) == (
        "dir/card.hcard: cannot read (Permission denied)")
    assert read_failure(path, OSError("device gone")) == "dir/card.hcard: cannot read (device gone)"
    assert read_failure(path, OSError()) == "dir/card.hcard: cannot read (OSError)"
    assert write_failure(path, OSError(28, "No space left on device"), "create") == (
        "dir/card.hcard: cannot create (No space left on device)")
    assert read_reason(IsADirectoryError(21, "x"), "a profile") == "is a directory, not a profile"
    assert write_reason(OSError(28, "No space left on device")) == (
        "cannot write (No space left on device)")


def test_the_blocks_raise_the_callers_error_without_the_os_error(tmp_path):
    missing = tmp_path / "none.csv"
    with pytest.raises(TrackError, match=r"none\.csv: no such file$") as info, \
            reading(missing, TrackError, "a CSV file"):
        missing.read_bytes()
    assert info.value.__cause__ is None and info.value.__suppress_context__
    with pytest.raises(TrackError, match="is a directory, not a CSV file"), \
            reading(tmp_path, TrackError, "a CSV file"):
        raise IsADirectoryError(21, "Is a directory", str(tmp_path))
    with pytest.raises(TrackError, match=r"cannot write \(Read-only file system\)"), \
            writing(missing, TrackError):
        raise OSError(30, "Read-only file system")
    with pytest.raises(ValueError, match="not mine"), reading(missing, TrackError):
        raise ValueError("not mine")  # not about the file system: passed through


@pytest.fixture()
def files(tmp_path) -> dict[str, Path]:
    card = tmp_path / "card.hcard"
    texture = build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv")
    hcard.save(build.card(20.0, 10.0, taxtel_mm=5.0, textures=[texture],
                          texture_index=[0] * 8), card)
    track = tmp_path / "stroke.csv"
    track.write_text(track_to_csv(straight_stroke((1.0, 5.0), (40.0, 0.0), 0.1)))
    profile = tmp_path / "device.json"
    DeviceProfile.coupled_stimulator().save(profile)
    image = tmp_path / "image.png"
    Image.fromarray(np.full((20, 20), 128, dtype=np.uint8)).save(image)
    return {"card": card, "track": track, "profile": profile, "image": image,
            "out": tmp_path / "out.csv"}


READERS = {
    # reader: (the command line, with the file read as {target}; what a directory is not)
    "card": (["info", "{target}"], "a card file"),
    "track": (["render", "{card}", "--track", "{target}", "-o", "{out}"], "a CSV file"),
    "profile": (["render", "{card}", "--track", "{track}", "-o", "{out}", "--profile",
                 "{target}"], "a profile"),
    "image": (["encode", "{target}", "-o", "{out}.hcard"], "an image"),
}


def _run(reader: str, files: dict[str, Path], target: Path):
    args, _ = READERS[reader]
    names = {**{k: str(v) for k, v in files.items()}, "target": str(target)}
    return CliRunner().invoke(cli, [a.format(**names) for a in args])


def _one_line(result) -> str:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), lines
    return lines[0]


@pytest.mark.parametrize("reader", sorted(READERS))
def test_every_reader_names_the_file_and_the_reason(reader, files, tmp_path, monkeypatch):
    missing = tmp_path / "missing.file"
    assert _one_line(_run(reader, files, missing)) == f"Error: {missing}: no such file"
    if reader == "card":  # the reason apart, as hcard validate --json reports it
        report = CliRunner().invoke(cli, ["validate", "--json", str(missing)]).output
        assert '"reason": "no such file"' in report
    folder = tmp_path / "folder"
    folder.mkdir()
    assert _one_line(_run(reader, files, folder)) == (
        f"Error: {folder}: is a directory, not {READERS[reader][1]}")

    target = files[reader]
    opened = pathlib.Path.open

    def refused(self, *args, **kwargs):
        if self == target:
            raise PermissionError(13, "Permission denied", str(self))
        return opened(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "open", refused)  # the tests may run as root
    assert _one_line(_run(reader, files, target)) == (
        f"Error: {target}: cannot read (Permission denied)")


def test_a_write_that_fails_names_the_file(files, tmp_path):
    result = CliRunner().invoke(cli, ["preview", str(files["card"]), "-o",
                                      str(tmp_path / "no-such-dir" / "p.png")])
    line = _one_line(result)
    assert line.startswith(f"Error: {tmp_path / 'no-such-dir' / 'p.png'}: cannot write (")


def _translations(path: Path) -> list[str]:
    """Where ``path`` translates an OSError itself: reads its ``strerror`` or catches
    ``FileNotFoundError`` or ``IsADirectoryError`` by name."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Attribute) and node.attr == "strerror":
            found.append(f"line {node.lineno}: .strerror")
        if isinstance(node, ast.ExceptHandler) and node.type is not None:
            names = {n.id for n in ast.walk(node.type) if isinstance(n, ast.Name)}
            for name in sorted(names & {"FileNotFoundError", "IsADirectoryError"}):
                found.append(f"line {node.lineno}: except {name}")
    return found


def test_file_errors_are_translated_in_one_module():
    copies = {}
    for folder in PACKAGE_DIRS:
        for path in sorted(folder.rglob("*.py")):
            name = path.relative_to(ROOT).as_posix()
            if name == "hcard/file_errors.py" or name in LINK_ERRORS:
                continue
            if found := _translations(path):
                copies[name] = found
    assert copies == {}, "use hcard.file_errors.reading/writing instead"
