"""The preview picture: texture periods against the analytic cosine, the cells drawn for every
texture, pixels of the taxtel map, CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import hcard
from hcard import build
from hcard.preview.periods import (
    BANDS,
    CELL_LABELS,
    CURVES,
    NATURAL,
    STRIPS,
    SWATCHES,
    UNREACHABLE,
    plot_series,
    spatial_friction,
    temporal_friction,
)
from hcard.preview.picture import (
    GRID_AXES_LABEL,
    PERIODS_AXES_LABEL,
    preview_figure,
    render_preview,
    texture_colors,
)

TAXTEL_MM = 20.0
INDEX = np.array([[0, 1, 2], [2, 0, 1]])


def three_texture_card() -> hcard.Card:
    textures = [
        build.texture(
            0.7, [build.spatial(1.0, 0.2)], channel="uv", locking="velocity", name="fine"
        ),
        build.texture(
            1.3, [build.grating_period(8.0, 0.25, orientation=math.pi / 4)], channel="ev"
        ),
        build.texture(1.0, [build.temporal(50.0, 0.1)], channel="bipolar", locking="position"),
    ]
    return build.card(
        60.0, 40.0, taxtel_mm=TAXTEL_MM, textures=textures, texture_index=INDEX, title="three"
    )


# ------------------------------------------------------------------------------ periods


def test_spatial_friction_of_a_grating_is_the_analytic_cosine() -> None:
    grating = build.spatial(0.25, 0.2, phase=0.3, orientation=0.5)
    s_mm, friction = spatial_friction(build.texture(0.7, [grating]), n=2001)
    assert s_mm.shape == friction.shape == (2001,)
    assert s_mm[0] == 0.0
    assert s_mm[-1] == pytest.approx(4.0)  # one period of 0.25 cycles/mm
    assert friction.max() == pytest.approx(0.9, abs=1e-6)
    assert friction.min() == pytest.approx(0.5, abs=1e-6)
    assert friction[0] == pytest.approx(0.7 + 0.2 * math.cos(0.3))
    assert friction[-1] == pytest.approx(friction[0])
    # The minimum is where the phase reaches pi: s = (pi - 0.3) / (2 pi 0.25) = 1.8090 mm.
    assert s_mm[np.argmin(friction)] == pytest.approx(1.8090, abs=0.002)
    assert s_mm[np.argmax(friction)] == pytest.approx(4.0 - 0.1910, abs=0.002)


def test_spatial_friction_follows_the_strongest_component_and_projects_the_others() -> None:
    strong = build.spatial(0.5, 0.3, orientation=math.pi / 3)
    perpendicular = build.spatial(2.0, 0.1, phase=0.4, orientation=math.pi / 3 + math.pi / 2)
    s_mm, friction = spatial_friction(build.texture(1.0, [strong, perpendicular]), n=401)
    # The perpendicular grating does not vary along the strongest's direction: constant
    # 0.1 cos(0.4) = 0.0921; its own period (0.5 mm) does not set the window (2 mm does).
    assert s_mm[-1] == pytest.approx(2.0)
    assert friction.max() == pytest.approx(1.3 + 0.1 * math.cos(0.4), abs=1e-9)
    assert friction.min() == pytest.approx(0.7 + 0.1 * math.cos(0.4), abs=1e-4)


def test_window_is_capped_by_the_strongest_component_and_50_mm() -> None:
    slow_weak = build.spatial(0.01, 0.05)  # 100 mm period
    fast_strong = build.spatial(2.0, 0.3)  # 0.5 mm period: window 4 x 0.5 = 2 mm
    s_mm, _ = spatial_friction(build.texture(1.0, [slow_weak, fast_strong]))
    assert s_mm[-1] == pytest.approx(2.0)
    s_mm, friction = spatial_friction(build.texture(1.0, [build.spatial(0.01, 0.2)]))
    assert s_mm[-1] == pytest.approx(50.0)
    assert friction[-1] == pytest.approx(1.0 + 0.2 * math.cos(2 * math.pi * 0.5))


def test_flat_and_temporal_friction() -> None:
    s_mm, friction = spatial_friction(build.texture(0.8), n=64)
    assert s_mm[-1] == pytest.approx(10.0)
    assert np.all(friction == 0.8)
    t_ms, friction = temporal_friction(build.texture(1.1, [build.temporal(50.0, 0.1)]), n=1001)
    assert t_ms[-1] == pytest.approx(20.0)  # one period of 50 Hz, in milliseconds
    assert friction.max() == pytest.approx(1.2)
    assert friction.min() == pytest.approx(1.0, abs=1e-6)
    assert t_ms[np.argmin(friction)] == pytest.approx(10.0, abs=0.02)
    # Temporal components stay out of the spatial friction.
    _, spatial = spatial_friction(build.texture(1.1, [build.temporal(50.0, 0.1)]))
    assert np.all(spatial == 1.1)


# ------------------------------------------------------------------------------ picture


def test_preview_png_shows_the_texture_of_every_taxtel(tmp_path: Path) -> None:
    card = three_texture_card()
    out = tmp_path / "preview.png"
    render_preview(card, out, dpi=100)

    with Image.open(out) as image:
        assert image.format == "PNG"
        width, height = image.size
        pixels = np.asarray(image.convert("RGB"))
    assert width == 1400  # 14 inches at 100 dpi
    assert 550 <= height <= 1200

    # Locate the taxtels in pixels with the same (deterministic) layout.
    fig = preview_figure(card, dpi=100)
    fig.canvas.draw()
    assert fig.canvas.get_width_height() == (width, height)
    grid_ax = next(ax for ax in fig.axes if ax.get_label() == GRID_AXES_LABEL)
    colours = np.round(texture_colors(3)[:, :3] * 255)
    seen: dict[int, set[tuple[int, ...]]] = {0: set(), 1: set(), 2: set()}
    for (row, col), texture in np.ndenumerate(INDEX):
        # A quarter of the way into the taxtel: away from the borders and the number label.
        x_mm, y_mm = (col + 0.25) * TAXTEL_MM, (row + 0.3) * TAXTEL_MM
        x_px, y_px = grid_ax.transData.transform((x_mm, y_mm))
        rgb = pixels[round(height - y_px), round(x_px)].astype(float)
        np.testing.assert_allclose(rgb, colours[texture], atol=2.0)
        seen[texture].add(tuple(int(v) for v in rgb))
    distinct = {colour for colours_of in seen.values() for colour in colours_of}
    assert len(distinct) == 3
    # The map lies in the left part of the picture, y growing downwards.
    top_left = grid_ax.transData.transform((0.0, 0.0))
    bottom_left = grid_ax.transData.transform((0.0, 40.0))
    assert top_left[1] > bottom_left[1]
    assert grid_ax.transData.transform((60.0, 0.0))[0] < 0.6 * width


def _periods(fig) -> dict[str, object]:
    """The periods axes' collections by label."""
    ax = next(ax for ax in fig.axes if ax.get_label() == PERIODS_AXES_LABEL)
    return {c.get_label(): c for c in ax.collections}


def test_every_texture_has_a_labelled_cell() -> None:
    marks = _periods(preview_figure(three_texture_card()))
    # periods: of 1 cycle/mm, of an 8 mm grating, of 50 Hz
    assert marks[CELL_LABELS].texts == [
        "texture 0 (fine)\nUV, VELOCITY, 1 component\nperiod 1 mm ∠0°",
        "texture 1\nEV, AUTO, 1 component\nperiod 8 mm ∠45°",
        "texture 2\nBIPOLAR, POSITION, 1 component\nperiod 20 ms",
    ]
    np.testing.assert_allclose(marks[SWATCHES].get_facecolors(), texture_colors(3))

    # 30 textures: no cap any more, compact labels ("BIP": bipolar)
    textures = [build.texture(1.0, [build.spatial(0.1 * (i + 1), 0.1)]) for i in range(30)]
    index = [i % 30 for i in range(36)]  # a 6 x 6 grid using all 30 textures
    card = build.card(30.0, 30.0, taxtel_mm=5.0, textures=textures, texture_index=index)
    labels = _periods(preview_figure(card))[CELL_LABELS].texts
    assert len(labels) == 30
    assert labels[0] == "0 BIP auto\n10 mm ∠0°"  # one period of 0.1 cycles/mm
    assert labels[29] == "29 BIP auto\n0.333 mm ∠0°"  # of 3 cycles/mm


def test_cell_draws_the_analytic_profile_on_the_shared_scale() -> None:
    marks = _periods(preview_figure(three_texture_card()))
    # Windows shared by every texture: 4 x the longest period (8 mm) rounded up to 50 mm; 4 x
    # 20 ms rounded up to 100 ms.
    # Extremes: 0.7 +- 0.2, 1.3 +- 0.25, 1.0 +- 0.1 and natural friction 1 -> 0.5 to 1.55,
    # padded by a tenth of the span (0.105). The scale comes from the drawn samples (a dozen
    # or more a period), whose extremes miss the true ones by less than 1 - cos(pi / 12).
    low, high = 0.5 - 0.105, 1.55 + 0.105
    tolerance = 5e-3
    strips = [path.vertices for path in marks[STRIPS].get_paths()]
    curves = [np.asarray(path.vertices) for path in marks[CURVES].get_paths()]
    assert len(strips) == len(curves) == 3
    left, top = strips[0].min(axis=0)
    right, bottom = strips[0].max(axis=0)
    x_in, y_in = curves[0][:, 0], curves[0][:, 1]
    s_mm = (x_in - left) / (right - left) * 50.0
    friction = high - (y_in - top) / (bottom - top) * (high - low)
    np.testing.assert_allclose(friction, 0.7 + 0.2 * np.cos(2 * np.pi * s_mm), atol=tolerance)
    assert s_mm[0] == pytest.approx(0.0) and s_mm[-1] == pytest.approx(50.0)
    # the dashed natural-friction line of that cell lies at 1
    natural = np.asarray(marks[NATURAL].get_segments()[0])
    natural_friction = high - (natural[0, 1] - top) / (bottom - top) * (high - low)
    assert natural_friction == pytest.approx(1.0, abs=tolerance)
    # the temporal texture: 1.0 + 0.1 cos(2 pi 50 Hz t) over 20 ms
    left, top = strips[2].min(axis=0)
    right, bottom = strips[2].max(axis=0)
    t_ms = (curves[2][:, 0] - left) / (right - left) * 100.0
    friction = high - (curves[2][:, 1] - top) / (bottom - top) * (high - low)
    np.testing.assert_allclose(friction, 1.0 + 0.1 * np.cos(2 * np.pi * 0.05 * t_ms),
                               atol=tolerance)


def test_cell_shades_what_a_one_sided_channel_cannot_render() -> None:
    marks = _periods(preview_figure(three_texture_card()))
    strips = [path.vertices for path in marks[STRIPS].get_paths()]
    spans = [path.vertices for path in marks[UNREACHABLE].get_paths()]
    lines = [np.asarray(s)[0, 1] for s in marks[NATURAL].get_segments()]
    assert len(spans) == 2  # the UV and the EV texture; the bipolar one renders both sides
    # UV (texture 0) cannot raise friction: shaded from the top of its strip down to 1
    assert spans[0][:, 1].min() == pytest.approx(strips[0][:, 1].min())
    assert spans[0][:, 1].max() == pytest.approx(lines[0])
    # EV (texture 1) cannot lower it: shaded from 1 down to the bottom of its strip
    assert spans[1][:, 1].min() == pytest.approx(lines[1])
    assert spans[1][:, 1].max() == pytest.approx(strips[1][:, 1].max())


def test_spatial_and_temporal_parts_are_stacked_in_one_cell() -> None:
    both = build.texture(1.0, [build.spatial(0.5, 0.2), build.temporal(100.0, 0.1)],
                         channel="bipolar")
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[both, build.texture(0.6)],
                      texture_index=[0, 1])
    marks = _periods(preview_figure(card))
    strips = [path.vertices for path in marks[STRIPS].get_paths()]
    assert len(strips) == 3  # two strips for texture 0, one for texture 1
    assert strips[0][:, 1].max() < strips[1][:, 1].min()  # spatial above temporal
    np.testing.assert_allclose(strips[0][:, 0].min(), strips[1][:, 0].min())
    assert marks[CELL_LABELS].texts[0] == (
        "texture 0\nBIPOLAR, AUTO, 2 components\nperiod 2 mm ∠0° | 10 ms")


def test_components_too_fine_to_draw_become_a_band() -> None:
    fine, coarse = (50.0, 0.05, 0.0), (0.1, 0.2, 0.3)  # cycles per mm, amplitude, phase
    x, friction, band = plot_series(0.8, [fine, coarse], 10.0, max_samples=1000)
    # 500 cycles of the fine term would need 6000 samples: it is the band
    assert band == pytest.approx(0.05)
    assert len(x) <= 1000 and x[0] == 0.0 and x[-1] == pytest.approx(10.0)
    np.testing.assert_allclose(friction, 0.8 + 0.2 * np.cos(2 * np.pi * 0.1 * x + 0.3))
    x, friction, band = plot_series(0.8, [fine, coarse], 10.0, max_samples=10_000)
    assert band == 0.0
    assert len(x) == 6001  # 12 samples per cycle of the finer term

    texture = build.texture(1.0, [build.spatial(50.0, 0.05), build.spatial(0.1, 0.2)])
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[texture])
    band_paths = _periods(preview_figure(card))[BANDS].get_paths()
    assert len(band_paths) == 1


def test_a_full_palette_is_drawn_in_a_few_axes() -> None:
    textures = [build.texture(0.4 + i / 512, [build.spatial(0.2 + i / 100, 0.05)],
                              channel="uv", locking="position") for i in range(256)]
    card = build.card(80.0, 80.0, taxtel_mm=5.0, textures=textures,
                      texture_index=np.arange(256))
    fig = preview_figure(card)
    assert len(fig.axes) == 3  # the taxtel map, its colour bar and the periods
    marks = _periods(fig)
    assert len(marks[CURVES].get_paths()) == 256
    labels = marks[CELL_LABELS].texts
    assert labels[255] == "255 UV pos.\n0.364 mm"  # one period of 2.75 cycles/mm
    # fewer cells a row beside the taxtel map than in the full-width rows below it
    rows: dict[float, int] = {}
    for _, y in marks[CELL_LABELS].get_offsets():
        rows[round(float(y), 6)] = rows.get(round(float(y), 6), 0) + 1
    counts = list(rows.values())
    assert sum(counts) == 256
    assert len(set(counts[:3])) == 1 and 8 <= counts[0] < max(counts) <= 16


def test_invalid_card_is_refused() -> None:
    card = three_texture_card()
    card.grid.texture_index[0] = 7  # no texture 7
    with pytest.raises(hcard.CardValidationError, match="texture_index"):
        preview_figure(card)


# ---------------------------------------------------------------------------------- CLI


def _cli():
    from hcard.cli.main import cli

    return cli


def test_cli_preview_writes_png(tmp_path: Path) -> None:
    card_path = tmp_path / "three.hcard"
    hcard.save(three_texture_card(), card_path)
    out = tmp_path / "three.png"
    result = CliRunner().invoke(_cli(), ["preview", str(card_path), "-o", str(out), "--dpi", "50"])
    assert result.exit_code == 0, result.output
    assert f"wrote {out}" in result.stdout
    with Image.open(out) as image:
        assert image.format == "PNG"
        assert image.size[0] == 700
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp files


@pytest.mark.parametrize(
    ("content", "reason"),
    [(None, "no such file"), (b"\x0a\xff\xff\xffgarbage", "corrupt or truncated")],
    ids=["missing", "corrupt"],
)
def test_cli_preview_bad_card_is_one_line_error(
    tmp_path: Path, content: bytes | None, reason: str
) -> None:
    card_path = tmp_path / "bad.hcard"
    if content is not None:
        card_path.write_bytes(content)
    out = tmp_path / "out.png"
    out.write_bytes(b"previous picture")
    result = CliRunner().invoke(_cli(), ["preview", str(card_path), "-o", str(out)])
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("Error: ")
    assert reason in lines[0]
    assert "Traceback" not in result.output
    assert out.read_bytes() == b"previous picture"


def test_cli_preview_refuses_other_formats(tmp_path: Path) -> None:
    card_path = tmp_path / "three.hcard"
    hcard.save(three_texture_card(), card_path)
    result = CliRunner().invoke(_cli(), ["preview", str(card_path), "-o", str(tmp_path / "a.jpg")])
    assert result.exit_code == 2
    assert "output must be a .png file" in result.stderr
