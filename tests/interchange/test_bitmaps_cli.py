"""``hcard import`` and ``hcard export`` with Tanvas and TPad bitmaps: the tie on a plain PNG,
``--from``, the export's losses in words and in JSON, and one-line errors
(spec/interchange/bitmaps.md IB12, IB15)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hcard import build
from hcard.card_io import load, save
from tests.helpers.cli import assert_one_line_error, run_hcard
from tests.interchange.bitmap_helpers import save_png
from tests.interchange.test_bitmaps_hostile import extension, hcard_chunk, png_with


def plain_png(tmp_path: Path) -> Path:
    """A 100 x 60 pixel PNG at 254 dpi: left half black, right half white."""
    pixels = np.zeros((60, 100), dtype=np.uint8)
    pixels[:, 50:] = 255
    return save_png(pixels, tmp_path / "plain.png", dpi=254.0)


def test_a_plain_png_is_a_tie_and_from_names_the_format(tmp_path: Path):
    """IB12: without --from a plain PNG fits tanvas and tpad alike: one line, exit 1; with
    --from tanvas the encoder's summary, prefixed by the format's mapping."""
    source = plain_png(tmp_path)
    tie = run_hcard("import", source, "-o", tmp_path / "x.hcard")
    assert_one_line_error(tie, str(source), "fits tanvas and tpad alike", "--from")
    done = run_hcard("import", source, "--from", "tanvas", "--dpi", "254", "-o",
                     tmp_path / "x.hcard")
    assert done.exit_code == 0, done.output
    assert done.output.startswith("format      tanvas: Tanvas bitmap, gray 0 = relative "
                                  "friction 1, 255 = 1.6 (channel ev)")
    card = load(tmp_path / "x.hcard")
    assert sorted(t.baseline for t in card.textures) == [1.0, 1.6]


def test_an_unknown_option_for_the_format_is_a_usage_error(tmp_path: Path):
    """IB6: --length-unit-mm is not a bitmap option: exit 2 naming it as the command's."""
    result = run_hcard("import", plain_png(tmp_path), "--from", "tpad", "--length-unit-mm",
                       "2", "-o", tmp_path / "x.hcard")
    assert_one_line_error(result, "--length-unit-mm: not an option of the tpad importer",
                          status=2, after_usage=True)


def card_file(tmp_path: Path) -> Path:
    """A 20 x 10 mm card: an EV grating and a UV texture (a channel Tanvas cannot hold)."""
    card = build.card(20.0, 10.0, taxtel_mm=5.0, textures=[
        build.texture(1.3, [build.spatial(0.4, 0.1)], channel="ev", locking="position"),
        build.texture(0.6, channel="uv")], texture_index=[0, 1] * 4)
    path = tmp_path / "card.hcard"
    save(card, path)
    return path


def test_export_to_tanvas_lists_its_losses_and_import_gives_the_card_back(tmp_path: Path):
    """IB12, IB13, IB15: the text summary names every loss and where it is kept; the export
    is recognised as tanvas without --from and imports to the same card."""
    card = card_file(tmp_path)
    out = tmp_path / "card.png"
    result = run_hcard("export", card, "--to", "tanvas", "-o", out)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1] == f"wrote       {out} ({out.stat().st_size} bytes)"
    held = [line.split(":")[0] for line in lines if line.startswith("cannot hold")]
    assert held == ["cannot hold channel", "cannot hold orientation", "cannot hold phase",
                    "cannot hold friction-scale", "cannot hold taxtel-map",
                    "cannot hold metadata"]
    assert all(line.endswith('kept in PNG chunk iTXt "hcard"') for line in lines
               if line.startswith("cannot hold"))
    assert "fidelity    the format's own content against the card: rms" in result.output
    back = run_hcard("import", out, "-o", tmp_path / "back.hcard")
    assert back.exit_code == 0, back.output
    assert "(tanvas: Tanvas bitmap 200 x 100 px exported by hcard" in back.output
    assert load(tmp_path / "back.hcard") == load(card)


def test_export_json_has_the_losses_and_figures(tmp_path: Path):
    """IB15: --json: the losses as objects, the clipped UV pixels (half of 200 x 100) and the
    error of the clipped UV half: (1 - 0.6) / 0.08 = 5 JND at most."""
    result = run_hcard("export", card_file(tmp_path), "--to", "tanvas", "-o",
                       tmp_path / "c.png", "--px-per-mm", "10", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["format"] == "tanvas"
    assert next(loss["field"] for loss in summary["losses"]) == "channel"
    assert summary["losses"][0]["carried"] == 'PNG chunk iTXt "hcard"'
    assert summary["clipped_pixels"] == 10_000
    assert abs(summary["max_error_jnd"] - 5.0) < 1e-6
    assert summary["files"][0]["bytes"] == (tmp_path / "c.png").stat().st_size


def test_a_bad_chunk_on_the_command_line_is_one_line(tmp_path: Path):
    """IB14: an hcard chunk whose card is not base64: one line naming the file and chunk."""
    source = tmp_path / "bad.png"
    source.write_bytes(png_with(hcard_chunk(extension(card="%%%"))))
    result = run_hcard("import", source, "-o", tmp_path / "x.hcard")
    assert_one_line_error(result, str(source), 'PNG chunk iTXt "hcard" card: not base64')


def test_the_import_summary_states_the_tanvas_polarity(tmp_path: Path):
    """IB1: the encoder's summary line of the channel says white = 1.6, black = 1 for a
    Tanvas import (the encoder's own default says black = high)."""
    result = run_hcard("import", plain_png(tmp_path), "--from", "tanvas", "-o",
                       tmp_path / "x.hcard")
    assert "channel     ev: white = 1.6, black = 1 relative friction" in result.output
    tpad = run_hcard("import", plain_png(tmp_path), "--from", "tpad", "-o", tmp_path / "y.hcard")
    assert "channel     uv: black = 1, white = 0.3 relative friction" in tpad.output
