"""A picture of a card a person can read: the taxtel map, the error map and every texture's
relative friction along a common length.

Top left: the taxtel grid over the surface (millimetres, origin top-left, y downwards, equal
aspect), coloured by texture index, with a colour bar naming the textures; beside it, when the
caller passes one, an error map of the taxtels in JND (:mod:`hcard.preview.error_map`) with its
colour bar. Then one cell per texture, all of them (up to the format's 256), drawn as small
multiples in a single axes (:mod:`hcard.preview.periods`): the texture's relative friction
``mu/mu0`` and its UV and EV drives along one shared length in mm (and, for a texture with
temporal components, versus one shared time in ms), every cell on the same friction scale, an
explanation with a legend above them. The cells fill the room right of the maps first, then
full rows below them, so the picture has no empty blocks; its height follows the content. The
layout is computed in inches (no constrained layout) and every kind of mark is drawn with one
collection, so the cost hardly grows with the palette. Rendering uses matplotlib's Agg canvas
directly (no pyplot, no display).

>>> from hcard.preview.picture import render_preview
>>> render_preview(card, "preview.png")          # doctest: +SKIP
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure

from hcard.atomic import write_atomically
from hcard.preview.error_map import ErrorPanel, draw_error_map, error_panel
from hcard.preview.glyph_labels import PathLabels, text_width
from hcard.preview.periods import cells_layout, draw_cells
from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid
from hcard.version import __version__

__all__ = [
    "GRID_AXES_LABEL",
    "PERIODS_AXES_LABEL",
    "preview_figure",
    "preview_png",
    "render_preview",
    "texture_colors",
]

GRID_LINES_MAX = 100
"""Taxtel boundaries are drawn when the grid has at most this many columns and rows."""
LABELS_MAX = 24
"""Texture numbers are written on the taxtels when the grid has at most this many columns/rows."""
GRID_AXES_LABEL = "taxtel-grid"
"""``Axes.get_label()`` of the taxtel map (lets tests and tools find it)."""
GRID_BAR_LABEL = "texture-colour-bar"
"""``Axes.get_label()`` of the taxtel map's colour bar."""
PERIODS_AXES_LABEL = "texture-periods"
"""``Axes.get_label()`` of the axes holding every texture's profile strips (it spans the
figure; its data units are inches from the figure's top-left, y downwards)."""
PNG_COMPRESS_LEVEL = 3
"""zlib level of the PNG: on a 256-texture preview as small as Pillow's default (6) and a third
faster to write."""
FIGURE_WIDTH_IN = 14.0
"""Width of the picture, inches."""
_TOP_IN, _BOTTOM_IN = 0.35, 0.12  # title band, margin below the cells
_MAP_LEFT_IN, _MAP_WIDTH_IN, _MAP_MAX_HEIGHT_IN = 0.8, 4.3, 5.5
_PAIR_MAP_MAX_WIDTH_IN = 5.0  # each of the taxtel and error maps side by side, at most
_MAP_ABOVE_IN, _MAP_BELOW_IN = 0.5, 0.5  # title (two lines) above a map, ticks and label below
_BAR_GAP_IN, _BAR_WIDTH_IN, _BAR_MIN_HEIGHT_IN = 0.12, 0.15, 1.5  # a map's colour bar
_ERROR_BAR_LABELS_IN = 0.75  # tick labels and label right of the error map's colour bar
_MAP_Y_LABELS_IN = 0.65  # y ticks and label left of the error map
_RIGHT_IN, _BELOW_LEFT_IN = 0.15, 0.05  # margins of the cells' regions


def texture_colors(count: int) -> np.ndarray:
    """RGBA colours (``count`` x 4, floats 0-1) of texture indices 0..count-1.

    Categorical palettes: tab10 up to 10 textures, tab20 (dark shades first) up to 20, tab20 +
    tab20b + tab20c up to 60, evenly spaced turbo colours beyond.
    """
    if count <= 10:
        palette = list(colormaps["tab10"].colors)  # type: ignore[attr-defined]
    elif count <= 20:
        tab20 = list(colormaps["tab20"].colors)  # type: ignore[attr-defined]
        palette = tab20[0::2] + tab20[1::2]
    elif count <= 60:
        palette = [
            colour
            for name in ("tab20", "tab20b", "tab20c")
            for colour in colormaps[name].colors  # type: ignore[attr-defined]
        ]
    else:
        return colormaps["turbo"](np.linspace(0.05, 0.95, count))
    rgba = np.ones((count, 4))
    rgba[:, :3] = np.asarray(palette[:count], dtype=float)
    return rgba


Rect = tuple[float, float, float, float]
"""A figure-fraction rectangle: left, bottom, width, height."""


def _draw_grid(fig: Figure, rect: Rect, bar_rect: Rect, card: pb.Card,
               colours: np.ndarray) -> Axes:
    """The taxtel map in ``rect`` and a colour bar of texture numbers (and names) in
    ``bar_rect`` (figure fractions)."""
    grid = card.grid
    count = len(card.textures)
    tw, th = grid.taxtel_width_mm, grid.taxtel_height_mm
    index = np.asarray(grid.texture_index, dtype=np.int64).reshape(grid.rows, grid.cols)
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(-0.5, count + 0.5), count)

    ax = fig.add_axes(rect, label=GRID_AXES_LABEL)
    ax.imshow(
        index,
        cmap=cmap,
        norm=norm,
        interpolation="nearest",
        origin="upper",
        extent=(0.0, grid.cols * tw, grid.rows * th, 0.0),
    )
    if grid.cols <= GRID_LINES_MAX and grid.rows <= GRID_LINES_MAX:
        ax.vlines([c * tw for c in range(1, grid.cols)], 0, grid.rows * th, colors="white", lw=0.6)
        ax.hlines([r * th for r in range(1, grid.rows)], 0, grid.cols * tw, colors="white", lw=0.6)
    if grid.cols <= LABELS_MAX and grid.rows <= LABELS_MAX:
        luminance = colours[:, :3] @ np.array([0.299, 0.587, 0.114])
        rows, cols = np.indices(index.shape)
        centres = np.column_stack([(cols.ravel() + 0.5) * tw, (rows.ravel() + 0.5) * th])
        ink = np.where(luminance[index.ravel()] > 0.5, "black", "white")
        ax.add_collection(PathLabels([str(v) for v in index.ravel()], centres, size_pt=8.0,
                                     inches=fig.dpi_scale_trans, offset_transform=ax.transData,
                                     ha="center", va="center", colors=list(ink), zorder=3),
                          autolim=False)
    _frame_surface(ax, card)
    ax.set_title("taxtel grid, coloured by texture", fontsize=9, loc="left")

    if count <= 32:
        ticks = list(range(count))
    else:
        ticks = sorted({round(v) for v in np.linspace(0, count - 1, 9)})
    cax = fig.add_axes(bar_rect, label=GRID_BAR_LABEL)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, ticks=ticks)
    if count <= 32:
        names = [t.name if len(t.name) <= 18 else t.name[:17] + "…" for t in card.textures]
        bar.set_ticklabels([f"{i} {name}".rstrip() for i, name in enumerate(names)])
    bar.ax.tick_params(labelsize=7)
    bar.minorticks_off()  # one per texture otherwise: 256 ticks cost 0.2 s
    return ax


def _frame_surface(ax: Axes, card: pb.Card) -> None:
    """Limits, aspect and labels of a map of the surface (mm, y downwards)."""
    ax.set_xlim(0.0, card.surface.width_mm)
    ax.set_ylim(card.surface.height_mm, 0.0)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)", fontsize=9, labelpad=2)
    ax.set_ylabel("y (mm), downwards", fontsize=9, labelpad=2)
    ax.tick_params(labelsize=8)


def _map_size(surface: pb.Surface, width_in: float = _MAP_WIDTH_IN) -> tuple[float, float]:
    """Width and height of a surface map, inches: ``width_in`` wide unless that makes it taller
    than :data:`_MAP_MAX_HEIGHT_IN`."""
    aspect = surface.height_mm / surface.width_mm
    width = min(width_in, _MAP_MAX_HEIGHT_IN / aspect)
    return width, width * aspect


def _bar_labels_width(card: pb.Card) -> float:
    """Room the texture colour bar's tick labels take right of it, inches."""
    count = len(card.textures)
    if count > 32:
        return text_width(str(count - 1), 7.0) + 0.15
    names = [t.name if len(t.name) <= 18 else t.name[:17] + "…" for t in card.textures]
    return max(text_width(f"{i} {name}".rstrip(), 7.0) for i, name in enumerate(names)) + 0.15


def preview_figure(
    card: pb.Card,
    *,
    dpi: int = 120,
    error_map: np.ndarray | Sequence[Sequence[float]] | None = None,
    error_label: str = "reconstruction error",
    check: bool = True,
) -> Figure:
    """The preview as a matplotlib figure (Agg canvas attached, not yet drawn).

    Args:
        card: a valid card.
        dpi: resolution, dots per inch.
        error_map: optional error of each taxtel in JND (multiples of
            :data:`hcard.limits.RELATIVE_FRICTION_JND`), shape ``(grid.rows, grid.cols)``, row 0
            at the top; NaN for a taxtel without a figure. Drawn under the taxtel map with a
            colour bar in JND and the taxtels above 1 JND outlined.
        error_label: what the error map shows, for its title (for example ``"RMS error"``).
        check: validate the card first; False for a card the caller has validated
            (:func:`hcard.card_io.load`, :func:`hcard.validate.require_valid`).

    Raises:
        CardValidationError: ``check`` and the card is invalid (a preview of it would be
            meaningless).
        ValueError: ``dpi`` is not positive, or ``error_map`` does not fit the grid or holds
            negative or infinite values.
    """
    if dpi <= 0:
        raise ValueError(f"dpi must be positive, got {dpi}")
    if check:
        require_valid(card)
    panel: ErrorPanel | None = None
    if error_map is not None:
        panel = error_panel(error_map, card.grid, error_label)
    textures = list(card.textures)
    labels_w = _bar_labels_width(card)
    bar_room = _BAR_GAP_IN + _BAR_WIDTH_IN + labels_w
    if panel is not None:  # the two maps side by side, as wide as the figure lets them
        spare = (FIGURE_WIDTH_IN - _MAP_LEFT_IN - bar_room - _MAP_Y_LABELS_IN - _BAR_GAP_IN
                 - _BAR_WIDTH_IN - _ERROR_BAR_LABELS_IN - _RIGHT_IN)
        map_w, map_h = _map_size(card.surface, min(spare / 2, _PAIR_MAP_MAX_WIDTH_IN))
    else:
        map_w, map_h = _map_size(card.surface)
    bar_h = max(map_h, _BAR_MIN_HEIGHT_IN)
    maps_h = _MAP_ABOVE_IN + bar_h + _MAP_BELOW_IN
    maps_right = _MAP_LEFT_IN + map_w + bar_room
    error_left = maps_right + _MAP_Y_LABELS_IN
    if panel is not None:
        maps_right = error_left + map_w + _BAR_GAP_IN + _BAR_WIDTH_IN + _ERROR_BAR_LABELS_IN
    beside_w = FIGURE_WIDTH_IN - _RIGHT_IN - maps_right
    layout = cells_layout(
        textures, beside=(maps_right, _TOP_IN, beside_w, maps_h) if beside_w > 0 else None,
        below=(_BELOW_LEFT_IN, FIGURE_WIDTH_IN - _BELOW_LEFT_IN - _RIGHT_IN),
        below_top=_TOP_IN + maps_h, dpi=dpi)
    height = max(_TOP_IN + maps_h, layout.bottom) + _BOTTOM_IN

    fig = Figure(figsize=(FIGURE_WIDTH_IN, height), dpi=dpi)
    FigureCanvasAgg(fig)

    def rect(left_in: float, top_in: float, width_in: float, height_in: float) -> Rect:
        """Figure-fraction rectangle of a box given in inches from the top-left."""
        return (left_in / FIGURE_WIDTH_IN, 1.0 - (top_in + height_in) / height,
                width_in / FIGURE_WIDTH_IN, height_in / height)

    colours = texture_colors(len(textures))
    top = _TOP_IN + _MAP_ABOVE_IN
    _draw_grid(fig, rect(_MAP_LEFT_IN, top, map_w, map_h),
               rect(_MAP_LEFT_IN + map_w + _BAR_GAP_IN, top, _BAR_WIDTH_IN, bar_h), card,
               colours)
    if panel is not None:
        ax = fig.add_axes(rect(error_left, top, map_w, map_h))
        cax = fig.add_axes(rect(error_left + map_w + _BAR_GAP_IN, top, _BAR_WIDTH_IN, bar_h))
        draw_error_map(fig, ax, cax, panel, card.grid)
        _frame_surface(ax, card)
    periods = fig.add_axes((0.0, 0.0, 1.0, 1.0), label=PERIODS_AXES_LABEL)
    periods.set_xlim(0.0, FIGURE_WIDTH_IN)
    periods.set_ylim(height, 0.0)
    periods.set_axis_off()
    draw_cells(periods, textures, colours, layout, dpi, fig.dpi_scale_trans)

    title = card.metadata.title or "(untitled card)"
    grid, surface = card.grid, card.surface
    fig.text(
        0.5,
        1.0 - 0.12 / height,
        f"{title}: {surface.width_mm:g} × {surface.height_mm:g} mm, "
        f"{grid.cols} × {grid.rows} taxtels of {grid.taxtel_width_mm:g} × "
        f"{grid.taxtel_height_mm:g} mm, {len(textures)} texture{'' if len(textures) == 1 else 's'}",
        fontsize=11,
        ha="center",
        va="top",
    )
    fig.add_artist(PathLabels(
        [f"hcard {__version__}"], np.array([[1.0 - _RIGHT_IN / FIGURE_WIDTH_IN,
                                             1.0 - 0.12 / height]]),
        size_pt=6.5, inches=fig.dpi_scale_trans, offset_transform=fig.transFigure, ha="right",
        va="top", colors="0.45"))
    return fig


def render_preview(
    card: pb.Card,
    path: str | os.PathLike[str],
    *,
    dpi: int = 120,
    error_map: np.ndarray | Sequence[Sequence[float]] | None = None,
    error_label: str = "reconstruction error",
    check: bool = True,
) -> None:
    """Write the preview of ``card`` as a PNG image to ``path``, atomically.

    The image is rendered in memory first, so a failure never leaves a partial file.

    Args:
        card: a valid card.
        path: output file (PNG bytes whatever the suffix).
        dpi: resolution, dots per inch; the figure is 14 inches wide (1680 pixels at 120 dpi).
        error_map, error_label: an error map in JND and its title (see :func:`preview_figure`).
        check: validate the card first (see :func:`preview_figure`).

    Raises:
        CardValidationError: ``check`` and the card is invalid.
        ValueError: the error map does not fit the card's grid.
        OSError: the file cannot be written.
    """
    write_atomically(path, preview_png(card, dpi=dpi, error_map=error_map,
                                       error_label=error_label, check=check))


def preview_png(
    card: pb.Card,
    *,
    dpi: int = 120,
    error_map: np.ndarray | Sequence[Sequence[float]] | None = None,
    error_label: str = "reconstruction error",
    check: bool = True,
) -> bytes:
    """The preview of ``card`` as PNG bytes (:func:`render_preview` without the file), so a
    caller can render it before it replaces anything; ``check``: validate the card first (see
    :func:`preview_figure`).

    Raises:
        CardValidationError: ``check`` and the card is invalid.
        ValueError: the error map does not fit the card's grid.
    """
    fig = preview_figure(card, dpi=dpi, error_map=error_map, error_label=error_label,
                         check=check)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, metadata={"Software": f"hcard {__version__}"},
                pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buffer.getvalue()
