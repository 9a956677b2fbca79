"""The preview explains itself, checked on the rendered image: little blank paper and no blank
block, profiles over one common length (the cycles of a 1 mm and a 4 mm grating counted in the
pixels), an error map whose colours tell 0.01 from 0.02 JND, the legend above the cells."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import hcard
from hcard import build
from hcard.limits import RELATIVE_FRICTION_JND
from hcard.preview.picture import PERIODS_AXES_LABEL, preview_figure, preview_png

from .pixels import blank_block_share, largest_blank_rectangle, white_share

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
WHITE_SHARE_MAX = 0.45
"""At most this share of the example's preview is near-white paper."""
WHITE_SHARE_ANY_MAX = 0.5
"""At most this share of any small card's preview (a short, wide map leaves more paper)."""
BLANK_BLOCK_MAX = 0.08
"""No blank rectangle (in tiles of 20 px) covers more than this share of a preview."""
DPI = 100


def _rgb(png: bytes) -> np.ndarray:
    with Image.open(io.BytesIO(png)) as image:
        return np.asarray(image.convert("RGB"))


def grating_card(periods_mm: tuple[float, ...] = (1.0, 4.0)) -> hcard.Card:
    textures = [build.texture(0.65, [build.grating_period(p, 0.25)], channel="uv",
                              name=f"{p:g} mm") for p in periods_mm]
    index = np.arange(32) % len(textures)
    return build.card(40.0, 20.0, taxtel_mm=5.0, textures=textures, texture_index=index,
                      title="gratings")


@pytest.fixture(scope="module")
def gratings_example() -> tuple[hcard.Card, np.ndarray]:
    """examples/gratings.png encoded as ``hcard encode --preview`` does, with its error map."""
    from hcard_builtins.image.encoder import encode_image

    result = encode_image(EXAMPLES / "gratings.png")
    return result.card, result.maps["error_rms"] / RELATIVE_FRICTION_JND


# ------------------------------------------------------------------------------ layout


@pytest.mark.parametrize("with_error_map", [True, False], ids=["error-map", "no-error-map"])
def test_gratings_example_is_not_mostly_blank(gratings_example, with_error_map: bool) -> None:
    card, error_jnd = gratings_example
    rgb = _rgb(preview_png(card, dpi=DPI, error_map=error_jnd if with_error_map else None))
    assert white_share(rgb) < WHITE_SHARE_MAX
    width, height = largest_blank_rectangle(rgb)
    assert blank_block_share(rgb) < BLANK_BLOCK_MAX, (width, height, rgb.shape)


@pytest.mark.parametrize("periods", [(2.0,), (1.0, 4.0), (1.0, 1.6, 2.0), tuple(
    0.5 + 0.25 * k for k in range(9))], ids=["1", "2", "3", "9"])
def test_any_palette_leaves_no_blank_block(periods: tuple[float, ...]) -> None:
    card = grating_card(periods)
    for error_map in (None, np.full((card.grid.rows, card.grid.cols), 0.3)):
        rgb = _rgb(preview_png(card, dpi=DPI, error_map=error_map))
        assert white_share(rgb) < WHITE_SHARE_ANY_MAX
        assert blank_block_share(rgb) < BLANK_BLOCK_MAX, largest_blank_rectangle(rgb)


# ------------------------------------------------------------------------------ profiles


def _curve_rows(rgb: np.ndarray, box_px: tuple[int, int, int, int]) -> np.ndarray:
    """Row of the darkest pixel in each column of a strip, ``box_px`` = left, top, right,
    bottom in image pixels: the friction curve, once the horizontal lines (natural friction,
    friction levels: rows dark across a third of the strip or more) are masked."""
    left, top, right, bottom = box_px
    ink = rgb[top:bottom, left:right].astype(float).sum(axis=2)
    lines = (ink < 600).mean(axis=1) > 0.3
    lines = lines | np.roll(lines, 1) | np.roll(lines, -1)
    ink[lines] = np.inf
    return ink.argmin(axis=0).astype(float)


def _crossings(profile: np.ndarray) -> int:
    """Crossings of the profile's mid-level, with a hysteresis of a tenth of its span."""
    mid = (profile.max() + profile.min()) / 2
    margin = 0.1 * (profile.max() - profile.min())
    state, count = 0, 0
    for value in profile:
        side = 1 if value > mid + margin else -1 if value < mid - margin else 0
        if side and state and side != state:
            count += 1
        state = side or state
    return count


def test_a_1_mm_grating_shows_four_times_the_cycles_of_a_4_mm_one() -> None:
    card = grating_card((1.0, 4.0))
    rgb = _rgb(preview_png(card, dpi=DPI))
    fig = preview_figure(card, dpi=DPI)
    fig.canvas.draw()
    ax = next(a for a in fig.axes if a.get_label() == PERIODS_AXES_LABEL)
    strips = next(c for c in ax.collections if c.get_label() == "period-strips")
    height = rgb.shape[0]
    cycles = []
    for path in strips.get_paths():
        (x0, y0), (x1, y1) = ax.transData.transform(path.vertices).min(0), \
            ax.transData.transform(path.vertices).max(0)
        box = (round(x0) + 2, round(height - y1) + 2, round(x1) - 2, round(height - y0) - 2)
        cycles.append(_crossings(_curve_rows(rgb, box)) / 2)
    fine, coarse = cycles
    assert coarse >= 2  # several periods, not one
    assert abs(fine - 4 * coarse) <= 1.0, cycles


def test_every_profile_spans_the_same_length_on_a_labelled_axis() -> None:
    from hcard.preview.periods import TICK_LABELS, Y_AXIS_LABELS

    fig = preview_figure(grating_card((1.0, 4.0)))
    ax = next(a for a in fig.axes if a.get_label() == PERIODS_AXES_LABEL)
    texts = [t for c in ax.collections if c.get_label() == TICK_LABELS for t in c.texts]
    # 4 x the longest period (4 mm) = 16, rounded up to 20 mm, the same under both strips
    assert texts.count("20 mm") == 2 and texts.count("0") == 2
    axis = next(c for c in ax.collections if c.get_label() == Y_AXIS_LABELS)
    assert set(axis.texts) == {"μ/μ0"}


# ------------------------------------------------------------------------------ error map


def test_an_error_map_of_001_and_002_jnd_shows_two_colours() -> None:
    from hcard.preview.error_map import ERROR_AXES_LABEL

    card = grating_card((1.0, 4.0))
    errors = np.where(np.indices((card.grid.rows, card.grid.cols)).sum(axis=0) % 2, 0.01, 0.02)
    rgb = _rgb(preview_png(card, dpi=DPI, error_map=errors)).astype(float)
    fig = preview_figure(card, dpi=DPI, error_map=errors)
    fig.canvas.draw()
    ax = next(a for a in fig.axes if a.get_label() == ERROR_AXES_LABEL)
    height = rgb.shape[0]

    def colour(row: int, col: int) -> np.ndarray:
        x, y = ax.transData.transform(((col + 0.5) * 5.0, (row + 0.5) * 5.0))
        return rgb[round(height - y), round(x)]

    low, high = colour(0, 1), colour(0, 0)  # 0.01 JND and 0.02 JND
    assert np.linalg.norm(high - low) > 60.0, (low, high)
    np.testing.assert_allclose(colour(1, 0), low, atol=2)  # the same value, the same colour
    title = ax.get_title(loc="left")
    assert "max 0.02 JND" in title and "p95 0.02 JND" in title and "0-0.02 JND" in title


# ------------------------------------------------------------------------------ legend


def test_the_legend_sits_above_the_cells_and_explains_every_mark() -> None:
    from hcard.preview.periods import CELL_LABELS, HEADER, LEGEND, STRIPS

    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(0.6, [build.grating_period(2.0, 0.2)], channel="uv"),
        build.texture(1.0, [build.spatial(0.5, 0.2), build.temporal(100.0, 0.1)],
                      channel="bipolar")], texture_index=[0, 1])
    fig = preview_figure(card)
    ax = next(a for a in fig.axes if a.get_label() == PERIODS_AXES_LABEL)
    marks = {c.get_label(): c for c in ax.collections}
    legend = marks[LEGEND].texts
    assert any(t.startswith("grey: out of reach of a UV-only texture") for t in legend)
    assert any(t.startswith("UV drive u") for t in legend)
    assert any(t.startswith("EV drive e") for t in legend)
    assert any(t.startswith("1: natural friction") for t in legend)
    (header,) = marks[HEADER].texts
    assert "over the same 10 mm" in header and "versus time over the same 50 ms" in header
    # above the first cell's label, in the same column
    top_of_cells = min(y for _, y in marks[CELL_LABELS].get_offsets())
    assert max(y for _, y in marks[LEGEND].get_offsets()) < top_of_cells
    left_of_cells = min(p.vertices[:, 0].min() for p in marks[STRIPS].get_paths())
    assert min(x for x, _ in marks[LEGEND].get_offsets()) >= left_of_cells - 0.5
    # and nothing explains the picture in a footer any more
    footers = [a for a in fig.artists if "grey" in " ".join(getattr(a, "texts", []))]
    assert footers == []
