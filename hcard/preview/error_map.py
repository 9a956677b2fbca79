"""The error map of a preview: each taxtel's error in JND over the surface.

The caller gives one figure per taxtel (for example the encoder's RMS reconstruction error, in
relative friction, divided by :data:`hcard.limits.RELATIVE_FRICTION_JND`). Errors up to 1 JND
are blues and errors above it yellows to reds, and the taxtels above 1 JND are outlined: a
difference of relative friction below one JND is not felt (thesis appendix B.1, Fig. B.2;
spec/README.md section 10), one above it is. The colour scale follows the data: a map whose
largest error is below 1 JND spreads the whole range of blues over 0 to that largest error
(rounded up), so that taxtels at 0.01 and 0.02 JND differ visibly; a map with errors above 1 JND
gives the lower half of the colour bar to 0-1 JND and the upper half to 1 JND up to the largest.
The title states the largest error, the 95th percentile and the scale's range.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Colormap, ListedColormap, Normalize, TwoSlopeNorm
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from hcard.limits import RELATIVE_FRICTION_JND
from hcard.preview.periods import nice_ceil
from hcard.v1 import card_pb2 as pb

ERROR_AXES_LABEL = "error-map"
"""``Axes.get_label()`` of the error map (lets tests and tools find it)."""
ERROR_BAR_LABEL = "error-colour-bar"
"""``Axes.get_label()`` of the error map's colour bar."""
OUTLINE_LABEL = "over-1-jnd"
"""``Collection.get_label()`` of the outline of the taxtels above 1 JND."""
THRESHOLD_JND = 1.0
"""Errors above this many JND are outlined."""
SCALE_STEPS = (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)
"""A map without errors above 1 JND is coloured from 0 to its largest error rounded up to one
of these times a power of ten (at most a quarter above it)."""
BELOW_THRESHOLD = (0.06, 1.0)
"""The span of matplotlib's ``Blues`` a map without errors above 1 JND spreads over its range
(from nearly white to dark blue)."""


@dataclass(frozen=True)
class ErrorPanel:
    """A checked error map.

    Attributes:
        values: ``(rows, cols)`` errors in JND, row 0 at the top; NaN where there is no figure.
        label: what the values are, for the title (for example ``"RMS error"``).
    """

    values: np.ndarray
    label: str

    @property
    def above(self) -> np.ndarray:
        """``(rows, cols)`` booleans: taxtels whose error exceeds :data:`THRESHOLD_JND`."""
        with np.errstate(invalid="ignore"):
            return self.values > THRESHOLD_JND


def error_panel(
    error_map: np.ndarray | Sequence[Sequence[float]], grid: pb.TaxtelGrid, label: str
) -> ErrorPanel:
    """Check ``error_map`` against the card's grid.

    Raises:
        ValueError: not a 2-D array of numbers of shape ``(grid.rows, grid.cols)``, or a value
            is negative or infinite (NaN is allowed: a taxtel without a figure).
    """
    try:
        values = np.array(error_map, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("error_map must be a 2-D array of numbers (JND per taxtel)") from None
    expected = (grid.rows, grid.cols)
    if values.shape != expected:
        raise ValueError(
            f"error_map has shape {values.shape}, but the card's taxtel grid is {grid.rows} rows "
            f"x {grid.cols} columns: it must be {expected} (rows, cols), row 0 at the top")
    if np.any(np.isinf(values)) or np.any(values < 0.0):
        raise ValueError("error_map holds negative or infinite values; errors are >= 0 JND "
                         "(NaN marks a taxtel without a figure)")
    return ErrorPanel(values, label)


def _runs(boundary: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along the last axis of a 2-D array: ``(line, start, stop)`` (stop
    exclusive), in row-major order."""
    padded = np.zeros((boundary.shape[0], boundary.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = boundary
    step = np.diff(padded, axis=1)
    line, start = np.nonzero(step == 1)
    _, stop = np.nonzero(step == -1)
    return line, start, stop


def outline_segments(mask: np.ndarray, taxtel_w: float, taxtel_h: float) -> np.ndarray:
    """The boundary of the True taxtels of ``mask`` (``rows x cols``, row 0 at the top), as
    ``(n, 2, 2)`` line segments ``((x0, y0), (x1, y1))`` in millimetres (y downwards).

    A segment is an edge between a True taxtel and a False one (or the grid's border); collinear
    edges in a row are joined, so the cost follows the outline, not the grid.
    """
    inside = np.pad(np.asarray(mask, dtype=bool), 1)
    horizontal = inside[:-1, 1:-1] != inside[1:, 1:-1]  # (rows + 1, cols): edge above row r
    vertical = inside[1:-1, :-1] != inside[1:-1, 1:]  # (rows, cols + 1): edge left of col c
    y_line, x_start, x_stop = _runs(horizontal)
    x_line, y_start, y_stop = _runs(vertical.T)
    segments = np.empty((len(y_line) + len(x_line), 2, 2))
    h = len(y_line)
    segments[:h, 0, 0], segments[:h, 1, 0] = x_start * taxtel_w, x_stop * taxtel_w
    segments[:h, :, 1] = (y_line * taxtel_h)[:, None]
    segments[h:, :, 0] = (x_line * taxtel_w)[:, None]
    segments[h:, 0, 1], segments[h:, 1, 1] = y_start * taxtel_h, y_stop * taxtel_h
    return segments


def error_colormap() -> ListedColormap:
    """256 colours: light to mid blues for the lower half (0 to 1 JND with :func:`error_norm`),
    yellow through red to dark red for the upper half (above 1 JND)."""
    below = colormaps["Blues"](np.linspace(0.08, 0.6, 128))
    above = colormaps["YlOrRd"](np.linspace(0.25, 1.0, 128))
    return ListedColormap(np.vstack([below, above]), name="hcard-error")


def largest(values: np.ndarray) -> float:
    """The largest error of the map, 0 when it has none."""
    return float(np.nanmax(values)) if np.any(np.isfinite(values)) else 0.0


def error_norm(values: np.ndarray) -> Normalize:
    """The colour scale of ``values``: 0 to the largest error rounded up to
    :data:`SCALE_STEPS` when it is at most 1 JND (a map without errors: 0 to 1 JND); else 0 JND
    to the colour map's bottom, 1 JND to its middle and the largest error to its top."""
    top = largest(values)
    if top <= THRESHOLD_JND:
        return Normalize(vmin=0.0, vmax=min(nice_ceil(top, SCALE_STEPS), THRESHOLD_JND)
                         if top > 0 else THRESHOLD_JND)
    return TwoSlopeNorm(vmin=0.0, vcenter=THRESHOLD_JND, vmax=top)


def scale_colormap(norm: Normalize) -> Colormap:
    """The colours of :func:`error_norm`'s scale: all blues below the threshold, else
    :func:`error_colormap`."""
    if isinstance(norm, TwoSlopeNorm):
        return error_colormap()
    return ListedColormap(colormaps["Blues"](np.linspace(*BELOW_THRESHOLD, 256)),
                          name="hcard-error-below")


def error_title(panel: ErrorPanel, top: float) -> str:
    """The map's title: what it shows, its largest error and 95th percentile, the colour
    scale's range and the taxtels above 1 JND."""
    counted = int(np.count_nonzero(~np.isnan(panel.values)))
    if counted == 0:
        return f"{panel.label} (JND): no taxtel has a figure"
    p95 = float(np.nanpercentile(panel.values, 95))
    above = int(panel.above.sum())
    felt = (f"{above} of {counted} taxtels above {THRESHOLD_JND:g} JND, outlined" if above else
            f"all {counted} taxtels below {THRESHOLD_JND:g} JND (not felt)")
    return (f"{panel.label}: max {largest(panel.values):.2g} JND, p95 {p95:.2g} JND\n"
            f"colour scale 0-{top:.2g} JND; {felt}")


def draw_error_map(fig: Figure, ax: Axes, cax: Axes, panel: ErrorPanel,
                   grid: pb.TaxtelGrid) -> None:
    """The error map in ``ax``: the values over the grid's extent, the outline of the taxtels
    above 1 JND and a title counting those taxtels; its colour bar in JND in ``cax``."""
    tw, th = grid.taxtel_width_mm, grid.taxtel_height_mm
    norm = error_norm(panel.values)
    ax.set_label(ERROR_AXES_LABEL)
    cax.set_label(ERROR_BAR_LABEL)
    image = ax.imshow(
        panel.values,
        cmap=scale_colormap(norm),
        norm=norm,
        interpolation="nearest",
        origin="upper",
        extent=(0.0, grid.cols * tw, grid.rows * th, 0.0),
    )
    above = panel.above
    # LineCollection takes the (n, 2, 2) array; its stubs ask for a sequence of segments.
    ax.add_collection(LineCollection(outline_segments(above, tw, th),  # type: ignore[arg-type]
                                     colors="black",
                                     linewidths=0.9, label=OUTLINE_LABEL, zorder=3))
    top = norm.vmax
    assert top is not None  # error_norm sets both ends
    ax.set_title(error_title(panel, top), fontsize=9, loc="left")
    if isinstance(norm, TwoSlopeNorm):
        upper = [v for v in MaxNLocator(nbins=4).tick_values(THRESHOLD_JND, top)
                 if THRESHOLD_JND < v <= top]
        ticks = [0.0, 0.5, THRESHOLD_JND, *upper]
    else:
        ticks = [v for v in MaxNLocator(nbins=5).tick_values(0.0, top) if 0.0 <= v <= top]
    bar = fig.colorbar(image, cax=cax, ticks=ticks)
    if isinstance(norm, TwoSlopeNorm):
        bar.ax.axhline(THRESHOLD_JND, color="black", linewidth=1.2)
    bar.set_label(f"JND (1 JND = {RELATIVE_FRICTION_JND:g} μ/μ0)", fontsize=8)
    bar.ax.tick_params(labelsize=7)
