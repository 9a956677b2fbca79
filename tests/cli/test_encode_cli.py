"""``hcard encode``: summary, output forms, options, and one-line errors for bad input."""

from __future__ import annotations

import functools
import json
import struct
import zlib
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import hcard
from hcard import limits
from hcard.cli import encode_cmd
from hcard.cli.main import cli
from hcard.v1 import card_pb2 as pb
from hcard_builtins.image import DEFAULT_MAX_PIXELS
from tests.helpers.cli import assert_one_line_error, run_hcard
from tests.helpers.repository import REPO


def grating_png(path: Path, width: int = 300, height: int = 200, period: float = 1.25) -> Path:
    """A 0.1 mm-per-pixel grating along x, 0.4 deep around mid gray."""
    x = (np.arange(width) + 0.5) * 0.1
    row = 0.5 - 0.4 * np.cos(2 * np.pi * x / period)
    gray = np.tile(row, (height, 1))
    Image.fromarray(np.round(gray * 255).astype(np.uint8)).save(path)
    return path


def png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG file written by hand that declares ``width`` x ``height`` and holds no pixels."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(b""))
        + chunk(b"IEND", b"")
    )
    return path


run = functools.partial(run_hcard, "encode")
"""``hcard encode ARGS``."""


# ---------------------------------------------------------------------------------------------
# Success


def test_encode_prints_the_summary_and_writes_a_binary_card(tmp_path: Path):
    image = grating_png(tmp_path / "stripes.png")
    out = tmp_path / "stripes.hcard"
    result = run(image, "-o", out)
    assert result.exit_code == 0, result.output
    assert result.stderr == ""  # small image: no progress lines
    card = hcard.load(out)
    assert not out.read_bytes().lstrip().startswith(b"{")
    assert (card.grid.cols, card.grid.rows) == (6, 4)
    assert len(card.textures) == 1
    (component,) = card.textures[0].components
    assert 1.0 / component.frequency == pytest.approx(1.25, rel=0.02)
    assert component.amplitude == pytest.approx(0.4 * 0.7, rel=0.05)
    assert card.metadata.title == "stripes"
    text = result.stdout
    assert "300 x 200 pixels" in text
    assert "30 x 20 mm" in text
    assert "pixel pitch 0.1 x 0.1 mm" in text
    assert "assumed 254 dpi" in text
    assert "grid        6 x 4 taxtels of 5 mm" in text
    assert "textures    1 in the palette" in text
    assert "components  1 in total" in text
    size = out.stat().st_size
    assert f"card size   {size} bytes (binary)" in text
    assert "raw 8-bit bitmap at 0.1 mm: 60000 bytes" in text
    assert "error       rms " in text and "x the 0.08 friction JND" in text
    assert f"wrote       {out} (binary, {size} bytes)" in text


def test_json_output_and_json_summary(tmp_path: Path):
    image = grating_png(tmp_path / "g.png")
    out = tmp_path / "g.hcard.json"
    result = run(image, "-o", out, "--json", "--taxtel-mm", "2.5", "--channel", "bipolar")
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["grid"]["cols"] == 12
    card = hcard.load(out)
    assert card.textures[0].channel == pb.CHANNEL_BIPOLAR
    summary = json.loads(result.stdout)
    assert summary["output_format"] == "json"
    assert summary["output_bytes"] == out.stat().st_size
    assert (summary["cols"], summary["rows"], summary["textures"]) == (12, 8, 1)
    assert summary["components"] == 1
    assert summary["card_bytes"] == len(hcard.dumps(card))
    assert summary["raw_bitmap_bytes"] == 300 * 200
    assert summary["friction_range"] == [0.5, 1.5]
    assert summary["rms_error_jnd"] == pytest.approx(
        summary["rms_error"] / limits.RELATIVE_FRICTION_JND
    )
    assert summary["rms_error"] < 0.01
    assert summary["max_error"] >= summary["rms_error"]


def test_size_metadata_and_range_options(tmp_path: Path):
    image = grating_png(tmp_path / "g.png")
    out = tmp_path / "g.hcard"
    result = run(
        image,
        "-o",
        out,
        "--width-mm",
        "60",
        "--components",
        "2",
        "--max-textures",
        "3",
        "--min-amplitude",
        "0.02",
        "--merge-tolerance",
        "0.01",
        "--channel",
        "ev",
        "--friction-range",
        "1.1",
        "1.5",
        "--locking",
        "velocity",
        "--title",
        "Ribs",
        "--author",
        "Ada",
        "--licence",
        "CC-BY-4.0",
    )
    assert result.exit_code == 0, result.output
    card = hcard.load(out)
    assert (card.surface.width_mm, card.surface.height_mm) == pytest.approx((60.0, 40.0))
    assert (card.metadata.title, card.metadata.author, card.metadata.licence) == (
        "Ribs",
        "Ada",
        "CC-BY-4.0",
    )
    texture = card.textures[0]
    assert texture.channel == pb.CHANNEL_EV and texture.locking == pb.LOCKING_VELOCITY
    assert texture.baseline == pytest.approx(1.3, abs=0.01)
    assert 1.0 / texture.components[0].frequency == pytest.approx(2.5, rel=0.02)
    assert texture.components[0].amplitude == pytest.approx(0.4 * 0.4, rel=0.05)
    assert "black = 1.5, white = 1.1" in result.stdout


def test_dpi_option(tmp_path: Path):
    image = grating_png(tmp_path / "g.png")
    out = tmp_path / "g.hcard"
    result = run(image, "-o", out, "--dpi", "127")
    assert result.exit_code == 0, result.output
    assert hcard.load(out).surface.width_mm == pytest.approx(60.0)
    assert "from --dpi 127" in result.stdout


def test_large_image_reports_progress_on_stderr(tmp_path: Path):
    image = tmp_path / "big.png"
    Image.new("L", (1100, 1000), 128).save(image)  # 1.1 megapixels
    result = run(image, "-o", tmp_path / "big.hcard")
    assert result.exit_code == 0, result.output
    progress = result.stderr.splitlines()
    assert progress and all(line.startswith("hcard encode: ") for line in progress)
    assert any("analysing 440 taxtels" in line for line in progress)  # 110 x 100 mm
    assert "hcard encode:" not in result.stdout


def test_preview_is_written_through_hcard_preview(tmp_path: Path):
    from PIL import Image

    image = grating_png(tmp_path / "g.png")
    out, preview = tmp_path / "g.hcard", tmp_path / "g-preview.png"
    result = run(image, "-o", out, "--preview", preview)
    assert result.exit_code == 0, result.output
    assert f"preview     {preview}" in result.stdout
    with Image.open(preview) as picture:
        assert picture.format == "PNG"
        assert picture.width > 600 and picture.height > 300


@pytest.mark.parametrize("target", [None, "1"])
def test_preview_draws_the_error_map_the_summary_counts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, target: str | None
):
    """encode --preview hands the preview the per-taxtel error in JND: each taxtel's RMS, or
    its 95th percentile under --max-error; the taxtels it shows above 1 JND are the ones the
    summary counts, and the worst one is where the summary says."""
    import hcard.preview.picture

    drawn: dict[str, object] = {}
    real_preview_png = hcard.preview.picture.preview_png

    def recording_preview_png(card: pb.Card, **options: object) -> bytes:
        drawn.update(options)
        return real_preview_png(card, **options)

    monkeypatch.setattr(hcard.preview.picture, "preview_png", recording_preview_png)
    options = [] if target is None else ["--max-error", target]
    out, preview = tmp_path / "b.hcard", tmp_path / "b-preview.png"
    button = REPO / "examples" / "button.png"
    result = run(button, "-o", out, "--preview", preview, "--json", *options)
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    error_map = np.asarray(drawn["error_map"])
    assert error_map.shape == (summary["rows"], summary["cols"])
    if target is None:
        assert drawn["error_label"] == "RMS error"
        assert int((error_map > 1).sum()) == summary["taxtels_over_jnd"]
        worst = summary["worst_taxtel"]
        assert error_map[worst["row"], worst["col"]] == pytest.approx(worst["rms_jnd"])
    else:
        assert drawn["error_label"] == "95th-percentile error"
        assert int((error_map > float(target)).sum()) == summary["target"]["taxtels_over"]
        worst = summary["target"]["worst"]
        assert error_map[worst["row"], worst["col"]] == pytest.approx(worst["p95_jnd"])
    assert np.nanmax(error_map) == pytest.approx(error_map[worst["row"], worst["col"]])
    with Image.open(preview) as picture:
        assert picture.format == "PNG"


def test_preview_that_cannot_be_written_is_a_one_line_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    def refuse(contents: list[tuple[Path, bytes]]) -> None:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(encode_cmd, "write_atomically_together", refuse)
    image = grating_png(tmp_path / "g.png")
    result = run(image, "-o", tmp_path / "g.hcard", "--preview", tmp_path / "p.png")
    assert_one_line_error(result, "cannot write the card and its preview", "Permission denied")


def test_every_option_has_help_text():
    command = encode_cmd.encode
    assert isinstance(command, click.Command)
    options = [p for p in command.params if isinstance(p, click.Option)]
    assert {o.name for o in options} >= {
        "output",
        "width_mm",
        "height_mm",
        "dpi",
        "taxtel_mm",
        "components",
        "max_textures",
        "min_amplitude",
        "merge_tolerance",
        "channel",
        "locking",
        "friction_range",
        "max_pixels",
        "title",
        "author",
        "licence",
        "preview",
        "as_json",
    }
    for option in options:
        assert option.help and len(option.help) > 10, option.name
    assert encode_cmd.DEFAULT_MAX_PIXELS == DEFAULT_MAX_PIXELS
    help_text = CliRunner().invoke(cli, ["encode", "--help"]).stdout
    assert "--friction-range LO HI" in help_text
    assert "black is high friction" in help_text


# ---------------------------------------------------------------------------------------------
# Bad input: one line, non-zero exit, no traceback, no card written


def test_not_an_image(tmp_path: Path):
    image = tmp_path / "readme.png"
    image.write_text("hello\n")
    out = tmp_path / "x.hcard"
    assert_one_line_error(run(image, "-o", out), str(image), "not an image")
    assert not out.exists()


def test_empty_file(tmp_path: Path):
    image = tmp_path / "empty.png"
    image.write_bytes(b"")
    assert_one_line_error(run(image, "-o", tmp_path / "x.hcard"), "empty file")


def test_image_of_zero_width(tmp_path: Path):
    image = png_header_only(tmp_path / "zero.png", 0, 40)
    assert_one_line_error(run(image, "-o", tmp_path / "x.hcard"), "empty image (0 x 40 pixels)")


def test_decompression_bomb(tmp_path: Path):
    image = png_header_only(tmp_path / "bomb.png", 100_000, 100_000)
    out = tmp_path / "x.hcard"
    assert_one_line_error(
        run(image, "-o", out), "10000000000 pixels exceed the limit of 64000000", "--max-pixels"
    )
    assert not out.exists()


def test_max_pixels_option(tmp_path: Path):
    image = grating_png(tmp_path / "g.png")
    assert_one_line_error(
        run(image, "-o", tmp_path / "x.hcard", "--max-pixels", "50000"),
        "60000 pixels exceed the limit of 50000",
    )
    assert run(image, "-o", tmp_path / "y.hcard", "--max-pixels", "60000").exit_code == 0


def test_missing_file(tmp_path: Path):
    assert_one_line_error(run(tmp_path / "nope.png", "-o", tmp_path / "x.hcard"), "no such file")


@pytest.mark.parametrize("where", ["missing-directory", "is-a-directory"])
def test_unwritable_output(tmp_path: Path, where: str):
    image = grating_png(tmp_path / "g.png")
    out = tmp_path / "no" / "such" / "x.hcard" if where == "missing-directory" else tmp_path
    message = "does not exist" if where == "missing-directory" else "is a directory"
    assert_one_line_error(run(image, "-o", out), "cannot write the card", message)


def test_output_write_failure_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A write that fails after the encode (disk full, permissions) is still one line."""
    import hcard.card_io

    def full(path: object, data: bytes) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(hcard.card_io, "write_atomically", full)
    image = grating_png(tmp_path / "g.png")
    out = tmp_path / "x.hcard"
    assert_one_line_error(run(image, "-o", out), "cannot write", "No space left on device")
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--friction-range", "0.5", "1.2"], "UV can only lower friction"),
        (["--channel", "ev", "--friction-range", "0.8", "1.4"], "EV can only raise friction"),
        (["--dpi", "300", "--width-mm", "20"], "not both"),
        (["--components", "17"], "--components"),
        (["--max-textures", "0"], "--max-textures"),
        (["--taxtel-mm", "0"], "--taxtel-mm must be between"),
        (["--channel", "air"], "--channel"),
        (["--width-mm", "-3"], "--width-mm must be a positive number"),
        (["--max-error", "0"], "--max-error"),
        (["--max-error", "-1"], "--max-error"),
        (["--max-error", "nan"], "--max-error"),
    ],
)
def test_bad_options_are_usage_errors(tmp_path: Path, args: list[str], message: str):
    image = grating_png(tmp_path / "g.png")
    result = run(image, "-o", tmp_path / "x.hcard", *args)
    assert_one_line_error(result, message, status=2, after_usage=True)


def test_missing_output_option_is_a_usage_error(tmp_path: Path):
    result = run(grating_png(tmp_path / "g.png"))
    assert result.exit_code == 2
    assert "Missing option '-o' / '--output'" in result.stderr


def test_summary_lines_format_the_ratio_to_the_raw_bitmap():
    lines = encode_cmd.summary_lines(
        {
            "image": "a.png",
            "image_width_px": 10,
            "image_height_px": 10,
            "image_mode": "L",
            "width_mm": 1.0,
            "height_mm": 1.0,
            "pixel_pitch_mm": (0.1, 0.1),
            "size_source": "test",
            "cols": 1,
            "rows": 1,
            "taxtel_mm": 5.0,
            "tile_px": (50, 50),
            "channel": "uv",
            "locking": "auto",
            "friction_range": (0.3, 1.0),
            "textures": 1,
            "distinct_textures": 3,
            "components": 0,
            "textured_taxtels": 0,
            "card_bytes": 25,
            "raw_bitmap_bytes": 100,
            "rms_error": 0.04,
            "max_error": 0.1,
            "rms_error_jnd": 0.5,
            "output": "a.hcard",
            "output_format": "binary",
            "output_bytes": 25,
        }
    )
    text = "\n".join(lines)
    assert "(card = 25 % of it)" in text
    assert "1 in the palette (3 distinct before merging)" in text
    # an encoder without a 95th percentile or per-taxtel figures: rms and max only
    assert "rms 0.0400, max 0.1000 relative friction = 0.50, 1.25 x the 0.08 friction JND" in text
    assert not any(line.startswith("taxtels") for line in lines)


def test_max_error_prints_the_target_and_who_misses_it(tmp_path: Path):
    """A grating patch with a sharp-edged dark square: with --max-error 1 the summary says how
    many taxtels meet the target, the worst of the others and why; the JSON summary lists them
    all with the same figures."""
    x = (np.arange(300) + 0.5) * 0.1
    xx, yy = np.meshgrid(x, x[:200])
    gray = 0.5 - 0.3 * np.cos(2 * np.pi * xx / 1.3)
    gray = np.where((xx > 12.3) & (xx < 18.9) & (yy > 6.2) & (yy < 13.7), 0.05, gray)
    path = tmp_path / "patch.png"
    Image.fromarray(np.round(gray * 255).astype(np.uint8)).save(path)
    result = run(path, "-o", tmp_path / "p.hcard", "--max-error", "1")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    target = next(line for line in lines if line.startswith("target"))
    assert "95th percentile <= 1 JND in each taxtel: met in" in target
    assert "worst: column" in target
    assert any("detail finer than 16 gratings" in line for line in lines)
    data = json.loads(run(path, "-o", tmp_path / "p.hcard", "--max-error", "1", "--json").stdout)
    figures = data["target"]
    assert figures["target_jnd"] == 1.0
    assert figures["taxtels_over"] == len(figures["over_target"]) > 0
    assert f"met in {24 - figures['taxtels_over']} of 24" in target
    worst = figures["worst"]
    assert f"column {worst['col']}, row {worst['row']} ({worst['p95_jnd']:.2f} JND" in target
    assert all(t["p95_jnd"] > 1.0 for t in figures["over_target"])
    plain = json.loads(run(path, "-o", tmp_path / "p.hcard", "--json").stdout)
    assert "target" not in plain and plain["components"] < data["components"]
