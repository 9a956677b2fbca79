"""The texture half of a preview: each texture's relative friction over one period, as small
multiples (the *texture periods*).

A texture's period strip is its relative friction ``mu/mu0`` over one period: spatial
components along the direction of the strongest one (:func:`main_direction`), temporal
components versus time. A preview shows every texture of the card (up to the format's 256) as a
cell of one axes: a coloured label, the period strips (spatial above temporal), the
natural-friction line, and the range a UV-only or EV-only texture cannot render shaded. All
cells share one friction scale; each cell's geometry is computed in inches and every kind of mark
is one collection, so drawing costs hardly more for 256 textures than for 16.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Transform

from hcard.channels import LABEL_OF_VALUE
from hcard.preview.glyph_labels import LINE_STEP_EM, PathLabels
from hcard.quantities import MS_PER_S, S_PER_MS
from hcard.v1 import card_pb2 as pb

MAX_SPATIAL_WINDOW_MM = 50.0
"""Longest spatial window, millimetres."""
MAX_TEMPORAL_WINDOW_MS = 10_000.0
"""Longest temporal window, milliseconds."""
WINDOW_PERIODS_OF_STRONGEST = 4.0
"""A window spans at most this many periods of the strongest component."""
MAX_PLOT_SAMPLES = 20_000
"""Most samples drawn per strip."""
MIN_PLOT_SAMPLES = 64
"""Fewest samples drawn per strip."""
SAMPLES_PER_CYCLE = 12
"""Samples per cycle a component needs to be drawn as a curve rather than as a band."""
SAMPLES_PER_PIXEL = 4
"""Samples a strip may spend per pixel of its width: a component with more than
``SAMPLES_PER_PIXEL / SAMPLES_PER_CYCLE`` cycles per pixel is drawn as a band."""
FLAT_WINDOW = 10.0
"""Extent of the window of a texture without components of a domain (mm or ms)."""
HEADER_IN = 0.38
"""Height of the explanation above the cells, inches."""
GUTTER_IN = 0.3
"""Width left of the first column of cells for its friction scale, inches."""
DOUBLED_PLOT = 1.3
"""Plot areas are this much taller when a texture shows a spatial and a temporal strip."""
STRIP_GAP_IN = 0.04
"""Gap between the spatial and the temporal strip of one texture, inches."""
LEVEL_SPACING_IN = 0.15
"""Dotted friction levels are drawn about this far apart (at most 6 per strip), inches."""
# ``Collection.get_label()`` of each kind of mark in the periods axes, in texture order (one per
# period strip, for the strips, unreachable spans, natural-friction lines and curves).
STRIPS = "period-strips"
SWATCHES = "texture-swatches"
UNREACHABLE = "unreachable-spans"
LEVELS = "friction-levels"
NATURAL = "natural-friction"
BANDS = "fine-component-bands"
CURVES = "friction-curves"
CELL_LABELS = "cell-labels"
SCALE_LABELS = "scale-labels"
HEADER = "periods-header"
_CELL_GAP_X_IN, _CELL_GAP_Y_IN = 0.12, 0.08
_SWATCH_IN = 0.09  # side of the texture colour's square in front of a cell's label
_LABEL_PAD_IN = 0.03  # between a label's last line and the plot
_CHANNEL_SHORT = {"UV": "UV", "EV": "EV", "BIPOLAR": "BIP"}
_LOCKING_SHORT = {"POSITION": "pos.", "VELOCITY": "vel.", "AUTO": "auto"}


def _enum_label(enum: object, value: int, prefix: str) -> str:
    """``"UV"`` for ``CHANNEL_UV``; unknown values (a newer minor version) as ``"?(7)"``."""
    try:
        return str(enum.Name(value)).removeprefix(prefix)  # type: ignore[attr-defined]
    except ValueError:
        return f"?({value})"


def channel_label(value: int) -> str:
    """Channel name without prefix: ``"UV"``, ``"EV"``, ``"BIPOLAR"``."""
    return LABEL_OF_VALUE.get(value) or _enum_label(pb.Channel, value, "CHANNEL_")


def locking_label(value: int) -> str:
    """Locking name without prefix: ``"POSITION"``, ``"VELOCITY"``, ``"AUTO"``."""
    return _enum_label(pb.Locking, value, "LOCKING_")
def _of_domain(texture: pb.Texture, domain: int) -> list[pb.Component]:
    return [c for c in texture.components if c.domain == domain]


Term = tuple[float, float, float]
"""A sinusoid along a window: (cycles per unit of the window's axis, amplitude, phase rad)."""


def _window(frequencies: Sequence[float], strongest: float, upper: float, scale: float) -> float:
    """One period of the slowest component, at most 4 periods of the strongest and ``upper``.

    Frequencies are per unit of the window divided by ``scale`` (1 for cycles/mm -> mm, 1000
    for Hz -> ms).
    """
    slowest = min(frequencies)
    return min(scale / slowest, WINDOW_PERIODS_OF_STRONGEST * scale / strongest, upper)


def main_direction(texture: pb.Texture) -> float:
    """Direction of the texture's strongest spatial component, radians from +x towards +y.

    The strongest is the one of largest amplitude (the first on ties); 0 without spatial
    components.
    """
    spatial = _of_domain(texture, pb.DOMAIN_SPATIAL)
    if not spatial:
        return 0.0
    return max(spatial, key=lambda c: c.amplitude).orientation


def _spatial_terms(texture: pb.Texture) -> tuple[list[Term], float]:
    """Spatial components projected on the main direction (cycles/mm), and the window (mm)."""
    spatial = _of_domain(texture, pb.DOMAIN_SPATIAL)
    if not spatial:
        return [], FLAT_WINDOW
    theta = main_direction(texture)
    strongest = max(spatial, key=lambda c: c.amplitude).frequency
    length = _window([c.frequency for c in spatial], strongest, MAX_SPATIAL_WINDOW_MM, 1.0)
    # u_c . u = cos(orientation_c - theta) for unit vectors.
    terms = [(c.frequency * math.cos(c.orientation - theta), c.amplitude, c.phase) for c in spatial]
    return terms, length


def _temporal_terms(texture: pb.Texture) -> tuple[list[Term], float]:
    """Temporal components in cycles per millisecond, and the window (ms)."""
    temporal = _of_domain(texture, pb.DOMAIN_TEMPORAL)
    if not temporal:
        return [], FLAT_WINDOW
    strongest = max(temporal, key=lambda c: c.amplitude).frequency
    length_ms = _window(
        [c.frequency for c in temporal], strongest, MAX_TEMPORAL_WINDOW_MS, MS_PER_S)
    return [(c.frequency * S_PER_MS, c.amplitude, c.phase) for c in temporal], length_ms


def _evaluate(baseline: float, terms: Sequence[Term], x: np.ndarray) -> np.ndarray:
    """``baseline + sum A cos(2 pi f x + phase)`` over ``terms``."""
    friction = np.full(x.shape, float(baseline))
    if terms:
        frequency, amplitude, phase = (np.asarray(column) for column in zip(*terms, strict=True))
        friction += np.cos(np.multiply.outer(x, 2.0 * np.pi * frequency) + phase) @ amplitude
    return friction


def spatial_friction(texture: pb.Texture, n: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Relative friction of the spatial part of ``texture`` along its main direction.

    Along the unit vector ``u = (cos th, sin th)`` of :func:`main_direction`, at distance
    ``s`` (mm) from the origin::

        friction(s) = baseline + sum_c A_c cos(2 pi k_c (u_c . u) s + phase_c)

    over spatial components ``c`` (``k_c`` in cycles/mm, ``u_c`` the component's own direction).
    The window is one period of the lowest-frequency component, capped at 4 periods of the
    strongest and at 50 mm; without spatial components the friction is the flat baseline over
    10 mm. Temporal components are left out (see :func:`temporal_friction`).

    Returns:
        ``(s_mm, friction)``: ``n`` distances from 0 to the window length inclusive, in mm,
        and the relative friction ``mu/mu0`` at each.
    """
    if n < 2:
        raise ValueError(f"n must be at least 2, got {n}")
    terms, length = _spatial_terms(texture)
    s_mm = np.linspace(0.0, length, n)
    return s_mm, _evaluate(texture.baseline, terms, s_mm)


def temporal_friction(texture: pb.Texture, n: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Relative friction of the baseline plus the temporal components versus time.

    ``friction(t) = baseline + sum_c A_c cos(2 pi f_c t + phase_c)`` over temporal components
    (``f_c`` in Hz), over one period of the slowest, capped at 4 periods of the strongest and
    at 10 s; without temporal components the flat baseline over 10 ms.

    Returns:
        ``(t_ms, friction)``: ``n`` times from 0 to the window inclusive, in milliseconds, and
        the relative friction at each.
    """
    if n < 2:
        raise ValueError(f"n must be at least 2, got {n}")
    terms, length_ms = _temporal_terms(texture)
    t_ms = np.linspace(0.0, length_ms, n)
    return t_ms, _evaluate(texture.baseline, terms, t_ms)


@dataclass(frozen=True)
class PlotSeries:
    """One period strip as drawn: samples of the drawable components and the band of the rest.

    Attributes:
        x: positions along the window, from 0 to ``window`` (mm or ms).
        friction: relative friction of the baseline and the drawable components at ``x``.
        band: half-width of the band (sum of the amplitudes of the components too fine to draw
            with the samples available), relative friction.
        window: length of the strip's window, mm (spatial) or ms (temporal).
        unit: ``"mm"`` or ``"ms"``.
        direction_deg: direction of a spatial strip (degrees from +x towards +y); ``None``
            for a temporal strip or a texture without spatial components.
    """

    x: np.ndarray
    friction: np.ndarray
    band: float
    window: float
    unit: str = "mm"
    direction_deg: float | None = None

    @property
    def low(self) -> float:
        """Lowest relative friction drawn (curve or band)."""
        return float(self.friction.min()) - self.band

    @property
    def high(self) -> float:
        """Highest relative friction drawn (curve or band)."""
        return float(self.friction.max()) + self.band

    def caption(self, direction: bool = True) -> str:
        """The window, for example ``"4 mm ∠60°"`` (or ``"4 mm"``) or ``"20 ms"``."""
        text = f"{self.window:.2g} {self.unit}"
        if direction and self.direction_deg is not None:
            text += f" ∠{self.direction_deg:.0f}°"
        return text


def plot_series(
    baseline: float, terms: Sequence[Term], window: float, max_samples: int = MAX_PLOT_SAMPLES,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Samples to draw over ``window``: ``(x, friction of the drawable terms, band half-width)``.

    A term with more cycles in the window than ``max_samples`` points can show at
    :data:`SAMPLES_PER_CYCLE` would alias into a false slow wave; it is drawn instead as a band
    of half-width equal to the sum of such terms' amplitudes around the rest.
    """
    max_samples = max(int(max_samples), 2)
    drawable: list[Term] = []
    band = 0.0
    for term in terms:
        if abs(term[0]) * window * SAMPLES_PER_CYCLE <= max_samples:
            drawable.append(term)
        else:
            band += term[1]
    cycles = max((abs(t[0]) * window for t in drawable), default=0.0)
    n = int(min(max(SAMPLES_PER_CYCLE * cycles + 1, MIN_PLOT_SAMPLES), max_samples))
    x = np.linspace(0.0, window, n)
    return x, _evaluate(baseline, drawable, x), band


def texture_series(texture: pb.Texture, max_samples: int = MAX_PLOT_SAMPLES) -> list[PlotSeries]:
    """The strips a cell of ``texture`` shows: spatial (also for a texture without any
    components), temporal, or spatial above temporal."""
    has_spatial = bool(_of_domain(texture, pb.DOMAIN_SPATIAL))
    has_temporal = bool(_of_domain(texture, pb.DOMAIN_TEMPORAL))
    series = []
    if has_spatial or not has_temporal:
        terms, length = _spatial_terms(texture)
        direction = math.degrees(main_direction(texture)) if has_spatial else None
        series.append(PlotSeries(*plot_series(texture.baseline, terms, length, max_samples),
                                 length, "mm", direction))
    if has_temporal:
        terms, length = _temporal_terms(texture)
        series.append(PlotSeries(*plot_series(texture.baseline, terms, length, max_samples),
                                 length, "ms"))
    return series


def unreachable_side(texture: pb.Texture) -> int | None:
    """The texture's channel when every part of it renders on UV only or EV only, else None.

    UV can only lower friction, so a UV-only texture cannot render the range above 1; EV can
    only raise it, so an EV-only texture cannot render the range below 1 (spec/README.md
    section 10, Channels; rule T6; thesis ch. 4).
    """
    channel = texture.channel
    if channel not in (pb.CHANNEL_UV, pb.CHANNEL_EV):
        return None
    if any(c.channel not in (pb.CHANNEL_UNSPECIFIED, channel) for c in texture.components):
        return None
    return channel


@dataclass(frozen=True)
class CellStyle:
    """How texture cells are laid out for a palette of up to ``up_to`` textures.

    Attributes:
        up_to: largest palette of this style.
        columns: cells per row.
        plot_in: height of a cell's plot area, inches.
        font_pt: label size, points.
        detailed: labels with the texture's name and words (else numbers and abbreviations).
        directions: spatial windows with the strip's direction.
    """

    up_to: int
    columns: int
    plot_in: float
    font_pt: float
    detailed: bool
    directions: bool


CELL_STYLES = (
    CellStyle(3, 1, 1.4, 8.0, True, True),
    CellStyle(8, 2, 1.1, 8.0, True, True),
    CellStyle(24, 3, 0.85, 7.0, True, True),
    CellStyle(64, 5, 0.55, 6.0, False, True),
    CellStyle(10**9, 8, 0.38, 5.5, False, False),
)
"""Cell styles by palette size, smallest first."""


def cell_style(count: int) -> CellStyle:
    """The style of a palette of ``count`` textures."""
    return next(style for style in CELL_STYLES if count <= style.up_to)


def cell_label(index: int, texture: pb.Texture, series: Sequence[PlotSeries],
               style: CellStyle) -> str:
    """The text above a texture's cell: number, channel, locking and the strips' windows.

    Detailed: ``"texture 0 (fine)\\nUV, VELOCITY, 1 component\\n4 mm ∠60°"``; compact (large
    palettes): ``"0 UV vel.\\n4 mm | 20 ms"``.
    """
    channel, locking = channel_label(texture.channel), locking_label(texture.locking)
    windows = " | ".join(s.caption(style.directions) for s in series)
    if not style.detailed:
        return (f"{index} {_CHANNEL_SHORT.get(channel, channel)} "
                f"{_LOCKING_SHORT.get(locking, locking)}\n{windows}")
    name = texture.name if len(texture.name) <= 24 else texture.name[:23] + "…"
    count = len(texture.components)
    return (f"texture {index}{f' ({name})' if name else ''}\n"
            f"{channel}, {locking}, {count} component{'' if count == 1 else 's'}\n{windows}")


@dataclass(frozen=True)
class CellsLayout:
    """Where the texture cells go, in inches from the top-left of the periods panel."""

    style: CellStyle
    count: int
    width: float
    label_lines: int
    doubled: bool

    @property
    def plot_h(self) -> float:
        """Height of a cell's plot area, inches."""
        return self.style.plot_in * (DOUBLED_PLOT if self.doubled else 1.0)

    @property
    def rows(self) -> int:
        return max(1, math.ceil(self.count / self.style.columns))

    @property
    def cell_w(self) -> float:
        return (self.width - GUTTER_IN + _CELL_GAP_X_IN) / self.style.columns

    @property
    def plot_w(self) -> float:
        return self.cell_w - _CELL_GAP_X_IN

    @property
    def label_h(self) -> float:
        return LINE_STEP_EM * self.label_lines * self.style.font_pt / 72.0 + _LABEL_PAD_IN

    @property
    def row_h(self) -> float:
        return self.label_h + self.plot_h + _CELL_GAP_Y_IN

    @property
    def strip_h(self) -> float:
        """Height of the smallest period strip, inches."""
        return (self.plot_h - STRIP_GAP_IN) / 2 if self.doubled else self.plot_h

    @property
    def height(self) -> float:
        """Height of the panel, inches."""
        return HEADER_IN + self.rows * self.row_h

    def plot_box(self, i: int) -> tuple[float, float, float, float]:
        """``(left, top, right, bottom)`` of texture ``i``'s plot area."""
        row, col = divmod(i, self.style.columns)
        left = GUTTER_IN + col * self.cell_w
        top = HEADER_IN + row * self.row_h + self.label_h
        return left, top, left + self.plot_w, top + self.plot_h


def _both_domains(texture: pb.Texture) -> bool:
    return bool(_of_domain(texture, pb.DOMAIN_SPATIAL)) and bool(
        _of_domain(texture, pb.DOMAIN_TEMPORAL))


def cells_layout(textures: Sequence[pb.Texture], width_in: float) -> CellsLayout:
    """The layout of the cells of ``textures`` in a panel ``width_in`` inches wide."""
    style = cell_style(len(textures))
    doubled = any(_both_domains(t) for t in textures)
    return CellsLayout(style, len(textures), width_in, 3 if style.detailed else 2, doubled)


def _scale_labels(levels: Sequence[float], low: float, high: float, height_in: float,
                  font_pt: float) -> list[float]:
    """The friction values to write beside a strip ``height_in`` tall: 1, then the dotted
    levels nearest to it first, each at least a line of text away from those kept."""
    step_in = 1.1 * font_pt / 72.0
    scale = height_in / (high - low)
    kept = [1.0]
    for value in sorted(levels, key=lambda v: abs(v - 1.0)):
        if all(abs(value - other) * scale >= step_in for other in kept):
            kept.append(value)
    return kept


def friction_range(all_series: Sequence[Sequence[PlotSeries]]) -> tuple[float, float]:
    """One friction scale for every cell: the extremes of every strip and of natural friction
    (1), padded by a tenth of the span (at least 0.05)."""
    low = min([1.0, *(s.low for series in all_series for s in series)])
    high = max([1.0, *(s.high for series in all_series for s in series)])
    pad = max(0.05, 0.1 * (high - low))
    return low - pad, high + pad


@dataclass
class _Marks:
    """What the cells draw, collected texture by texture (inches, y downwards)."""

    strips: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    strip_colours: list[np.ndarray] = field(default_factory=list)
    swatches: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    unreachable: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    levels: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    natural: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    bands: list[np.ndarray] = field(default_factory=list)
    curves: list[np.ndarray] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    label_anchors: list[tuple[float, float]] = field(default_factory=list)
    scale_texts: list[str] = field(default_factory=list)
    scale_anchors: list[tuple[float, float]] = field(default_factory=list)


def _rectangle(left: float, top: float, right: float, bottom: float
               ) -> tuple[tuple[float, float], ...]:
    return ((left, top), (right, top), (right, bottom), (left, bottom))


def _add_strip(marks: _Marks, s: PlotSeries, box: tuple[float, float, float, float],
               side: int | None, friction: tuple[float, float], levels: Sequence[float]) -> None:
    """One period strip in ``box`` (left, top, right, bottom; inches) on the scale ``friction``
    (bottom, top), with the range ``side`` (UV or EV) cannot render shaded."""
    left, top, right, bottom = box
    low, high = friction

    def y_of(value: np.ndarray | float) -> np.ndarray | float:
        return top + (high - value) * ((bottom - top) / (high - low))

    one = float(y_of(1.0))
    if side == pb.CHANNEL_UV:  # UV can only lower friction
        marks.unreachable.append(_rectangle(left, top, right, one))
    elif side == pb.CHANNEL_EV:  # EV can only raise it
        marks.unreachable.append(_rectangle(left, one, right, bottom))
    marks.natural.append(((left, one), (right, one)))
    marks.levels.extend(((left, float(y_of(v))), (right, float(y_of(v)))) for v in levels)
    xs = left + s.x * ((right - left) / s.window)
    if s.band > 0.0:
        marks.bands.append(np.column_stack([np.concatenate([xs, xs[::-1]]), np.concatenate(
            [y_of(s.friction + s.band), np.asarray(y_of(s.friction - s.band))[::-1]])]))
    marks.curves.append(np.column_stack([xs, y_of(s.friction)]))


def draw_cells(ax: Axes, textures: Sequence[pb.Texture], colours: np.ndarray,
               layout: CellsLayout, dpi: float, inches: Transform) -> None:
    """Every texture's cell in ``ax``, whose data units must be inches from the panel's
    top-left, y downwards (``inches`` is the figure's ``dpi_scale_trans``)."""
    max_samples = min(MAX_PLOT_SAMPLES,
                      max(MIN_PLOT_SAMPLES, round(SAMPLES_PER_PIXEL * layout.plot_w * dpi)))
    all_series = [texture_series(t, max_samples) for t in textures]
    low, high = friction_range(all_series)
    bins = min(6, max(2, int(layout.strip_h / LEVEL_SPACING_IN)))
    levels = [v for v in MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]).tick_values(low, high)
              if low < v < high and not math.isclose(v, 1.0)]
    tint = 0.82 + 0.18 * colours[:, :3]  # each texture's colour at 18 % over white
    scale_font = min(layout.style.font_pt, 6.5)

    marks = _Marks()
    for i, (texture, series) in enumerate(zip(textures, all_series, strict=True)):
        left, top, right, bottom = layout.plot_box(i)
        label_top = top - layout.label_h
        marks.swatches.append(_rectangle(left, label_top, left + _SWATCH_IN,
                                         label_top + _SWATCH_IN))
        marks.labels.append(cell_label(i, texture, series, layout.style))
        marks.label_anchors.append((left + _SWATCH_IN + 0.04, label_top))
        strip_h = (bottom - top - STRIP_GAP_IN * (len(series) - 1)) / len(series)
        for k, s in enumerate(series):
            s_top = top + k * (strip_h + STRIP_GAP_IN)
            marks.strips.append(_rectangle(left, s_top, right, s_top + strip_h))
            marks.strip_colours.append(tint[i])
            _add_strip(marks, s, (left, s_top, right, s_top + strip_h),
                       unreachable_side(texture), (low, high), levels)
            if i % layout.style.columns == 0:  # the friction scale left of the first column
                for value in _scale_labels(levels, low, high, strip_h, scale_font):
                    marks.scale_texts.append(f"{value:g}")
                    marks.scale_anchors.append(
                        (left - 0.03, s_top + (high - value) * strip_h / (high - low)))

    for collection in (
        PolyCollection(marks.strips, facecolors=marks.strip_colours, edgecolors="none",
                       zorder=0, label=STRIPS),
        PolyCollection(marks.swatches, facecolors=colours, edgecolors="none", label=SWATCHES),
        PolyCollection(marks.unreachable, facecolors="0.8", edgecolors="none", zorder=0.5,
                       label=UNREACHABLE),
        LineCollection(marks.levels, colors="0.55", linewidths=0.4, linestyles=":", zorder=1,
                       label=LEVELS),
        LineCollection(marks.natural, colors="0.3", linewidths=0.7, linestyles="--",
                       zorder=1.5, label=NATURAL),
        PolyCollection(marks.bands, facecolors="0.1", alpha=0.3, edgecolors="none", zorder=2,
                       label=BANDS),
        LineCollection(marks.curves, colors="0.05", linewidths=0.8, zorder=3, label=CURVES),
        PathLabels(marks.labels, np.array(marks.label_anchors), size_pt=layout.style.font_pt,
                   inches=inches, offset_transform=ax.transData, ha="left", va="top",
                   zorder=4, label=CELL_LABELS),
        PathLabels(marks.scale_texts, np.array(marks.scale_anchors), size_pt=scale_font,
                   inches=inches, offset_transform=ax.transData, ha="right", va="center",
                   colors="0.3", zorder=4, label=SCALE_LABELS),
    ):
        ax.add_collection(collection, autolim=False)
    dotted = ", ".join(f"{v:g}" for v in levels)
    header = ("relative friction μ/μ0 of each texture over one period (spatial profile above "
              f"temporal)\none scale for all cells: {low:.2f} (bottom) to {high:.2f} (top); "
              f"dashed: 1, natural friction{f'; dotted: {dotted}' if dotted else ''}")
    ax.add_collection(PathLabels([header], np.array([[GUTTER_IN, 0.02]]), size_pt=8.0,
                                 inches=inches, offset_transform=ax.transData, ha="left",
                                 va="top", label=HEADER), autolim=False)
    ax.set_xlim(0.0, layout.width)
    ax.set_ylim(layout.height, 0.0)
    ax.set_axis_off()
