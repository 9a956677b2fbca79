"""The figures of a calibration report (:mod:`hcard.calibration.report`):

- ``residuals.png``: one panel per regressor: the binned mean residual (mN) before (base
  model) and after (final model) over a light scatter of the residual before;
- ``fit.png``: observed and predicted lateral force over a stretch of held-out samples, and
  predicted against observed (held-out samples), before and after.

Figures are drawn on matplotlib's Agg canvas directly (no pyplot) and encoded by
:func:`figure_png`.
"""

from __future__ import annotations

import io
import math

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator, ScalarFormatter
from matplotlib.transforms import ScaledTranslation

from hcard.calibration.report.number_text import force_in_mn
from hcard.calibration.results import CalibrationResult
from hcard.preview.glyph_labels import PathLabels
from hcard.quantities import MN_PER_N, N_PER_MN, SI_UNITS, display_unit
from hcard.version import __version__

DPI = 100
"""Resolution of the figures, dots per inch."""
PANEL_INCHES = (3.2, 2.5)
"""Size of one regressor panel of ``residuals.png`` (width, height), inches."""
PANEL_COLUMNS = 3
"""Regressor panels per row."""
FIT_INCHES = (12.0, 4.0)
"""Size of ``fit.png``, inches."""
TICKS = MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10])
"""Where the figures' ticks go (:func:`_fixed_ticks`): at most 5 intervals (matplotlib's own
choice for the panels' axes is 5-8); each tick is a handful of artists to make and draw."""
PNG_COMPRESSION = 1
"""zlib level of the PNG figures: 1 encodes residuals.png in 23 ms instead of 39 ms (level 6,
PIL's default), for a file 15 % larger."""
MARGINS_INCHES = (0.62, 0.12, 0.5, 0.3)
"""Space around each panel's axes (left, right, bottom, top), inches: tick labels and the axis
label at left and below, the title above. The figures place their axes at these fixed margins
instead of running matplotlib's constrained layout, which drew every figure twice (with it,
residuals.png of 9-11 regressors took 0.56-0.79 s, without it and with fixed ticks 0.21-0.36 s;
bench/bench_calibration.py); tests/calibration/test_report.py checks that no panel's labels
leave its cell."""
MAX_SCATTER = 3000
"""Most points of a scatter."""
MAX_STRETCH_S = 2.0
"""Longest stretch of held-out samples drawn over time, s."""

REGRESSOR_UNITS = {
    **SI_UNITS,
    "occlusion_time": "s",
    "amplitude_history": "m",
    "voltage_history": "s",
    "recording": "",
}
"""SI unit of each regressor (:mod:`hcard.physics.effects`,
:mod:`hcard.calibration.dataset`)."""

BEFORE_COLOUR = "tab:orange"
AFTER_COLOUR = "tab:blue"


def figure_png(fig: Figure) -> bytes:
    """``fig`` encoded as PNG at :data:`DPI`, zlib level :data:`PNG_COMPRESSION`."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, metadata={"Software": f"hcard {__version__}"},
                pil_kwargs={"compress_level": PNG_COMPRESSION})
    return buffer.getvalue()


def _subsample(indices: np.ndarray, most: int) -> np.ndarray:
    if indices.size <= most:
        return indices
    pick = np.random.default_rng(0).choice(indices.size, size=most, replace=False)
    return indices[np.sort(pick)]


def residuals_grid(n_regressors: int) -> tuple[int, int]:
    """(rows, columns) of the panels of ``residuals.png`` for ``n_regressors``."""
    columns = max(1, min(PANEL_COLUMNS, n_regressors))
    return max(1, math.ceil(n_regressors / columns)), columns


def _panel(fig: Figure, row: int, column: int, rows: int, cell_inches: tuple[float, float],
           span: int = 1) -> Axes:
    """Axes in the cell (``row``, ``column``) of a ``rows``-row grid of cells of
    ``cell_inches`` (``span`` cells wide), inside :data:`MARGINS_INCHES`."""
    width, height = fig.get_size_inches()
    left, right, bottom, top = MARGINS_INCHES
    x0 = column * cell_inches[0] + left
    y0 = (rows - 1 - row) * cell_inches[1] + bottom
    return fig.add_axes((x0 / width, y0 / height,
                         (span * cell_inches[0] - left - right) / width,
                         (cell_inches[1] - bottom - top) / height))


def _fixed_ticks(ax: Axes) -> None:
    """Fix ``ax``'s ticks for its current limits at :data:`TICKS` (steps of 1, 2, 2.5 or 5
    times a power of ten, as matplotlib's automatic locator): the automatic locator runs
    again at every stage of a draw, and took about half of the drawing of a panel."""
    for axis, limits in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        low, high = sorted(limits)
        ticks = np.asarray(TICKS.tick_values(low, high))
        slack = 1e-9 * (high - low)
        axis.set_ticks(ticks[(ticks >= low - slack) & (ticks <= high + slack)])


TICK_LABEL_PT = 7.0
"""Font size of the residual panels' tick labels, points."""
TICK_GAP_PT = 7.0
"""From the axes' edge to its tick labels, points (matplotlib's tick length plus its pad)."""
LABEL_GAP_PT = 4.0
"""From the tick labels to the axis label, points (matplotlib's label pad)."""


def _tick_texts(ticks: np.ndarray) -> list[str]:
    """The tick labels matplotlib would write for ``ticks``, without an offset or a power of
    ten taken out (the panels have no room for the offset text)."""
    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    formatter.set_locs(ticks)  # type: ignore[arg-type]  # stubs say list; any sequence works
    return [formatter(value) for value in ticks]


def _outlined_tick_labels(ax: Axes, *, left: bool) -> None:
    """Label ``ax``'s fixed ticks with glyph outlines, one collection per axis
    (:class:`hcard.preview.glyph_labels.PathLabels`), below the x axis and, if ``left``, left of
    the y axis, and place its axis labels beyond them. matplotlib's ``Text`` costs about 1 ms per
    label to lay out and draw: the ~100 tick labels of a figure of 11 panels took a third of
    it."""
    fig = ax.get_figure()
    assert isinstance(fig, Figure)  # the residual panels' axes sit on the figure itself
    inches = fig.dpi_scale_trans
    gap = TICK_GAP_PT / 72.0
    ax.tick_params(labelbottom=False, labelleft=False)
    box = ax.get_position()
    width_in, height_in = fig.get_size_inches()
    axes_width_in, axes_height_in = box.width * width_in, box.height * height_in
    x_ticks = ax.get_xticks()
    below = ax.get_xaxis_transform() + ScaledTranslation(0.0, -gap, inches)
    x_labels = PathLabels(_tick_texts(x_ticks), np.column_stack(
        [x_ticks, np.zeros_like(x_ticks)]), size_pt=TICK_LABEL_PT, inches=inches,
        offset_transform=below, ha="center", va="top", clip_on=False)
    ax.add_collection(x_labels, autolim=False)
    # from the top of the capitals down to the lowest control point (the outlines' control
    # points bound their curves; Path.get_extents solves for the curves' extrema and took a
    # third of the figure's time)
    label_height_in = max((-float(np.asarray(path.vertices)[:, 1].min())
                           for path in x_labels.get_paths() if len(np.asarray(path.vertices))),
                          default=0.0)
    ax.xaxis.set_label_coords(
        0.5, -(gap + label_height_in + LABEL_GAP_PT / 72.0) / axes_height_in)
    if not left:
        return
    y_ticks = ax.get_yticks()
    texts = _tick_texts(y_ticks)
    beside = ax.get_yaxis_transform() + ScaledTranslation(-gap, 0.0, inches)
    labels = PathLabels(texts, np.column_stack([np.zeros_like(y_ticks), y_ticks]),
                        size_pt=TICK_LABEL_PT, inches=inches, offset_transform=beside,
                        ha="right", va="center", clip_on=False)
    ax.add_collection(labels, autolim=False)
    widest_in = max((float(np.ptp(np.asarray(path.vertices)[:, 0])) for path in labels.get_paths()
                     if len(np.asarray(path.vertices))), default=0.0)
    ax.yaxis.set_label_coords(
        -(gap + widest_in + LABEL_GAP_PT / 72.0) / axes_width_in, 0.5)


def residuals_figure(result: CalibrationResult) -> Figure:
    """``residuals.png`` as a figure (Agg canvas attached)."""
    names = list(result.data.regressors)
    rows, columns = residuals_grid(len(names))
    fig = Figure(figsize=(PANEL_INCHES[0] * columns, PANEL_INCHES[1] * rows), dpi=DPI)
    FigureCanvasAgg(fig)
    before = result.before.fit.residuals
    pick = _subsample(np.flatnonzero(result.data.used), MAX_SCATTER)
    low, high = np.percentile(before[pick], [1.0, 99.0]) if pick.size else (0.0, 0.0)
    if not names:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(0.5, 0.5, "no regressor varies in these data", ha="center", va="center")
        ax.set_axis_off()
        return fig
    # one residual scale for every panel: the binned means of all regressors compare at a
    # glance, and only the first column needs its tick labels
    means = np.concatenate([
        np.concatenate([result.before.analysis.regressors[name].bin_means,
                        result.after.analysis.regressors[name].bin_means])
        for name in names])
    span_low = min(float(low), float(np.nanmin(means, initial=low)))
    span_high = max(float(high), float(np.nanmax(means, initial=high)))
    # in mN for the usual residuals, N or kN should a fit be far off: tick labels of at most
    # four digits, which the panel's margin holds
    force_scale, force_unit = (N_PER_MN, "mN") if max(-span_low, span_high) < 1.0 else display_unit(
        "N", [span_low, span_high])
    before = before / force_scale
    span_low, span_high = span_low / force_scale, span_high / force_scale
    pad = 0.05 * (span_high - span_low) or 1.0
    for k, name in enumerate(names):
        ax = _panel(fig, k // columns, k % columns, rows, PANEL_INCHES)
        x = result.data.regressors[name]
        scale, unit = display_unit(REGRESSOR_UNITS.get(name, ""), x)
        ax.scatter(
            x[pick] / scale, before[pick], s=2, c="0.75", alpha=0.5, linewidths=0
        )
        stats_b = result.before.analysis.regressors[name]
        stats_a = result.after.analysis.regressors[name]
        ax.plot(
            stats_b.bin_centres / scale,
            stats_b.bin_means / force_scale,
            "o-",
            color=BEFORE_COLOUR,
            ms=3,
            lw=1.2,
            label="before",
        )
        ax.plot(
            stats_a.bin_centres / scale,
            stats_a.bin_means / force_scale,
            "s-",
            color=AFTER_COLOUR,
            ms=3,
            lw=1.2,
            label="after",
        )
        ax.axhline(0.0, color="0.4", lw=0.6)
        ax.set_ylim(span_low - pad, span_high + pad)
        ax.set_title(f"{name}: eta² {stats_b.eta2:.2f} → {stats_a.eta2:.2f}", fontsize=9, y=1.0)
        ax.set_xlabel(f"{name} [{unit or '-'}]", fontsize=8)
        _fixed_ticks(ax)
        first_column = k % columns == 0
        if first_column:
            ax.set_ylabel(f"residual [{force_unit}]", fontsize=8)
        _outlined_tick_labels(ax, left=first_column)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
    return fig


def _held_out_stretch(result: CalibrationResult) -> np.ndarray:
    """Indices of the window of at most :data:`MAX_STRETCH_S` (within one recording) holding
    the most held-out samples, starting at a held-out sample."""
    data = result.data
    test = data.test
    if not test.any():
        return np.zeros(0, dtype=np.intp)
    width = max(1, round(MAX_STRETCH_S * data.sample_rate_hz))
    counts = np.concatenate([[0], np.cumsum(test)])
    starts = np.flatnonzero(test)
    ends = np.minimum(starts + width, test.size)
    ends = np.minimum(ends, np.searchsorted(data.recording, data.recording[starts], "right"))
    best = int(np.argmax(counts[ends] - counts[starts]))
    return np.arange(starts[best], ends[best])


def fit_figure(result: CalibrationResult) -> Figure:
    """``fit.png`` as a figure (Agg canvas attached)."""
    data = result.data
    observed = data.observed * MN_PER_N
    before = observed - result.before.fit.residuals * MN_PER_N
    after = observed - result.after.fit.residuals * MN_PER_N
    fig = Figure(figsize=FIT_INCHES, dpi=DPI)
    FigureCanvasAgg(fig)
    cell = (FIT_INCHES[0] / 3, FIT_INCHES[1])
    ax = _panel(fig, 0, 0, 1, cell, span=2)
    window = _held_out_stretch(result)
    timed = data.time_ordered and "time" in data.inputs
    if window.size:
        t = data.inputs["time"][window] if timed else window.astype(np.float64)
        held = data.test[window]

        def masked(values: np.ndarray) -> np.ndarray:
            return np.where(held, values[window], np.nan)

        ax.plot(t, masked(observed), color="black", lw=0.8, label="observed")
        ax.plot(
            t,
            masked(before),
            color=BEFORE_COLOUR,
            lw=1.0,
            label=f"before ({force_in_mn(result.before.test_rmse)} mN)",
        )
        ax.plot(
            t,
            masked(after),
            color=AFTER_COLOUR,
            lw=1.0,
            label=f"after ({force_in_mn(result.after.test_rmse)} mN)",
        )
        ax.legend(fontsize=8, loc="best")
    ax.set_xlabel("time [s]" if timed else "sample")
    quantity = "lateral force" if result.observation == "lateral_force" else "force"
    ax.set_ylabel(f"{quantity} [mN]")
    ax.set_title("(a) held-out strokes (gaps: training samples)", fontsize=10, y=1.0)
    _fixed_ticks(ax)

    ax = _panel(fig, 0, 2, 1, cell)
    pick = _subsample(np.flatnonzero(data.test), MAX_SCATTER)
    for predicted, colour, label in (
        (before, BEFORE_COLOUR, "before"),
        (after, AFTER_COLOUR, "after"),
    ):
        ax.scatter(
            observed[pick],
            predicted[pick],
            s=3,
            c=colour,
            alpha=0.4,
            linewidths=0,
            label=label,
            rasterized=True,
        )
    if pick.size:
        values = np.concatenate([observed[pick], before[pick], after[pick]])
        low, high = float(values.min()), float(values.max())
        ax.plot([low, high], [low, high], color="0.3", lw=0.8, ls="--", label="identity")
    ax.set_xlabel("observed [mN]")
    ax.set_ylabel("predicted [mN]")
    ax.set_title("(b) held-out: predicted vs observed", fontsize=10, y=1.0)
    _fixed_ticks(ax)
    ax.legend(fontsize=8, loc="best", markerscale=3)
    return fig
