"""A card turned into the numpy arrays the frame kernel reads (done once per renderer)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hcard.render.options import RenderMode, RenderOptions
from hcard.v1 import card_pb2 as pb

GROUP_UV, GROUP_EV, GROUP_BIPOLAR = 0, 1, 2
"""Column of each channel group in the per-frame deviation array."""
_GROUP_OF_CHANNEL = {
    pb.CHANNEL_UV: GROUP_UV,
    pb.CHANNEL_EV: GROUP_EV,
    pb.CHANNEL_BIPOLAR: GROUP_BIPOLAR,
}
PHASE_INPUTS = 6
"""Columns of the per-frame phase input: dead-reckoned x, y (mm), odometer x, y (mm), time
since touch-down (s), and a constant 1 that carries the phase offset."""


@dataclass(frozen=True)
class CompiledTexture:
    """One palette texture as arrays over its C components.

    Attributes:
        phase_weights: (6, C) turns per unit of each phase input: a position-locked spatial
            component has (kx, ky) in rows 0-1, a velocity-locked one in rows 2-3 (cycles/mm),
            a temporal one its frequency in row 4 (Hz); row 5 is the phase at the origin, turns.
        wave_vectors: (2, C) spatial wave vector (kx, ky), cycles/mm; zero for temporal ones.
        temporal_hz: (C,) frequency of temporal components, Hz; zero for spatial ones.
        band_limited: (C,) whether the band-limit gain applies to the component.
        amplitude: (C,) peak amplitude, relative friction.
        group_matrix: (C, 3) one-hot channel group of each component.
        weighted_groups: (C, 3) float32 ``amplitude * group_matrix``.
        max_wave_number: largest |k| of band-limited spatial components, cycles/mm.
        max_temporal_hz: largest band-limited temporal frequency, Hz.
        baseline_deviation: (3,) baseline - 1 in the texture's channel group.
    """

    phase_weights: np.ndarray
    wave_vectors: np.ndarray
    temporal_hz: np.ndarray
    band_limited: np.ndarray
    amplitude: np.ndarray
    group_matrix: np.ndarray
    baseline_deviation: np.ndarray
    weighted_groups: np.ndarray
    max_wave_number: float
    max_temporal_hz: float

    @property
    def n_components(self) -> int:
        return int(self.amplitude.shape[0])


@dataclass(frozen=True)
class CompiledCard:
    """The grid as a (rows, cols) index array plus compiled textures."""

    width_mm: float
    height_mm: float
    taxtel_width_mm: float
    taxtel_height_mm: float
    grid: np.ndarray
    textures: tuple[CompiledTexture, ...]
    channel_groups: tuple[int, ...]
    """Channel groups (GROUP_UV, GROUP_EV, GROUP_BIPOLAR) that some texture of the card uses."""
    size_mm: np.ndarray = field(init=False, repr=False, compare=False)
    """(2,) surface width and height, mm."""
    taxtel_mm: np.ndarray = field(init=False, repr=False, compare=False)
    """(2,) taxtel width and height, mm."""
    last_cell: np.ndarray = field(init=False, repr=False, compare=False)
    """(2,) last grid column and row, as floats."""
    cell_strides: np.ndarray = field(init=False, repr=False, compare=False)
    """(2,) flat-index step of a column and of a row of the grid: ``(1, cols)``."""
    texture_columns: tuple[TextureColumns, ...] = field(init=False, repr=False, compare=False)
    """Per texture, its arrays restricted to :attr:`channel_groups` (the kernel's columns)."""
    _max_components: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # Frozen dataclass: the derived arrays are set once, here.
        rows, cols = self.grid.shape
        columns = list(self.channel_groups)
        derived = {
            "size_mm": np.array([self.width_mm, self.height_mm], dtype=np.float64),
            "taxtel_mm": np.array([self.taxtel_width_mm, self.taxtel_height_mm],
                                  dtype=np.float64),
            "last_cell": np.array([cols - 1, rows - 1], dtype=np.float64),
            "cell_strides": np.array([1, cols], dtype=np.intp),
            "_max_components": max((t.n_components for t in self.textures), default=0),
            "texture_columns": tuple(
                TextureColumns(
                    baseline=t.baseline_deviation[columns],
                    weighted_groups=t.weighted_groups[:, columns],
                    group_matrix=t.group_matrix[:, columns],
                )
                for t in self.textures
            ),
        }
        for name, value in derived.items():
            object.__setattr__(self, name, value)

    @property
    def max_components(self) -> int:
        return self._max_components


@dataclass(frozen=True)
class TextureColumns:
    """A texture's arrays restricted to the channel groups its card uses (the columns of the
    kernel's per-frame deviation), made once per card instead of once per block.

    Attributes:
        baseline: (G,) baseline - 1 per used group.
        weighted_groups: (C, G) float32 ``amplitude * group_matrix`` of the used groups.
        group_matrix: (C, G) one-hot group of each component among the used groups.
    """

    baseline: np.ndarray
    weighted_groups: np.ndarray
    group_matrix: np.ndarray


def velocity_locked(component: pb.Component, locking: int, options: RenderOptions) -> bool:
    """Whether a spatial component's phase follows the odometer (spec rule R-lock)."""
    if options.mode is RenderMode.POSITION_ONLY:
        return False
    if locking == pb.LOCKING_VELOCITY:
        return True
    if locking == pb.LOCKING_AUTO:
        return 1.0 / component.frequency < options.auto_period_mm
    return False


def compile_texture(texture: pb.Texture, options: RenderOptions) -> CompiledTexture:
    """Compile one (validated) texture."""
    n = len(texture.components)
    weights = np.zeros((6, n))
    wave = np.zeros((2, n))
    temporal = np.zeros(n)
    limited = np.ones(n, dtype=bool)
    amplitude = np.zeros(n)
    groups = np.zeros((n, 3))
    for c, comp in enumerate(texture.components):
        weights[5, c] = comp.phase / (2.0 * math.pi)
        amplitude[c] = comp.amplitude
        channel = comp.channel or texture.channel
        groups[c, _GROUP_OF_CHANNEL[channel]] = 1.0
        if comp.domain == pb.DOMAIN_TEMPORAL:
            temporal[c] = comp.frequency
            weights[4, c] = comp.frequency
            continue
        kx = comp.frequency * math.cos(comp.orientation)
        ky = comp.frequency * math.sin(comp.orientation)
        wave[:, c] = (kx, ky)
        row = 2 if velocity_locked(comp, texture.locking, options) else 0
        weights[row : row + 2, c] = (kx, ky)
        limited[c] = options.mode is RenderMode.HYBRID
    baseline = np.zeros(3)
    baseline[_GROUP_OF_CHANNEL[texture.channel]] = texture.baseline - 1.0
    spatial_limited = limited & (temporal == 0)
    temporal_limited = limited & (temporal > 0)
    return CompiledTexture(
        phase_weights=weights,
        wave_vectors=wave,
        temporal_hz=temporal,
        band_limited=limited,
        amplitude=amplitude,
        group_matrix=groups,
        baseline_deviation=baseline,
        weighted_groups=(amplitude[:, None] * groups).astype(np.float32),
        max_wave_number=float(np.hypot(*wave)[spatial_limited].max(initial=0.0)),
        max_temporal_hz=float(temporal[temporal_limited].max(initial=0.0)),
    )


def compile_card(card: pb.Card, options: RenderOptions) -> CompiledCard:
    """Compile a validated card for rendering with ``options``."""
    grid = card.grid
    index = np.asarray(grid.texture_index, dtype=np.int32).reshape(grid.rows, grid.cols)
    textures = tuple(compile_texture(t, options) for t in card.textures)
    used = np.zeros(3, dtype=bool)
    for texture in textures:
        used |= texture.baseline_deviation != 0
        used |= texture.group_matrix.any(axis=0)
    return CompiledCard(
        width_mm=card.surface.width_mm,
        height_mm=card.surface.height_mm,
        taxtel_width_mm=grid.taxtel_width_mm,
        taxtel_height_mm=grid.taxtel_height_mm,
        grid=index,
        textures=textures,
        channel_groups=tuple(int(g) for g in np.flatnonzero(used)),
    )
