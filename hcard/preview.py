"""A picture of a card a person can read: the taxtel map and every texture's friction profile.

Left: the taxtel grid over the surface (millimetres, origin top-left, y downwards, equal aspect),
coloured by texture index. Right: one small panel per texture (at most :data:`MAX_PANELS`) with
its relative friction ``mu/mu0`` over one period: spatial components along the direction of the
strongest one, temporal components versus time. Rendering uses matplotlib's Agg canvas directly
(no pyplot, no display).

>>> from hcard.preview import render_preview
>>> render_preview(card, "preview.png")          # doctest: +SKIP
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure, SubFigure
from matplotlib.gridspec import SubplotSpec

from hcard import __version__
from hcard.atomic import write_atomically
from hcard.errors import CardValidationError
from hcard.v1 import card_pb2 as pb
from hcard.validate import errors_of, validate

MAX_PANELS = 24
"""Texture panels drawn at most; the rest are counted as "+N more"."""
MAX_SPATIAL_WINDOW_MM = 50.0
"""Longest spatial profile, millimetres."""
MAX_TEMPORAL_WINDOW_MS = 10_000.0
"""Longest temporal profile, milliseconds."""
WINDOW_PERIODS_OF_STRONGEST = 4.0
"""A profile spans at most this many periods of the strongest component."""
MAX_PLOT_SAMPLES = 20_000
"""Most samples drawn per profile."""
SAMPLES_PER_CYCLE = 12
"""Samples per cycle a component needs to be drawn as a curve rather than as a band."""
FLAT_WINDOW = 10.0
"""Extent of the profile of a texture without components of a domain (mm or ms)."""
GRID_LINES_MAX = 100
"""Taxtel boundaries are drawn when the grid has at most this many columns and rows."""
LABELS_MAX = 24
"""Texture numbers are written on the taxtels when the grid has at most this many columns/rows."""
GRID_AXES_LABEL = "taxtel-grid"
"""``Axes.get_label()`` of the left panel (lets tests and tools find it)."""


def _enum_label(enum: object, value: int, prefix: str) -> str:
    """``"UV"`` for ``CHANNEL_UV``; unknown values (a newer minor version) as ``"?(7)"``."""
    try:
        return str(enum.Name(value)).removeprefix(prefix)  # type: ignore[attr-defined]
    except ValueError:
        return f"?({value})"


def channel_label(value: int) -> str:
    """Channel name without prefix: ``"UV"``, ``"EV"``, ``"BIPOLAR"``."""
    return _enum_label(pb.Channel, value, "CHANNEL_")


def locking_label(value: int) -> str:
    """Locking name without prefix: ``"POSITION"``, ``"VELOCITY"``, ``"AUTO"``."""
    return _enum_label(pb.Locking, value, "LOCKING_")


def _of_domain(texture: pb.Texture, domain: int) -> list[pb.Component]:
    return [c for c in texture.components if c.domain == domain]


Term = tuple[float, float, float]
"""A sinusoid along a profile: (cycles per unit of the profile axis, amplitude, phase rad)."""


def _window(frequencies: Sequence[float], strongest: float, upper: float, scale: float) -> float:
    """One period of the slowest component, at most 4 periods of the strongest and ``upper``.

    Frequencies are per unit of the window divided by ``scale`` (1 for cycles/mm -> mm, 1000
    for Hz -> ms).
    """
    slowest = min(frequencies)
    return min(scale / slowest, WINDOW_PERIODS_OF_STRONGEST * scale / strongest, upper)


def profile_direction(texture: pb.Texture) -> float:
    """Direction of the texture's strongest spatial component, radians from +x towards +y.

    The strongest is the one of largest amplitude (the first on ties); 0 without spatial
    components.
    """
    spatial = _of_domain(texture, pb.DOMAIN_SPATIAL)
    if not spatial:
        return 0.0
    return max(spatial, key=lambda c: c.amplitude).orientation


def _spatial_terms(texture: pb.Texture) -> tuple[list[Term], float]:
    """Spatial components projected on the profile direction (cycles/mm), and the window (mm)."""
    spatial = _of_domain(texture, pb.DOMAIN_SPATIAL)
    if not spatial:
        return [], FLAT_WINDOW
    theta = profile_direction(texture)
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
    length_ms = _window([c.frequency for c in temporal], strongest, MAX_TEMPORAL_WINDOW_MS, 1e3)
    return [(c.frequency * 1e-3, c.amplitude, c.phase) for c in temporal], length_ms


def _evaluate(baseline: float, terms: Sequence[Term], x: np.ndarray) -> np.ndarray:
    """``baseline + sum A cos(2 pi f x + phase)`` over ``terms``."""
    friction = np.full(x.shape, float(baseline))
    for frequency, amplitude, phase in terms:
        friction += amplitude * np.cos(2.0 * np.pi * frequency * x + phase)
    return friction


def texture_profile(texture: pb.Texture, n: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Relative friction of the spatial part of ``texture`` along its main direction.

    Along the unit vector ``u = (cos th, sin th)`` of :func:`profile_direction`, at distance
    ``s`` (mm) from the origin::

        friction(s) = baseline + sum_c A_c cos(2 pi k_c (u_c . u) s + phase_c)

    over spatial components ``c`` (``k_c`` in cycles/mm, ``u_c`` the component's own direction).
    The window is one period of the lowest-frequency component, capped at 4 periods of the
    strongest and at 50 mm; without spatial components the profile is the flat baseline over
    10 mm. Temporal components are left out (see :func:`temporal_profile`).

    Returns:
        ``(s_mm, friction)``: ``n`` distances from 0 to the window length inclusive, in mm,
        and the relative friction ``mu/mu0`` at each.
    """
    if n < 2:
        raise ValueError(f"n must be at least 2, got {n}")
    terms, length = _spatial_terms(texture)
    s_mm = np.linspace(0.0, length, n)
    return s_mm, _evaluate(texture.baseline, terms, s_mm)


def temporal_profile(texture: pb.Texture, n: int = 512) -> tuple[np.ndarray, np.ndarray]:
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


def _plot_series(
    baseline: float, terms: Sequence[Term], window: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Samples to draw: ``(x, friction of the drawable terms, band half-width)``.

    Terms with more cycles in the window than :data:`MAX_PLOT_SAMPLES` can show at
    :data:`SAMPLES_PER_CYCLE` would alias into a false slow wave; they are drawn instead as a
    band of half-width equal to the sum of their amplitudes around the rest.
    """
    drawable: list[Term] = []
    band = 0.0
    for term in terms:
        if abs(term[0]) * window * SAMPLES_PER_CYCLE <= MAX_PLOT_SAMPLES:
            drawable.append(term)
        else:
            band += term[1]
    cycles = max((abs(t[0]) * window for t in drawable), default=0.0)
    n = int(min(max(SAMPLES_PER_CYCLE * cycles + 1, 512), MAX_PLOT_SAMPLES))
    x = np.linspace(0.0, window, n)
    return x, _evaluate(baseline, drawable, x), band


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


def _texture_title(index: int, texture: pb.Texture) -> str:
    name = texture.name if len(texture.name) <= 24 else texture.name[:23] + "…"
    label = f"texture {index} ({name})" if name else f"texture {index}"
    count = len(texture.components)
    return (
        f"{label}:\n{channel_label(texture.channel)}, {locking_label(texture.locking)}, "
        f"{count} component{'' if count == 1 else 's'}"
    )


def _unreachable_span(texture: pb.Texture) -> int | None:
    """The texture's channel when every part of it renders on UV only or EV only, else None."""
    channel = texture.channel
    if channel not in (pb.CHANNEL_UV, pb.CHANNEL_EV):
        return None
    if any(c.channel not in (pb.CHANNEL_UNSPECIFIED, channel) for c in texture.components):
        return None
    return channel


def _draw_profile(
    ax: Axes, series: tuple[np.ndarray, np.ndarray, float], texture: pb.Texture, xlabel: str
) -> None:
    """One profile with the natural-friction line and, for UV- or EV-only textures, the range
    the channel cannot render shaded."""
    x, friction, band = series
    lo = min(float(friction.min()) - band, 1.0)
    hi = max(float(friction.max()) + band, 1.0)
    pad = max(0.05, 0.1 * (hi - lo))
    channel = _unreachable_span(texture)
    if channel == pb.CHANNEL_UV:  # UV can only lower friction
        ax.axhspan(1.0, hi + pad, color="0.85", zorder=0)
    elif channel == pb.CHANNEL_EV:  # EV can only raise it
        ax.axhspan(lo - pad, 1.0, color="0.85", zorder=0)
    ax.axhline(1.0, color="0.35", linestyle="--", linewidth=0.8, zorder=1)
    if band > 0.0:
        ax.fill_between(x, friction - band, friction + band, color="0.1", alpha=0.3, lw=0)
    ax.plot(x, friction, color="0.1", linewidth=1.0, zorder=2)
    ax.set_xlim(float(x[0]), float(x[-1]))
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_xlabel(xlabel, fontsize=7, labelpad=1)
    ax.set_ylabel("μ/μ0", fontsize=7, labelpad=1)
    ax.tick_params(labelsize=6, length=2, pad=1)


def _draw_texture_panel(
    fig: Figure | SubFigure, cell: SubplotSpec, index: int, texture: pb.Texture, colour: np.ndarray
) -> None:
    """The profile(s) of one texture: spatial, temporal, or both stacked."""
    has_spatial = bool(_of_domain(texture, pb.DOMAIN_SPATIAL))
    has_temporal = bool(_of_domain(texture, pb.DOMAIN_TEMPORAL))
    parts = [
        part
        for part, present in (
            ("spatial", has_spatial or not has_temporal),
            ("temporal", has_temporal),
        )
        if present
    ]
    cells = cell.subgridspec(len(parts), 1, hspace=0.0)
    for row, part in enumerate(parts):
        ax = fig.add_subplot(cells[row])
        ax.set_facecolor((*colour[:3], 0.18))
        if part == "spatial":
            terms, length = _spatial_terms(texture)
            degrees = math.degrees(profile_direction(texture))
            series = _plot_series(texture.baseline, terms, length)
            _draw_profile(ax, series, texture, f"distance along {degrees:.0f}° (mm)")
        else:
            terms, length = _temporal_terms(texture)
            series = _plot_series(texture.baseline, terms, length)
            _draw_profile(ax, series, texture, "time (ms), temporal part")
        if row == 0:
            ax.set_title(_texture_title(index, texture), fontsize=7.5, loc="left", pad=3)


def _draw_grid(
    fig: Figure | SubFigure, cell: SubplotSpec, card: pb.Card, colours: np.ndarray
) -> Axes:
    """The taxtel map, with a colorbar of texture numbers (and names)."""
    grid, surface = card.grid, card.surface
    count = len(card.textures)
    tw, th = grid.taxtel_width_mm, grid.taxtel_height_mm
    index = np.asarray(grid.texture_index, dtype=np.int64).reshape(grid.rows, grid.cols)
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(-0.5, count + 0.5), count)

    ax = fig.add_subplot(cell, label=GRID_AXES_LABEL)
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
        for (r, c), value in np.ndenumerate(index):
            ax.text(
                (c + 0.5) * tw,
                (r + 0.5) * th,
                str(value),
                ha="center",
                va="center",
                fontsize=8,
                color="black" if luminance[value] > 0.5 else "white",
                clip_on=True,
            )
    ax.set_xlim(0.0, surface.width_mm)
    ax.set_ylim(surface.height_mm, 0.0)
    ax.set_aspect("equal")
    ax.set_anchor("N")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm), downwards")
    ax.set_title("taxtel grid, coloured by texture", fontsize=9)

    if count <= 32:
        ticks = list(range(count))
    else:
        ticks = sorted({round(v) for v in np.linspace(0, count - 1, 9)})
    # An inset follows the aspect-adjusted axes, so the bar is as tall as the map.
    cax = ax.inset_axes((1.03, 0.0, 0.035, 1.0))
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, ticks=ticks)
    bar.ax.set_title("texture", fontsize=8, loc="left")
    if count <= 32:
        names = [t.name if len(t.name) <= 18 else t.name[:17] + "…" for t in card.textures]
        bar.set_ticklabels([f"{i} {name}".rstrip() for i, name in enumerate(names)])
    bar.ax.tick_params(labelsize=7)
    return ax


def preview_figure(card: pb.Card, *, dpi: int = 120) -> Figure:
    """The preview as a matplotlib figure (Agg canvas attached, not yet drawn).

    Raises:
        CardValidationError: the card is invalid (a preview of it would be meaningless).
        ValueError: ``dpi`` is not positive.
    """
    if dpi <= 0:
        raise ValueError(f"dpi must be positive, got {dpi}")
    problems = errors_of(validate(card))
    if problems:
        raise CardValidationError(problems)
    textures = list(card.textures)
    shown = textures[:MAX_PANELS]
    more = len(textures) - len(shown)
    cells = len(shown) + (1 if more else 0)
    ncols = 1 if cells <= 3 else 2 if cells <= 8 else 3
    nrows = math.ceil(cells / ncols)
    doubled = any(
        _of_domain(t, pb.DOMAIN_SPATIAL) and _of_domain(t, pb.DOMAIN_TEMPORAL) for t in shown
    )
    row_height = 2.3 if doubled else 1.7
    fig = Figure(figsize=(14.0, max(5.5, row_height * nrows + 1.2)), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    outer = fig.add_gridspec(1, 2, width_ratios=(1.0, 0.6 + 0.3 * ncols))

    colours = texture_colors(len(textures))
    _draw_grid(fig, outer[0], card, colours)
    panels = outer[1].subgridspec(nrows, ncols)
    for i, texture in enumerate(shown):
        _draw_texture_panel(fig, panels[i // ncols, i % ncols], i, texture, colours[i])
    if more:
        note = fig.add_subplot(panels[len(shown) // ncols, len(shown) % ncols])
        note.axis("off")
        note.text(0.5, 0.5, f"+{more} more", ha="center", va="center", fontsize=11)

    title = card.metadata.title or "(untitled card)"
    grid, surface = card.grid, card.surface
    fig.suptitle(
        f"{title}: {surface.width_mm:g} × {surface.height_mm:g} mm, "
        f"{grid.cols} × {grid.rows} taxtels of {grid.taxtel_width_mm:g} × "
        f"{grid.taxtel_height_mm:g} mm, {len(textures)} texture{'' if len(textures) == 1 else 's'}",
        fontsize=11,
    )
    fig.supxlabel(
        "dashed: natural friction (μ/μ0 = 1); grey: what a UV-only (below 1) or EV-only "
        "(above 1) texture cannot render; dark band: components too fine to draw at this scale. "
        f"hcard {__version__}",
        x=0.995,
        ha="right",
        fontsize=6.5,
        color="0.35",
    )
    return fig


def render_preview(card: pb.Card, path: str | os.PathLike[str], *, dpi: int = 120) -> None:
    """Write the preview of ``card`` as a PNG image to ``path``, atomically.

    The image is rendered in memory first, so a failure never leaves a partial file.

    Args:
        card: a valid card.
        path: output file (PNG bytes whatever the suffix).
        dpi: resolution, dots per inch; the figure is 14 inches wide (1680 pixels at 120 dpi).

    Raises:
        CardValidationError: the card is invalid.
        OSError: the file cannot be written.
    """
    write_atomically(path, preview_png(card, dpi=dpi))


def preview_png(card: pb.Card, *, dpi: int = 120) -> bytes:
    """The preview of ``card`` as PNG bytes (:func:`render_preview` without the file), so a
    caller can render it before it replaces anything.

    Raises:
        CardValidationError: the card is invalid.
    """
    fig = preview_figure(card, dpi=dpi)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, metadata={"Software": f"hcard {__version__}"})
    return buffer.getvalue()
