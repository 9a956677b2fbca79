"""Many short labels drawn as one collection of glyph outlines.

matplotlib lays out and rasterises every ``Text`` glyph by glyph: on Agg about 1 ms per short
label plus some 50 us per character, so the 256 texture cells and up to 576 taxtel numbers of a
preview cost seconds as ``Text``. Here each character's outline is taken once from the font
(:class:`matplotlib.textpath.TextPath`), a label is its characters' outlines placed side by side
by their advance widths (no kerning: the labels are numbers, units and short words), and all
labels of one size form one :class:`~matplotlib.collections.PathCollection`, filled in a single
draw call. The outlines are in inches and follow the figure's resolution; the labels' anchors are
in data coordinates, so they stay put whichever way an axis points.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import numpy as np
from matplotlib import ft2font
from matplotlib.collections import PathCollection
from matplotlib.font_manager import FontProperties, findfont
from matplotlib.path import Path
from matplotlib.textpath import TextPath
from matplotlib.transforms import Transform

LINE_STEP_EM = 1.2
"""Distance between the baselines of two lines of a label, in font sizes."""
CAP_HEIGHT_CHAR = "H"
"""The character whose height anchors ``va="top"`` and ``va="center"``."""
_NO_HINTING = (ft2font.LoadFlags.NO_HINTING if hasattr(ft2font, "LoadFlags")
               else ft2font.LOAD_NO_HINTING)  # type: ignore[attr-defined]  # matplotlib < 3.10


@lru_cache(maxsize=4)
def _font(path: str) -> ft2font.FT2Font:
    """A FT2Font of our own (the renderer's shared ones change size under it), at 1 pixel per
    em so that advances come out in ems."""
    font = ft2font.FT2Font(path)
    font.set_size(1.0, 72.0)
    return font


@lru_cache(maxsize=2048)
def _glyph(path: str, character: str) -> tuple[np.ndarray, np.ndarray, float]:
    """``(vertices, codes, advance)`` of ``character`` in the font at ``path``, in ems (y up)."""
    font = _font(path)
    known = font.get_char_index(ord(character)) != 0
    advance = (font.load_char(ord(character), flags=_NO_HINTING).linearHoriAdvance / 65536.0
               if known else 0.0)
    if character.isspace():  # no ink (TextPath refuses a blank)
        return np.empty((0, 2)), np.empty(0, dtype=np.uint8), advance
    outline = TextPath((0.0, 0.0), character, size=1.0, prop=FontProperties(fname=path))
    if not known:  # drawn by a fallback font: advance by its ink
        advance = max(outline.get_extents().x1, 0.0) + 0.1
    return np.asarray(outline.vertices, dtype=float), np.asarray(outline.codes), advance


def _line_glyphs(path: str, line: str) -> tuple[list[tuple[np.ndarray, np.ndarray, float]],
                                                 float]:
    """The inked glyphs of one line with their x offsets (ems), and the line's width."""
    glyphs, x = [], 0.0
    for character in line:
        vertices, codes, advance = _glyph(path, character)
        if len(codes):
            glyphs.append((vertices, codes, x))
        x += advance
    return glyphs, x


def text_width(text: str, size_pt: float, font: str | None = None) -> float:
    """Width of the longest line of ``text`` at ``size_pt`` points, inches (as drawn by
    :class:`PathLabels`: advance widths, no kerning)."""
    path = font or findfont(FontProperties())
    return max(_line_glyphs(path, line)[1] for line in text.split("\n")) * size_pt / 72.0


def label_outline(text: str, *, ha: str = "left", va: str = "top", font: str | None = None,
                  size: float = 1.0, rotation: float = 0.0) -> Path:
    """The outline of ``text`` (lines split at ``"\n"``), y up, anchored at (0, 0), in units of
    ``size`` ems.

    ``ha``: ``"left"``, ``"center"`` or ``"right"`` (each line on its own); ``va``: ``"top"``
    (the first line's capitals touch 0), ``"center"`` (the block's capitals-to-last-baseline
    span centred on 0) or ``"baseline"`` (the first baseline at 0). ``font``: a font file
    (default: matplotlib's default font). ``rotation``: degrees counter-clockwise about the
    anchor, after the alignment (90 for a y-axis label read from below).
    """
    path = font or findfont(FontProperties())
    cap = float(_glyph(path, CAP_HEIGHT_CHAR)[0][:, 1].max())
    lines = text.split("\n")
    block = cap + LINE_STEP_EM * (len(lines) - 1)
    first_baseline = {"top": -cap, "center": block / 2.0 - cap, "baseline": 0.0}[va]
    pieces, codes, origins = [], [], []
    for i, line in enumerate(lines):
        glyphs, width = _line_glyphs(path, line)
        shift = {"left": 0.0, "center": -width / 2.0, "right": -width}[ha]
        baseline = first_baseline - i * LINE_STEP_EM
        for vertices, glyph_codes, x in glyphs:
            pieces.append(vertices)
            codes.append(glyph_codes)
            origins.append((x + shift, baseline))
    if not pieces:
        return Path(np.empty((0, 2)))
    counts = [len(piece) for piece in pieces]
    vertices = np.concatenate(pieces) + np.repeat(np.array(origins), counts, axis=0)
    if rotation:
        angle = np.radians(rotation)
        cos, sin = np.cos(angle), np.sin(angle)
        vertices = vertices @ np.array([[cos, sin], [-sin, cos]])
    return Path(vertices * size, np.concatenate(codes).astype(np.uint8))


class PathLabels(PathCollection):
    """Labels of one size as glyph outlines; :attr:`texts` keeps what they say.

    Args:
        texts: one string per label (``"\\n"`` separates lines).
        offsets: ``(n, 2)`` anchors in the coordinates of ``offset_transform``.
        size_pt: font size, points.
        inches: the figure's ``dpi_scale_trans`` (outlines are laid out in inches).
        offset_transform: for example ``ax.transData``.
        ha, va: alignment to the anchor (see :func:`label_outline`).
        colors: one fill colour, or one per label.
        rotation: degrees counter-clockwise about each anchor (see :func:`label_outline`).
    """

    def __init__(self, texts: Sequence[str], offsets: np.ndarray, *, size_pt: float,
                 inches: Transform, offset_transform: Transform, ha: str = "left",
                 va: str = "top", colors: object = "black", rotation: float = 0.0,
                 **kwargs: Any) -> None:
        self.texts = list(texts)
        font = findfont(FontProperties())
        paths = [label_outline(text, ha=ha, va=va, font=font, size=size_pt / 72.0,
                               rotation=rotation)
                 for text in self.texts]
        super().__init__(paths, offsets=np.asarray(offsets, dtype=float).reshape(-1, 2),
                         offset_transform=offset_transform, facecolors=colors,
                         edgecolors="none", linewidths=0.0, **kwargs)
        self.set_transform(inches)
