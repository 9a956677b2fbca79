"""A card turned into the numpy arrays the frame kernel reads (done once per renderer)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hcard.channels import GROUP_OF_VALUE
from hcard.render.options import RenderMode, RenderOptions
from hcard.v1 import card_pb2 as pb

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
        baseline_deviation: (3,) baseline - 1 in the texture's channel group.
    """

    phase_weights: np.ndarray
    wave_vectors: np.ndarray
    temporal_hz: np.ndarray
    band_limited: np.ndarray
    amplitude: np.ndarray
    group_matrix: np.ndarray
    baseline_deviation: np.ndarray

    @property
    def n_components(self) -> int:
        return int(self.amplitude.shape[0])


@dataclass(frozen=True)
class Palette:
    """Every texture of a card stacked into arrays indexed by palette index, each texture
    padded with silent components (zero amplitude and weights) to the card's largest component
    count C, plus one silent texture at the end that index -1 (a neutral frame) picks.

    The kernel gathers from these per run of frames, so its work does not grow with the
    palette.

    Attributes:
        phase_weights: (T + 1, 6, C) :attr:`CompiledTexture.phase_weights`.
        band_limited: (T + 1, C) whether the band-limit gain applies.
        group_amplitude: (T + 1, G, C) amplitude of each component in each of the card's G
            channel groups (:attr:`CompiledCard.channel_groups`), relative friction.
        baseline: (T + 1, G) baseline - 1 in each channel group.
        n_components: (T + 1,) components of each texture (0 for the silent one).
    """

    phase_weights: np.ndarray
    band_limited: np.ndarray
    group_amplitude: np.ndarray
    baseline: np.ndarray
    n_components: np.ndarray


def stack_palette(textures: tuple[CompiledTexture, ...], columns: list[int]) -> Palette:
    """The :class:`Palette` of ``textures``, restricted to the channel groups ``columns``."""
    count = len(textures) + 1
    width = max((t.n_components for t in textures), default=0)
    palette = Palette(
        phase_weights=np.zeros((count, 6, width)),
        band_limited=np.zeros((count, width), dtype=bool),
        group_amplitude=np.zeros((count, len(columns), width)),
        baseline=np.zeros((count, len(columns))),
        n_components=np.zeros(count, dtype=np.intp),
    )
    for index, texture in enumerate(textures):
        c = texture.n_components
        palette.phase_weights[index, :, :c] = texture.phase_weights
        palette.band_limited[index, :c] = texture.band_limited
        palette.group_amplitude[index, :, :c] = (
            texture.amplitude[:, None] * texture.group_matrix[:, columns]).T
        palette.baseline[index] = texture.baseline_deviation[columns]
        palette.n_components[index] = c
    return palette


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
    palette: Palette = field(init=False, repr=False, compare=False)
    """The textures stacked for the kernel (:func:`stack_palette`)."""
    one_texture_grid: bool = field(init=False, repr=False, compare=False)
    """Every taxtel holds the same texture."""

    def __post_init__(self) -> None:
        # Frozen dataclass: the derived arrays are set once, here.
        object.__setattr__(self, "palette",
                           stack_palette(self.textures, list(self.channel_groups)))
        object.__setattr__(self, "one_texture_grid",
                           bool((self.grid == self.grid.flat[0]).all()))

    @property
    def max_components(self) -> int:
        """Components of the card's largest texture."""
        return int(self.palette.phase_weights.shape[2])


def velocity_locked(component: pb.Component, locking: int, options: RenderOptions) -> bool:
    """Whether a spatial component's phase follows the odometer (spec rule R8)."""
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
        groups[c, GROUP_OF_VALUE[channel]] = 1.0
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
    baseline[GROUP_OF_VALUE[texture.channel]] = texture.baseline - 1.0
    return CompiledTexture(
        phase_weights=weights,
        wave_vectors=wave,
        temporal_hz=temporal,
        band_limited=limited,
        amplitude=amplitude,
        group_matrix=groups,
        baseline_deviation=baseline,
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
