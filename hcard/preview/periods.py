"""The texture half of a preview: each texture's relative friction along a common length, as
small multiples (the *texture profiles*).

A texture's profile strip is its relative friction ``mu/mu0`` along the direction of its
strongest spatial component (:func:`main_direction`) over a window every texture of the card
shares (:func:`common_windows`: a few times the longest period, at least 10 mm), so that a 1 mm
grating shows four times the cycles of a 4 mm one; a texture with temporal components has a
second strip versus time over a shared time window. Each strip draws the UV drive ``u`` and the
EV drive ``e`` the card's channel groups give (spec/README.md rule R11) under the friction
``u e`` they make, the natural-friction line, and the range a UV-only or EV-only texture cannot
render shaded; tick marks in mm (ms) below it and the friction scale left of each row. An
explanation with a legend of every kind of mark heads the cells.

A preview shows every texture of the card (up to the format's 256) as a cell of one axes laid
over the figure: a coloured label with the texture's period, and its strips. All cells share one
friction scale; each cell's geometry is computed in inches (:func:`cells_layout` fills the room
beside the maps first, then full rows below them) and every kind of mark is one collection, so
drawing costs hardly more for 256 textures than for 16.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import Collection, LineCollection, PolyCollection
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Transform

from hcard.channels import GROUP_BIPOLAR, GROUP_OF_VALUE, LABEL_OF_VALUE
from hcard.preview.glyph_labels import LINE_STEP_EM, PathLabels, text_width
from hcard.quantities import MS_PER_S, S_PER_MS
from hcard.v1 import card_pb2 as pb

MAX_SPATIAL_WINDOW_MM = 50.0
"""Longest spatial window, millimetres."""
MAX_TEMPORAL_WINDOW_MS = 10_000.0
"""Longest temporal window, milliseconds."""
MIN_SPATIAL_WINDOW_MM = 10.0
"""Shortest common spatial window of a preview, millimetres."""
MIN_TEMPORAL_WINDOW_MS = 10.0
"""Shortest common temporal window of a preview, milliseconds."""
PERIODS_SHOWN = 4.0
"""The common window spans at least this many of the longest texture period (before rounding
up to a round number)."""
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
LEGEND_PT = 7.5
"""Size of the explanation above the cells, points."""
GUTTER_IN = 0.4
"""Width left of the first column of cells for its friction scale and its name, inches."""
MAX_PLOT_IN = 2.2
"""Tallest plot area of a cell below the maps (and, beyond the style's least, beside them)."""
WIDE_PLOT_ASPECT = 0.5
"""Below the maps a plot area is this fraction of its width tall (within the style's least and
:data:`MAX_PLOT_IN`)."""
TICK_IN = 0.035
"""Length of a tick mark below a strip, inches."""
TICK_SPACING_IN = 0.45
"""About one tick this far apart along a strip, inches."""
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
LEGEND = "periods-legend"
LEGEND_MARKS = "periods-legend-marks"  # the legend's sample marks (one collection per kind)
UV_DRIVES = "uv-drives"
EV_DRIVES = "ev-drives"
TICKS = "x-ticks"
TICK_LABELS = "x-tick-labels"
Y_AXIS_LABELS = "y-axis-labels"
_CELL_GAP_X_IN, _CELL_GAP_Y_IN = 0.12, 0.08
_SWATCH_IN = 0.09  # side of the texture colour's square in front of a cell's label
_LABEL_PAD_IN = 0.03  # between a label's last line and the plot
_SAMPLE_IN = 0.28  # length of a legend entry's sample mark
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
    """One profile strip as drawn: samples of the drawable components and the band of the rest.

    Attributes:
        x: positions along the window, from 0 to ``window`` (mm or ms).
        friction: relative friction ``mu/mu0 = u e`` of the baseline and the drawable components
            at ``x`` (spec/README.md rule R11, without the band limit of R10).
        band: half-width of the band (sum of the amplitudes of the components too fine to draw
            with the samples available), relative friction.
        window: length of the strip's window, mm (spatial) or ms (temporal): the same for every
            texture of a card (:func:`common_windows`).
        unit: ``"mm"`` or ``"ms"``.
        direction_deg: direction of a spatial strip (degrees from +x towards +y); ``None``
            for a temporal strip or a texture without spatial components.
        uv, ev: the UV and EV drives ``u`` (0 to 1) and ``e`` (1 to 4) at ``x``, the texture's
            channel groups split as rule R11 does; ``None`` when not computed.
        period: period of the strongest component of the strip's domain (mm or ms); ``None``
            without components.
    """

    x: np.ndarray
    friction: np.ndarray
    band: float
    window: float
    unit: str = "mm"
    direction_deg: float | None = None
    uv: np.ndarray | None = None
    ev: np.ndarray | None = None
    period: float | None = None

    @property
    def low(self) -> float:
        """Lowest relative friction drawn (curve, band or UV drive)."""
        low = float(self.friction.min()) - self.band
        return low if self.uv is None else min(low, float(self.uv.min()))

    @property
    def high(self) -> float:
        """Highest relative friction drawn (curve, band or EV drive)."""
        high = float(self.friction.max()) + self.band
        return high if self.ev is None else max(high, float(self.ev.max()))

    def caption(self, direction: bool = True) -> str:
        """The period, for example ``"4 mm ∠60°"`` (or ``"4 mm"``) or ``"20 ms"``;
        ``"flat"`` without components."""
        if self.period is None:
            return "flat"
        text = f"{self.period:.3g} {self.unit}"
        if direction and self.direction_deg is not None:
            text += f" ∠{self.direction_deg:.0f}°"
        return text


def _drawable(frequencies: Sequence[float], window: float, max_samples: int
              ) -> tuple[list[bool], int]:
    """Which components a strip of ``max_samples`` samples over ``window`` draws as curves
    (at least :data:`SAMPLES_PER_CYCLE` samples per cycle), and the samples it needs (at least
    one per pixel, ``max_samples / SAMPLES_PER_PIXEL``, so a wide strip stays smooth)."""
    max_samples = max(int(max_samples), 2)
    drawn = [abs(f) * window * SAMPLES_PER_CYCLE <= max_samples for f in frequencies]
    cycles = max((abs(f) * window for f, d in zip(frequencies, drawn, strict=True) if d),
                 default=0.0)
    least = max(MIN_PLOT_SAMPLES, max_samples // SAMPLES_PER_PIXEL)  # a sample per pixel
    n = int(min(max(SAMPLES_PER_CYCLE * cycles + 1, least), max_samples))
    return drawn, n


def plot_series(
    baseline: float, terms: Sequence[Term], window: float, max_samples: int = MAX_PLOT_SAMPLES,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Samples to draw over ``window``: ``(x, friction of the drawable terms, band half-width)``.

    A term with more cycles in the window than ``max_samples`` points can show at
    :data:`SAMPLES_PER_CYCLE` would alias into a false slow wave; it is drawn instead as a band
    of half-width equal to the sum of such terms' amplitudes around the rest.
    """
    drawn, n = _drawable([t[0] for t in terms], window, max_samples)
    x = np.linspace(0.0, window, n)
    band = sum(t[1] for t, d in zip(terms, drawn, strict=True) if not d)
    return x, _evaluate(baseline, [t for t, d in zip(terms, drawn, strict=True) if d], x), band


def texture_period(texture: pb.Texture, domain: int) -> float | None:
    """Period of the texture's strongest component of ``domain`` (largest amplitude, the first
    on ties): mm for ``DOMAIN_SPATIAL``, ms for ``DOMAIN_TEMPORAL``; None without one."""
    components = _of_domain(texture, domain)
    if not components:
        return None
    strongest = max(components, key=lambda c: c.amplitude).frequency
    return 1.0 / strongest if domain == pb.DOMAIN_SPATIAL else MS_PER_S / strongest


def nice_ceil(value: float, steps: Sequence[float] = (1.0, 2.0, 2.5, 5.0)) -> float:
    """The least of ``steps`` (between 1 and 10) times a power of ten that is at least
    ``value`` (> 0)."""
    power = 10.0 ** math.floor(math.log10(value))
    return next(m * power for m in (*steps, 10.0) if m * power >= value * (1 - 1e-12))


def common_window(periods: Sequence[float | None], least: float, most: float) -> float:
    """The window every texture's strip of one domain spans: :data:`PERIODS_SHOWN` times the
    longest period, at least ``least``, rounded up by :func:`nice_ceil` and at most ``most``."""
    longest = max((p for p in periods if p is not None), default=0.0)
    return min(nice_ceil(max(least, PERIODS_SHOWN * longest)), most)


def common_windows(textures: Sequence[pb.Texture]) -> tuple[float, float]:
    """The spatial window (mm) and the temporal window (ms) of every texture's strips, so that
    strips compare: a 1 mm grating shows four times the cycles of a 4 mm one."""
    spatial = common_window([texture_period(t, pb.DOMAIN_SPATIAL) for t in textures],
                            MIN_SPATIAL_WINDOW_MM, MAX_SPATIAL_WINDOW_MM)
    temporal = common_window([texture_period(t, pb.DOMAIN_TEMPORAL) for t in textures],
                             MIN_TEMPORAL_WINDOW_MS, MAX_TEMPORAL_WINDOW_MS)
    return spatial, temporal


def profile_series(texture: pb.Texture, domain: int, window: float,
                   max_samples: int = MAX_PLOT_SAMPLES) -> PlotSeries:
    """The strip of ``texture``'s components of ``domain`` over ``window`` (mm or ms).

    Spatial components are projected on the direction of the strongest one
    (:func:`main_direction`). Each component joins its channel group (its own channel, or the
    texture's), the texture's ``baseline - 1`` joins the texture's group, and the groups are
    split into the UV drive ``u`` and the EV drive ``e`` as rule R11 does (clipping included):
    the strip's friction is ``u e``. Components too fine for ``max_samples`` samples are left
    to the band (:func:`plot_series`).
    """
    from hcard.render.synthesis import channel_targets  # numpy only; keeps the import cheap

    components = _of_domain(texture, domain)
    if domain == pb.DOMAIN_SPATIAL:
        theta = main_direction(texture)
        frequencies = [c.frequency * math.cos(c.orientation - theta) for c in components]
        unit, direction = "mm", math.degrees(theta) if components else None
    else:
        frequencies = [c.frequency * S_PER_MS for c in components]
        unit, direction = "ms", None
    drawn, n = _drawable(frequencies, window, max_samples)
    x = np.linspace(0.0, window, n)
    own_group = GROUP_OF_VALUE.get(texture.channel, GROUP_BIPOLAR)
    deviation = np.zeros((3, n))
    deviation[own_group] += texture.baseline - 1.0
    band = 0.0
    for component, frequency, draw in zip(components, frequencies, drawn, strict=True):
        if not draw:
            band += component.amplitude
            continue
        group = GROUP_OF_VALUE.get(component.channel, own_group)
        deviation[group] += component.amplitude * np.cos(
            2.0 * np.pi * frequency * x + component.phase)
    uv, ev = channel_targets(deviation)
    return PlotSeries(x, uv * ev, band, window, unit, direction, uv, ev,
                      texture_period(texture, domain))


def texture_series(texture: pb.Texture, windows: tuple[float, float] | None = None,
                   max_samples: int = MAX_PLOT_SAMPLES) -> list[PlotSeries]:
    """The strips a cell of ``texture`` shows: spatial (also for a texture without any
    components), temporal, or spatial above temporal, over ``windows`` (mm, ms; default: the
    texture's own, :func:`common_windows` of it alone)."""
    spatial_mm, temporal_ms = windows if windows is not None else common_windows([texture])
    has_spatial = bool(_of_domain(texture, pb.DOMAIN_SPATIAL))
    has_temporal = bool(_of_domain(texture, pb.DOMAIN_TEMPORAL))
    series = []
    if has_spatial or not has_temporal:
        series.append(profile_series(texture, pb.DOMAIN_SPATIAL, spatial_mm, max_samples))
    if has_temporal:
        series.append(profile_series(texture, pb.DOMAIN_TEMPORAL, temporal_ms, max_samples))
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
        min_cell_in: narrowest cell, inches (a region holds as many columns as fit).
        plot_in: least height of a cell's plot area, inches.
        font_pt: label size, points.
        detailed: labels with the texture's name and words (else numbers and abbreviations),
            every x tick labelled (else the ends only).
        directions: periods with the strip's direction.
    """

    up_to: int
    min_cell_in: float
    plot_in: float
    font_pt: float
    detailed: bool
    directions: bool


CELL_STYLES = (
    CellStyle(3, 4.0, 1.4, 8.0, True, True),
    CellStyle(8, 3.0, 1.1, 8.0, True, True),
    CellStyle(24, 2.1, 0.85, 7.0, True, True),
    CellStyle(64, 1.25, 0.55, 6.0, False, True),
    CellStyle(10**9, 0.72, 0.38, 5.5, False, False),
)
"""Cell styles by palette size, smallest first."""


def cell_style(count: int) -> CellStyle:
    """The style of a palette of ``count`` textures."""
    return next(style for style in CELL_STYLES if count <= style.up_to)


def cell_label(index: int, texture: pb.Texture, series: Sequence[PlotSeries],
               style: CellStyle) -> str:
    """The text above a texture's cell: number, channel, locking and the strips' periods.

    Detailed: ``"texture 0 (fine)\\nUV, VELOCITY, 1 component\\nperiod 4 mm ∠60°"``; compact
    (large palettes): ``"0 UV vel.\\n4 mm | 20 ms"``.
    """
    channel, locking = channel_label(texture.channel), locking_label(texture.locking)
    periods = " | ".join(s.caption(style.directions) for s in series)
    if not style.detailed:
        return (f"{index} {_CHANNEL_SHORT.get(channel, channel)} "
                f"{_LOCKING_SHORT.get(locking, locking)}\n{periods}")
    name = texture.name if len(texture.name) <= 24 else texture.name[:23] + "…"
    count = len(texture.components)
    return (f"texture {index}{f' ({name})' if name else ''}\n"
            f"{channel}, {locking}, {count} component{'' if count == 1 else 's'}\n"
            f"{'' if periods == 'flat' else 'period '}{periods}")


Box = tuple[float, float, float, float]
"""``(left, top, right, bottom)``, inches from the figure's top-left, y downwards."""


@dataclass(frozen=True)
class CellsLayout:
    """Where the texture cells go, inches from the figure's top-left (y downwards).

    Attributes:
        style: the palette's cell style.
        boxes: each texture's plot area (its strips and the tick labels between them; the
            last strip's tick labels lie below it, its label above).
        first_in_row: whether each cell starts a row (its friction scale is written left of it).
        header: ``(left, top, width)`` of the explanation above the first cells.
        bottom: lowest extent of the cells, inches.
        slots: strips a plot area is laid out for (2 when a texture has both domains).
        windows: the strips' common spatial (mm) and temporal (ms) windows.
        plan: the explanation, wrapped to the header's width.
    """

    style: CellStyle
    boxes: list[Box]
    first_in_row: list[bool]
    header: tuple[float, float, float]
    bottom: float
    slots: int
    windows: tuple[float, float]
    plan: HeaderPlan

    @property
    def label_lines(self) -> int:
        return 3 if self.style.detailed else 2

    @property
    def label_h(self) -> float:
        return label_height(self.style)

    @property
    def tick_h(self) -> float:
        return tick_height(self.style)

    @property
    def plot_w(self) -> float:
        """Width of the narrowest plot area, inches."""
        return min((b[2] - b[0] for b in self.boxes), default=1.0)


def label_height(style: CellStyle) -> float:
    """Height of a cell's label above its plot area, inches."""
    return LINE_STEP_EM * (3 if style.detailed else 2) * style.font_pt / 72.0 + _LABEL_PAD_IN


def tick_height(style: CellStyle) -> float:
    """Height of a strip's tick marks and tick labels below it, inches."""
    return TICK_IN + 0.03 + scale_font(style) * 1.15 / 72.0


def scale_font(style: CellStyle) -> float:
    """Size of the tick and scale labels, points."""
    return min(style.font_pt, 6.5)


def _both_domains(texture: pb.Texture) -> bool:
    return bool(_of_domain(texture, pb.DOMAIN_SPATIAL)) and bool(
        _of_domain(texture, pb.DOMAIN_TEMPORAL))


def _grid(count: int, width: float, style: CellStyle) -> tuple[int, int, float]:
    """``(columns, rows, cell width)`` of ``count`` cells in ``width`` inches: as many columns
    as cells of :attr:`CellStyle.min_cell_in` fit, then as few as keep that many rows, so the
    last row is as full as it can be."""
    usable = width - GUTTER_IN + _CELL_GAP_X_IN
    most = max(1, int(usable / (style.min_cell_in + _CELL_GAP_X_IN)))
    rows = max(1, math.ceil(count / most))
    columns = max(1, math.ceil(count / rows))
    return columns, rows, usable / columns


def cells_layout(textures: Sequence[pb.Texture], *,
                 beside: tuple[float, float, float, float] | None,
                 below: tuple[float, float], below_top: float, dpi: float = 120.0
                 ) -> CellsLayout:
    """Lay the cells of ``textures`` out in two regions: ``beside`` (``left, top, width,
    height`` inches: the room right of the maps, filled to its height, or None), then ``below``
    (``left, width``: full width from ``below_top`` down) for those that do not fit beside.

    The explanation (:func:`plan_header`) heads the first region used. Beside the maps the plot
    areas stretch to fill the region's height; below they are as tall as the style asks,
    taller for wide cells (at most :data:`MAX_PLOT_IN`). The cells of a region's last row
    share its whole width, so no row ends in a blank gap.
    """
    style = cell_style(len(textures))
    slots = 2 if any(_both_domains(t) for t in textures) else 1
    windows = common_windows(textures)
    temporal = any(_of_domain(t, pb.DOMAIN_TEMPORAL) for t in textures)
    entries = legend_entries(any(unreachable_side(t) is not None for t in textures),
                             _may_band(textures, windows, style.min_cell_in, dpi))
    least = style.plot_in * (DOUBLED_PLOT if slots == 2 else 1.0)
    fixed = (label_height(style) + tick_height(style) + _CELL_GAP_Y_IN
             + (slots - 1) * (tick_height(style) + STRIP_GAP_IN))
    boxes: list[Box] = []
    first: list[bool] = []
    header: tuple[float, float, float] | None = None
    plan: HeaderPlan | None = None

    def place(count: int, left: float, top: float, width: float, columns: int,
              plot_h: float) -> float:
        """Place ``count`` cells in rows from ``top``; the bottom of the last row."""
        row_h = fixed + plot_h
        rows = math.ceil(count / columns)
        for k in range(count):
            row, col = divmod(k, columns)
            in_row = columns if row < rows - 1 else count - (rows - 1) * columns
            cell_w = (width - GUTTER_IN + _CELL_GAP_X_IN) / in_row
            x = left + GUTTER_IN + col * cell_w
            y = top + row * row_h + label_height(style)
            boxes.append((x, y, x + cell_w - _CELL_GAP_X_IN, y + plot_h))
            first.append(col == 0)
        return top + rows * row_h

    remaining, bottom = len(textures), below_top
    if beside is not None:
        left, top, width, height = beside
        beside_plan = plan_header(header_text(windows, temporal), entries, width - GUTTER_IN)
        room = height - beside_plan.height
        fit_rows = int(room / (fixed + least)) if room > 0 else 0
        if fit_rows > 0 and width - GUTTER_IN >= style.min_cell_in:
            columns, rows, _ = _grid(remaining, width, style)
            if rows > fit_rows:  # full rows beside, the rest below
                columns, _, _ = _grid(10**6, width, style)
                rows = fit_rows
            placed = min(remaining, rows * columns)
            rows = math.ceil(placed / columns)
            plot_h = min((room - rows * fixed) / rows, MAX_PLOT_IN + least)
            header, plan = (left + GUTTER_IN, top, width - GUTTER_IN), beside_plan
            bottom = max(bottom, place(placed, left, top + plan.height, width, columns, plot_h))
            remaining -= placed
    if remaining:
        left, width = below
        columns, _, cell_w = _grid(remaining, width, style)
        plot_h = max(least, min(WIDE_PLOT_ASPECT * (cell_w - _CELL_GAP_X_IN), MAX_PLOT_IN))
        top = below_top
        if header is None:
            header = (left + GUTTER_IN, top, width - GUTTER_IN)
            plan = plan_header(header_text(windows, temporal), entries, width - GUTTER_IN)
            top += plan.height
        bottom = place(remaining, left, top, width, columns, plot_h)
    assert header is not None and plan is not None  # a card has a texture (rule G1)
    return CellsLayout(style, boxes, first, header, bottom, slots, windows, plan)


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
    """One friction scale for every cell: the extremes of every strip (curves, bands and
    drives) and of natural friction (1), padded by a tenth of the span (at least 0.05)."""
    low = min([1.0, *(s.low for series in all_series for s in series)])
    high = max([1.0, *(s.high for series in all_series for s in series)])
    pad = max(0.05, 0.1 * (high - low))
    return low - pad, high + pad


def x_ticks(window: float, width_in: float) -> list[float]:
    """Tick positions along a strip ``width_in`` wide over ``window`` (mm or ms): about one
    every :data:`TICK_SPACING_IN`, both ends included (the window is a round number)."""
    bins = max(1, int(width_in / TICK_SPACING_IN))
    ticks = MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]).tick_values(0.0, window)
    return [float(t) for t in ticks if -1e-9 <= t <= window * (1 + 1e-9)]


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
    uv: list[np.ndarray] = field(default_factory=list)
    ev: list[np.ndarray] = field(default_factory=list)
    ticks: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    label_anchors: list[tuple[float, float]] = field(default_factory=list)
    scale_texts: list[str] = field(default_factory=list)
    scale_anchors: list[tuple[float, float]] = field(default_factory=list)
    axis_anchors: list[tuple[float, float]] = field(default_factory=list)
    tick_texts: tuple[list[str], list[str], list[str]] = field(
        default_factory=lambda: ([], [], []))
    tick_anchors: tuple[list[tuple[float, float]], list[tuple[float, float]],
                        list[tuple[float, float]]] = field(default_factory=lambda: ([], [], []))


def _rectangle(left: float, top: float, right: float, bottom: float
               ) -> tuple[tuple[float, float], ...]:
    return ((left, top), (right, top), (right, bottom), (left, bottom))


def _add_strip(marks: _Marks, s: PlotSeries, box: Box, side: int | None,
               friction: tuple[float, float], levels: Sequence[float]) -> None:
    """One profile strip in ``box`` (left, top, right, bottom; inches) on the scale
    ``friction`` (bottom, top), with the range ``side`` (UV or EV) cannot render shaded."""
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
    if s.uv is not None and s.ev is not None:
        marks.uv.append(np.column_stack([xs, y_of(s.uv)]))
        marks.ev.append(np.column_stack([xs, y_of(s.ev)]))


def _add_ticks(marks: _Marks, s: PlotSeries, box: Box, style: CellStyle) -> None:
    """Tick marks under a strip and their labels: every tick of a detailed style, the ends of a
    compact one; the last label carries the unit."""
    left, _, right, bottom = box
    ticks = x_ticks(s.window, right - left)
    xs = [left + t * (right - left) / s.window for t in ticks]
    marks.ticks.extend(((x, bottom), (x, bottom + TICK_IN)) for x in xs)
    y = bottom + TICK_IN + 0.03
    texts = [f"{t:g}" for t in ticks]
    texts[-1] += f" {s.unit}"
    shown = range(len(ticks)) if style.detailed else (0, len(ticks) - 1)
    for k in shown:
        slot = 0 if k == 0 else 2 if k == len(ticks) - 1 else 1  # left, centre, right aligned
        marks.tick_texts[slot].append(texts[k])
        marks.tick_anchors[slot].append((xs[k], y))


LEGEND_UV_COLOUR = "#2c7fb8"
"""The UV drive's curve (a wide, light line under the friction curve)."""
LEGEND_EV_COLOUR = "#e34a33"
"""The EV drive's curve."""


def header_text(windows: tuple[float, float], temporal: bool) -> list[str]:
    """The sentences of the explanation above the cells: what the strips show."""
    spatial_mm, temporal_ms = windows
    parts = [f"Relative friction μ/μ0 of each texture along its direction (∠, that of its "
             f"strongest component) over the same {spatial_mm:g} mm"]
    if temporal:
        parts.append(f"below it, versus time over the same {temporal_ms:g} ms (its temporal "
                     f"components)")
    return parts


def legend_entries(any_unreachable: bool, any_band: bool) -> list[tuple[str, str]]:
    """``(mark kind, text)`` of the legend, in order."""
    entries = [("curve", "μ/μ0 = u·e, the friction felt"),
               ("uv", "UV drive u (0-1, lowers)"),
               ("ev", "EV drive e (1-4, raises)"),
               ("natural", "1: natural friction")]
    if any_unreachable:
        entries.append(("unreachable", "grey: out of reach of a UV-only texture (above 1) or "
                                       "an EV-only one (below 1)"))
    if any_band:
        entries.append(("band", "dark band: components too fine to draw here"))
    return entries


@dataclass(frozen=True)
class HeaderPlan:
    """The explanation above the cells wrapped to a width: its title lines and, for each legend
    entry, ``(kind, text, x offset in inches, line)`` (lines counted after the title's)."""

    title: list[str]
    entries: list[tuple[str, str, float, int]]

    @property
    def lines(self) -> int:
        return len(self.title) + 1 + max((e[3] for e in self.entries), default=0)

    @property
    def height(self) -> float:
        """Height of the explanation, inches."""
        return self.lines * LINE_STEP_EM * LEGEND_PT / 72.0 + 0.1


def plan_header(parts: Sequence[str], entries: Sequence[tuple[str, str]], width: float
                ) -> HeaderPlan:
    """Wrap the explanation's sentences (joined by "; " while they fit) and its legend entries
    (a sample mark and its text each) to ``width`` inches."""
    title: list[str] = []
    for part in parts:
        joined = f"{title[-1]}; {part}" if title else part
        if title and text_width(joined, LEGEND_PT) <= width:
            title[-1] = joined
        else:
            title.append(part)
    title[-1] += "."
    placed: list[tuple[str, str, float, int]] = []
    x, line = 0.0, 0
    for kind, text in entries:
        need = _SAMPLE_IN + 0.05 + text_width(text, LEGEND_PT) + 0.18
        if x > 0.0 and x + need > width:
            x, line = 0.0, line + 1
        placed.append((kind, text, x, line))
        x += need
    return HeaderPlan(title, placed)


def _may_band(textures: Sequence[pb.Texture], windows: tuple[float, float], plot_w: float,
              dpi: float) -> bool:
    """Whether a strip ``plot_w`` inches wide at ``dpi`` may draw a component as a band (the
    legend keeps a place for it)."""
    samples = min(MAX_PLOT_SAMPLES, max(MIN_PLOT_SAMPLES, round(SAMPLES_PER_PIXEL * plot_w * dpi)))
    spatial_mm, temporal_ms = windows
    return any(c.frequency * (spatial_mm if c.domain == pb.DOMAIN_SPATIAL else
                              temporal_ms * S_PER_MS) * SAMPLES_PER_CYCLE > samples
               for t in textures for c in t.components)


def draw_cells(ax: Axes, textures: Sequence[pb.Texture], colours: np.ndarray,
               layout: CellsLayout, dpi: float, inches: Transform) -> None:
    """Every texture's cell in ``ax``, whose data units must be inches from the figure's
    top-left, y downwards (``inches`` is the figure's ``dpi_scale_trans``), and the explanation
    with its legend above the first cells."""
    style = layout.style
    max_samples = min(MAX_PLOT_SAMPLES,
                      max(MIN_PLOT_SAMPLES, round(SAMPLES_PER_PIXEL * layout.plot_w * dpi)))
    all_series = [texture_series(t, layout.windows, max_samples) for t in textures]
    low, high = friction_range(all_series)
    strip_least = (layout.boxes[0][3] - layout.boxes[0][1] - (layout.slots - 1) * (
        layout.tick_h + STRIP_GAP_IN)) / layout.slots
    bins = min(6, max(2, int(strip_least / LEVEL_SPACING_IN)))
    levels = [v for v in MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]).tick_values(low, high)
              if low < v < high and not math.isclose(v, 1.0)]
    tint = 0.82 + 0.18 * colours[:, :3]  # each texture's colour at 18 % over white
    small = scale_font(style)

    marks = _Marks()
    for i, (texture, series) in enumerate(zip(textures, all_series, strict=True)):
        left, top, right, bottom = layout.boxes[i]
        label_top = top - layout.label_h
        marks.swatches.append(_rectangle(left, label_top, left + _SWATCH_IN,
                                         label_top + _SWATCH_IN))
        marks.labels.append(cell_label(i, texture, series, style))
        marks.label_anchors.append((left + _SWATCH_IN + 0.04, label_top))
        gap = layout.tick_h + STRIP_GAP_IN
        strip_h = (bottom - top - gap * (len(series) - 1)) / len(series)
        for k, s in enumerate(series):
            s_top = top + k * (strip_h + gap)
            box = (left, s_top, right, s_top + strip_h)
            marks.strips.append(_rectangle(*box))
            marks.strip_colours.append(tint[i])
            _add_strip(marks, s, box, unreachable_side(texture), (low, high), levels)
            _add_ticks(marks, s, box, style)
            if layout.first_in_row[i]:  # the friction scale and its name left of the row
                for value in _scale_labels(levels, low, high, strip_h, small):
                    marks.scale_texts.append(f"{value:g}")
                    marks.scale_anchors.append(
                        (left - 0.03, s_top + (high - value) * strip_h / (high - low)))
                marks.axis_anchors.append((left - GUTTER_IN + 0.02, s_top + strip_h / 2))

    legend = _legend(layout, bool(marks.unreachable), bool(marks.bands))
    styles: dict[str, dict[str, Any]] = {
        UNREACHABLE: dict(facecolors="0.8", edgecolors="none", zorder=0.5),
        NATURAL: dict(colors="0.3", linewidths=0.7, linestyles="--", zorder=1.5),
        BANDS: dict(facecolors="0.1", alpha=0.3, edgecolors="none", zorder=2),
        UV_DRIVES: dict(colors=LEGEND_UV_COLOUR, linewidths=2.4, alpha=0.55, zorder=2.5,
                        capstyle="butt"),
        EV_DRIVES: dict(colors=LEGEND_EV_COLOUR, linewidths=2.4, alpha=0.55, zorder=2.6,
                        capstyle="butt"),
        CURVES: dict(colors="0.05", linewidths=0.8, zorder=3),
    }
    drawn: list[tuple[str, list[Any], list[Any]]] = [  # (kind, the cells' marks, the legend's)
        (UNREACHABLE, marks.unreachable, legend.unreachable),
        (NATURAL, marks.natural, legend.natural),
        (BANDS, marks.bands, legend.bands),
        (UV_DRIVES, marks.uv, legend.uv),
        (EV_DRIVES, marks.ev, legend.ev),
        (CURVES, marks.curves, legend.curves),
    ]
    kinds: list[Collection] = []
    for kind, cells, samples in drawn:
        make: Any = PolyCollection if kind in (UNREACHABLE, BANDS) else LineCollection
        kinds.append(make(cells, label=kind, **styles[kind]))
        kinds.append(make(samples, label=LEGEND_MARKS, **styles[kind]))
    for collection in (
        PolyCollection(marks.strips, facecolors=marks.strip_colours, edgecolors="none",
                       zorder=0, label=STRIPS),
        PolyCollection(marks.swatches, facecolors=colours, edgecolors="none", label=SWATCHES),
        LineCollection(marks.levels, colors="0.55", linewidths=0.4, linestyles=":", zorder=1,
                       label=LEVELS),
        *kinds,
        LineCollection(marks.ticks, colors="0.3", linewidths=0.6, zorder=3, label=TICKS),
        PathLabels(marks.labels, np.array(marks.label_anchors), size_pt=style.font_pt,
                   inches=inches, offset_transform=ax.transData, ha="left", va="top",
                   zorder=4, label=CELL_LABELS),
        PathLabels(marks.scale_texts, np.array(marks.scale_anchors), size_pt=small,
                   inches=inches, offset_transform=ax.transData, ha="right", va="center",
                   colors="0.3", zorder=4, label=SCALE_LABELS),
        PathLabels(["μ/μ0"] * len(marks.axis_anchors), np.array(marks.axis_anchors),
                   size_pt=small, inches=inches, offset_transform=ax.transData, ha="center",
                   va="top", colors="0.3", rotation=90.0, zorder=4, label=Y_AXIS_LABELS),
        *(PathLabels(texts, np.array(anchors).reshape(-1, 2), size_pt=small, inches=inches,
                     offset_transform=ax.transData, ha=ha, va="top", colors="0.3", zorder=4,
                     label=TICK_LABELS)
          for texts, anchors, ha in zip(marks.tick_texts, marks.tick_anchors,
                                        ("left", "center", "right"), strict=True)),
        PathLabels(legend.texts[:1], np.array(legend.anchors[:1]), size_pt=LEGEND_PT,
                   inches=inches, offset_transform=ax.transData, ha="left", va="top", zorder=4,
                   label=HEADER),
        PathLabels(legend.texts[1:], np.array(legend.anchors[1:]), size_pt=LEGEND_PT,
                   inches=inches, offset_transform=ax.transData, ha="left", va="center",
                   zorder=4, label=LEGEND),
    ):
        ax.add_collection(collection, autolim=False)


@dataclass
class _Legend:
    """The explanation above the cells: its texts and the sample marks of its legend line."""

    texts: list[str] = field(default_factory=list)
    anchors: list[tuple[float, float]] = field(default_factory=list)
    curves: list[np.ndarray] = field(default_factory=list)
    uv: list[np.ndarray] = field(default_factory=list)
    ev: list[np.ndarray] = field(default_factory=list)
    natural: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    unreachable: list[tuple[tuple[float, float], ...]] = field(default_factory=list)
    bands: list[np.ndarray] = field(default_factory=list)


def _legend(layout: CellsLayout, any_unreachable: bool, any_band: bool) -> _Legend:
    """The explanation at ``layout.header`` as planned (:func:`plan_header`): the title lines,
    then the legend's entries, a sample mark and its text each; an entry whose mark the cells
    do not draw is left out."""
    left, top, _ = layout.header
    line = LINE_STEP_EM * LEGEND_PT / 72.0
    title = layout.plan.title
    legend = _Legend(["\n".join(title)], [(left, top + 0.05)])
    for kind, text, offset, row in layout.plan.entries:
        if (kind == "unreachable" and not any_unreachable) or (kind == "band" and not any_band):
            continue
        a, b = left + offset, left + offset + _SAMPLE_IN
        mid = top + 0.05 + (len(title) + row) * line + 0.035
        if kind == "curve":
            legend.curves.append(np.array([[a, mid], [b, mid]]))
        elif kind == "uv":
            legend.uv.append(np.array([[a, mid], [b, mid]]))
        elif kind == "ev":
            legend.ev.append(np.array([[a, mid], [b, mid]]))
        elif kind == "natural":
            legend.natural.append(((a, mid), (b, mid)))
        elif kind == "unreachable":
            legend.unreachable.append(_rectangle(a, mid - 0.04, b, mid + 0.04))
        else:
            legend.bands.append(np.array([[a, mid - 0.03], [b, mid - 0.03], [b, mid + 0.03],
                                          [a, mid + 0.03]]))
        legend.texts.append(text)
        legend.anchors.append((b + 0.05, mid))
    return legend
