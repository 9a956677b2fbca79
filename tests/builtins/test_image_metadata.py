"""The surface an image encodes to does not hang on metadata Pillow makes up, and no stored
or given resolution makes the encoder's work unbounded (a 271-byte PNG storing 150,000
dpi took 7.8 GB)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from hcard.cli.main import cli
from hcard.errors import ImageError
from hcard_builtins.image import load_gray
from hcard_builtins.image.geometry import MAX_DPI, resolve_geometry
from tests.card.test_bounded_resources import run_measured

CHECKER = (np.indices((64, 48)).sum(axis=0) % 2 * 255).astype(np.uint8)  # 48 wide, 64 high


def saved(path: Path, **options) -> Path:
    Image.fromarray(CHECKER).save(path, **options)
    return path


def encoded_width_mm(path: Path, *args: str) -> float:
    result = CliRunner().invoke(cli, ["encode", str(path), "-o", str(path.with_suffix(".hcard")),
                                      "--json", *args])
    assert result.exit_code == 0, result.output
    import json

    return json.loads(result.stdout)["width_mm"]


def test_a_resolution_pillow_invents_is_not_taken_for_the_files(tmp_path: Path) -> None:
    exif = Image.Exif()
    exif[0x010F] = "camera"
    cases = {
        "exif.jpg": ({"exif": exif.tobytes()}, 48 * 0.1),  # Pillow: 72 dpi; the file: none
        "jfif.jpg": ({"dpi": (300, 300)}, 48 * 25.4 / 300),  # JFIF density in dots per inch
        "plain.tif": ({}, 48 * 0.1),  # Pillow: 1 dpi; the file: no resolution unit
        "inch.tif": ({"dpi": (300, 300)}, 48 * 25.4 / 300),
        "metre.png": ({"dpi": (300, 300)}, 48 * 25.4 / 300),  # pHYs in pixels per metre
    }
    for name, (options, width) in cases.items():
        assert encoded_width_mm(saved(tmp_path / name, **options)) == pytest.approx(
            width, rel=1e-3), name


def test_a_stored_resolution_out_of_range_is_reported_and_not_used(tmp_path: Path) -> None:
    path = saved(tmp_path / "fine.png", dpi=(150_000, 150_000))
    image = load_gray(path)
    geometry = resolve_geometry(image.width, image.height, taxtel_mm=5.0,
                              embedded_dpi=image.dpi, source=path)
    assert geometry.width_mm == pytest.approx(4.8)
    assert "the image stores 150000 x 150000 dpi, outside 10-25400" in geometry.size_source
    measured, stderr = run_measured("encode", str(path), "-o", str(tmp_path / "fine.hcard"))
    assert measured["code"] == 0, stderr
    assert measured["peak_kb"] < 1024 * 1024  # 7.8 GB before the tile bound


@pytest.mark.parametrize(("option", "value", "named"), [
    ("--dpi", "1e6", "from --dpi 1e+06"),
    ("--width-mm", "0.01", "from --width-mm"),
])
def test_a_given_resolution_finer_than_the_limit_is_one_clear_error(
        tmp_path: Path, option: str, value: str, named: str) -> None:
    path = saved(tmp_path / "g.png")
    result = CliRunner().invoke(cli, ["encode", str(path), "-o", str(tmp_path / "g.hcard"),
                                      option, value])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert named in result.output and f"({MAX_DPI:g} dpi)" in result.output
    with pytest.raises(ImageError, match="finer than the 1 um"):
        resolve_geometry(48, 64, taxtel_mm=5.0, dpi=float(value) if option == "--dpi" else None,
                       width_mm=float(value) if option == "--width-mm" else None)
