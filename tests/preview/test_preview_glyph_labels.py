"""Labels drawn as glyph outlines: laid out like matplotlib's own text, sized in points."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.textpath import TextPath

from hcard.preview.glyph_labels import LINE_STEP_EM, PathLabels, label_outline


@pytest.mark.parametrize("text", ["27 UV vel.", "0.36 mm | 12 ms", "texture 4 (fine)"])
def test_outline_matches_matplotlibs_text_path(text: str) -> None:
    ours = label_outline(text, ha="left", va="baseline").get_extents()
    theirs = TextPath((0.0, 0.0), text, size=1.0).get_extents()
    # Same glyphs and advances; only kerning (left out here) moves letters, by a few hundredths
    # of an em a pair: the width agrees to 1 %.
    assert ours.x0 == pytest.approx(theirs.x0, abs=1e-9)
    assert ours.x1 == pytest.approx(theirs.x1, rel=0.01)
    assert ours.y0 == pytest.approx(theirs.y0, abs=1e-9)
    assert ours.y1 == pytest.approx(theirs.y1, abs=1e-9)


def test_alignment() -> None:
    cap = TextPath((0.0, 0.0), "H", size=1.0).get_extents().y1
    top = label_outline("H", ha="left", va="top").get_extents()
    assert top.y1 == pytest.approx(0.0, abs=1e-9)
    centre = label_outline("H", ha="center", va="center").get_extents()
    assert centre.y0 == pytest.approx(-cap / 2) and centre.y1 == pytest.approx(cap / 2)
    assert centre.x0 == pytest.approx(-centre.x1, abs=0.01)  # H's side bearings are equal
    right = label_outline("H", ha="right", va="baseline").get_extents()
    assert right.x1 < 0.0 < right.x1 + 0.1  # only the right side bearing beyond the ink
    two = label_outline("H\nH", ha="left", va="top").get_extents()
    assert two.y0 == pytest.approx(-cap - LINE_STEP_EM)


def _ink_rows(pixels: np.ndarray) -> np.ndarray:
    return np.nonzero((pixels[:, :, :3] < 128).any(axis=(1, 2)))[0]


def test_labels_are_as_tall_as_matplotlib_text_of_the_same_size() -> None:
    fig = Figure(figsize=(4.0, 2.0), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    labels = PathLabels(["H", "H"], np.array([[0.1, 0.5], [0.3, 0.5]]), size_pt=36.0,
                        inches=fig.dpi_scale_trans, offset_transform=ax.transAxes, va="top")
    ax.add_collection(labels, autolim=False)
    ax.text(0.6, 0.5, "H", fontsize=36.0, va="top", transform=ax.transAxes)
    fig.canvas.draw()
    pixels = np.asarray(fig.canvas.buffer_rgba())
    ours, theirs = pixels[:, :160], pixels[:, 240:]
    # the cap height of DejaVu Sans is 0.729 em: 36 pt -> 26.2 pt -> 36.5 px at 100 dpi
    assert len(_ink_rows(ours)) == pytest.approx(len(_ink_rows(theirs)), abs=2)
    assert len(_ink_rows(ours)) == pytest.approx(36.5, abs=2)
    assert _ink_rows(ours)[0] == pytest.approx(100, abs=1)  # tops at the anchor, mid-height
    assert labels.texts == ["H", "H"]
    # both labels drawn, each at its anchor (x = 0.1 and 0.3 of 400 px) plus H's left bearing
    bearing_px = TextPath((0.0, 0.0), "H", size=36.0).get_extents().x0 * 100 / 72
    ink = (ours[:, :, :3] < 128).any(axis=(0, 2))
    starts = np.nonzero(ink[1:] & ~ink[:-1])[0] + 1
    np.testing.assert_allclose(starts, [40 + bearing_px, 120 + bearing_px], atol=1.5)
