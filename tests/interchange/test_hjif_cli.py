"""``hcard export --to hjif`` and ``hcard import x.hjif`` (spec/interchange/hjif.md)."""

from __future__ import annotations

import json

from hcard.card_io import load, save
from tests.helpers.cli import run_hcard
from tests.interchange.hjif_cards import _fixed_date, hjif_registered, mixed_card

__all__ = ["_fixed_date", "hjif_registered"]


def test_export_lists_what_the_format_cannot_hold(hjif_registered, tmp_path) -> None:
    card = tmp_path / "mixed.hcard"
    save(mixed_card(), card)
    result = run_hcard("export", card, "--to", "hjif", "-o", tmp_path / "mixed.hjif")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0] == f"export      {card} to hjif"
    assert lines[1].startswith(f"wrote       {tmp_path / 'mixed.hjif'} (")
    assert lines[2].startswith(f"wrote       {tmp_path / 'mixed.gltf'} (")
    held = [line.split(":")[0] for line in lines if line.startswith("cannot hold")]
    assert held == ["cannot hold channel", "cannot hold locking", "cannot hold orientation",
                    "cannot hold friction-scale", "cannot hold phase",
                    "cannot hold components", "cannot hold taxtel-map",
                    "cannot hold metadata"]
    assert any(line.startswith("fidelity    the format's own content against the card: rms "
                               "0.00") for line in lines)
    assert (tmp_path / "mixed.hjif").read_bytes().startswith(b'{"version":"2023"')


def test_export_json_summary(hjif_registered, tmp_path) -> None:
    card = tmp_path / "mixed.hcard"
    save(mixed_card(), card)
    result = run_hcard("export", card, "--to", "hjif", "-o", tmp_path / "m.hjif", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert [f["path"] for f in summary["files"]] == [str(tmp_path / "m.hjif"),
                                                     str(tmp_path / "m.gltf")]
    assert summary["files"][0]["bytes"] == (tmp_path / "m.hjif").stat().st_size
    fields = {loss["field"]: loss for loss in summary["losses"]}
    assert fields["orientation"]["carried"].startswith("the hcard extension")
    assert summary["timescale"] == 40000 and summary["channels"] == 3
    assert summary["max_error_jnd"] < 0.0125


def test_import_of_an_export_gives_the_card_back(hjif_registered, tmp_path) -> None:
    card = tmp_path / "mixed.hcard"
    save(mixed_card(), card)
    assert run_hcard("export", card, "--to", "hjif", "-o", tmp_path / "m.hjif").exit_code == 0
    result = run_hcard("import", tmp_path / "m.hjif", "-o", tmp_path / "back.hcard")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f"source      {tmp_path / 'm.hjif'} (hjif: MPEG-I haptics 2023 "
                               "Main@1, 3 perception(s) (Electrotactile, Friction), 3 "
                               "channel(s) imported, hcard extension, glTF taxtel map)")
    assert "card        12 x 8 taxtels, 3 textures, 6 components" in lines
    back = load(tmp_path / "back.hcard")
    assert list(back.grid.texture_index) == list(mixed_card().grid.texture_index)
    assert back.textures[0].name == "ridges"


def test_import_json_summary(hjif_registered, tmp_path) -> None:
    card = tmp_path / "mixed.hcard"
    save(mixed_card(), card)
    run_hcard("export", card, "--to", "hjif", "-o", tmp_path / "m.hjif")
    result = run_hcard("import", tmp_path / "m.hjif", "-o", tmp_path / "b.json", "--json",
                       "--title", "renamed")
    summary = json.loads(result.stdout)
    assert summary["format"] == "hjif" and summary["hcard_extension"] is True
    assert summary["textures"] == 3 and summary["cols"] == 12
    assert summary["max_error_jnd"] < 0.0125
    assert load(tmp_path / "b.json").metadata.title == "renamed"


def test_an_export_whose_extension_outgrows_the_recognised_head_is_still_recognised(
        hjif_registered, tmp_path) -> None:
    """IJ70: 40 textures make the top-level description (the extension) longer than the 4096
    bytes hcard import recognises a format by, so "perceptions" lies past them."""
    from hcard import build

    textures = [build.texture(1.1 + 0.01 * t, [build.spatial(0.5 + 0.05 * t, 0.05)],
                              channel="ev", name=f"ridge-{t}") for t in range(40)]
    card = build.card(40.0, 5.0, taxtel_mm=1.0, textures=textures,
                      texture_index=list(range(40)) * 5)
    save(card, tmp_path / "wide.hcard")
    assert run_hcard("export", tmp_path / "wide.hcard", "--to", "hjif", "-o",
                     tmp_path / "wide.hjif").exit_code == 0
    head = (tmp_path / "wide.hjif").read_bytes()[:4096]
    assert b'"perceptions"' not in head
    result = run_hcard("import", tmp_path / "wide.hjif", "-o", tmp_path / "back.hcard")
    assert result.exit_code == 0, result.output
    back = load(tmp_path / "back.hcard")
    assert [t.name for t in back.textures] == [f"ridge-{t}" for t in range(40)]
    assert list(back.grid.texture_index) == list(card.grid.texture_index)
