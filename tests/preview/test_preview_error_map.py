"""The preview's error map: the values it shows, the taxtels above 1 JND, bad maps refused."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hcard import build
from hcard.limits import RELATIVE_FRICTION_JND
from hcard.preview.error_map import (
    ERROR_AXES_LABEL,
    ERROR_BAR_LABEL,
    OUTLINE_LABEL,
    error_panel,
    outline_segments,
)
from hcard.preview.picture import preview_figure, render_preview

TAXTEL_MM = 10.0
# 2 rows x 3 columns, JND; two taxtels above 1 JND, side by side in the top row
ERRORS = np.array([[0.2, 1.5, 3.0], [0.0, 0.9, 1.0]])


def two_by_three_card():
    textures = [build.texture(0.6, channel="uv"), build.texture(0.9, channel="uv")]
    return build.card(30.0, 20.0, taxtel_mm=TAXTEL_MM, textures=textures,
                      texture_index=[0, 1, 1, 0, 0, 1], title="errors")


def _edges(segments: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(float(v) for v in np.asarray(s).ravel()) for s in segments}


def _length(segments: np.ndarray) -> float:
    segments = np.asarray(segments)
    return float(np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1).sum())


# ----------------------------------------------------------------------------- outline


def test_outline_of_one_taxtel_is_its_four_edges() -> None:
    mask = np.zeros((3, 4), dtype=bool)
    mask[1, 2] = True
    # taxtel (row 1, col 2) of 5 x 4 mm spans x 10-15 mm, y 4-8 mm
    assert _edges(outline_segments(mask, 5.0, 4.0)) == {
        (10.0, 4.0, 15.0, 4.0), (10.0, 8.0, 15.0, 8.0),
        (10.0, 4.0, 10.0, 8.0), (15.0, 4.0, 15.0, 8.0),
    }


def test_outline_joins_collinear_edges() -> None:
    # an L of four unit taxtels: perimeter 4 x 4 - 2 x 3 shared edges = 10, in six straight runs
    mask = np.array([[1, 1, 1], [1, 0, 0]], dtype=bool)
    segments = outline_segments(mask, 1.0, 1.0)
    assert len(segments) == 6
    assert _length(segments) == pytest.approx(10.0)
    assert (0.0, 0.0, 3.0, 0.0) in _edges(segments)  # the top, one run
    assert len(outline_segments(np.ones((4, 5), dtype=bool), 2.0, 3.0)) == 4  # the border
    assert len(outline_segments(np.zeros((4, 5), dtype=bool), 2.0, 3.0)) == 0


# ------------------------------------------------------------------------------- panel


def _error_axes(fig):
    return next(ax for ax in fig.axes if ax.get_label() == ERROR_AXES_LABEL)


def test_error_map_shows_the_array_over_the_grid() -> None:
    fig = preview_figure(two_by_three_card(), error_map=ERRORS, error_label="RMS error")
    ax = _error_axes(fig)
    (image,) = ax.get_images()
    np.testing.assert_array_equal(image.get_array(), ERRORS)
    assert image.get_extent() == [0.0, 30.0, 20.0, 0.0]  # 3 x 2 taxtels of 10 mm, y downwards
    # 0 JND at the bottom of the colour scale, 1 JND in the middle, the largest (3) at the top
    assert image.norm(0.0) == pytest.approx(0.0)
    assert image.norm(1.0) == pytest.approx(0.5)
    assert image.norm(3.0) == pytest.approx(1.0)
    assert ax.get_title(loc="left") == (
        "RMS error: max 3 JND, p95 2.6 JND\ncolour scale 0-3 JND; 2 of 6 taxtels above 1 JND, "
        "outlined")
    # outlined: the 1.5 and 3.0 JND taxtels, a 20 x 10 mm block (1.0 JND itself is not above)
    (outline,) = [c for c in ax.collections if c.get_label() == OUTLINE_LABEL]
    assert _length(outline.get_segments()) == pytest.approx(60.0)
    assert _edges(outline.get_segments()) >= {(10.0, 0.0, 30.0, 0.0), (10.0, 10.0, 30.0, 10.0)}
    bar = next(a for a in ax.figure.axes if a.get_label() == ERROR_BAR_LABEL)
    assert f"1 JND = {RELATIVE_FRICTION_JND:g}" in bar.get_ylabel()
    assert 1.0 in bar.get_yticks()


def test_error_map_pixels_separate_the_taxtels_above_1_jnd(tmp_path: Path) -> None:
    card = two_by_three_card()
    out = tmp_path / "errors.png"
    render_preview(card, out, dpi=80, error_map=ERRORS)
    with Image.open(out) as image:
        pixels = np.asarray(image.convert("RGB")).astype(int)
    fig = preview_figure(card, dpi=80, error_map=ERRORS)
    fig.canvas.draw()
    ax = _error_axes(fig)
    height = pixels.shape[0]

    def colour(row: int, col: int) -> np.ndarray:
        x, y = ax.transData.transform(((col + 0.5) * TAXTEL_MM, (row + 0.5) * TAXTEL_MM))
        return pixels[round(height - y), round(x)]

    for (row, col), value in np.ndenumerate(ERRORS):
        if value == 1.0:
            continue  # exactly on the colour boundary: the outline decides (test above)
        red, _, blue = colour(row, col)
        assert (red > blue) == (value > 1.0), (row, col, value, colour(row, col))


def test_no_taxtel_above_1_jnd_and_missing_figures() -> None:
    values = np.array([[0.1, np.nan, 0.4], [0.0, 0.99, 0.5]])
    ax = _error_axes(preview_figure(two_by_three_card(), error_map=values))
    assert ax.get_title(loc="left") == (
        "reconstruction error: max 0.99 JND, p95 0.89 JND\n"
        "colour scale 0-1 JND; all 5 taxtels below 1 JND (not felt)")
    (image,) = ax.get_images()
    assert image.norm.vmax == 1.0  # the largest error, 0.99, rounded up
    outline = next(c for c in ax.collections if c.get_label() == OUTLINE_LABEL)
    assert len(outline.get_segments()) == 0


@pytest.mark.parametrize(
    ("error_map", "message"),
    [
        (np.zeros((3, 2)), r"shape \(3, 2\), but the card's taxtel grid is 2 rows x 3 columns: "
                           r"it must be \(2, 3\)"),
        (np.zeros(6), r"shape \(6,\)"),
        (np.zeros((1, 2, 3)), r"shape \(1, 2, 3\)"),
        ([[0.0, "a", 1.0], [0.0, 0.0, 0.0]], "must be a 2-D array of numbers"),
        (np.array([[0.0, -0.1, 0.0], [0.0, 0.0, 0.0]]), "negative or infinite"),
        (np.array([[0.0, math.inf, 0.0], [0.0, 0.0, 0.0]]), "negative or infinite"),
    ],
    ids=["transposed", "flat", "3-d", "text", "negative", "infinite"],
)
def test_a_map_that_does_not_fit_is_refused(error_map, message: str) -> None:
    card = two_by_three_card()
    with pytest.raises(ValueError, match=message):
        preview_figure(card, error_map=error_map)
    with pytest.raises(ValueError, match=message):
        error_panel(error_map, card.grid, "error")


def test_the_encoders_error_map_fits_its_card(tmp_path: Path) -> None:
    """The call ``hcard encode --preview`` makes: the per-taxtel RMS error in JND."""
    from hcard_builtins.image.encoder import encode_image

    image = tmp_path / "steps.png"
    y, x = np.mgrid[0:60, 0:80]
    Image.fromarray(np.where((x // 10 + y // 15) % 2, 230, 20).astype(np.uint8)).save(image)
    result = encode_image(image, width_mm=40.0, taxtel_mm=5.0, components=2)
    error_jnd = result.maps["error_rms"] / RELATIVE_FRICTION_JND
    ax = _error_axes(preview_figure(result.card, error_map=error_jnd, error_label="RMS error"))
    above = result.stats["taxtels_over_jnd"]  # counted by the encoder: rms > 1 JND
    taxtels = result.card.grid.rows * result.card.grid.cols
    assert 0 < above < taxtels  # steps the taxtels do not follow: some above 1 JND, not all
    assert ax.get_title(loc="left").endswith(
        f"; {above} of {taxtels} taxtels above 1 JND, outlined")
