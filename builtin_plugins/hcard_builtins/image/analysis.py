"""Per-taxtel textures of an image, meeting an error target where the format allows.

For each chunk of taxtel rows:

1. the spectral analysis (:mod:`.spectral`) finds each tile's gratings, at most
   ``peaks`` of them;
2. with a target, each taxtel's own texture is compared with its pixels: a taxtel whose 95th
   percentile of absolute error exceeds the target gets more gratings from the residual
   pursuit (:mod:`.pursuit`), within ``components`` per texture. Taxtels that cannot be over
   the target are not examined further (Chebyshev's inequality: at most 1/20 of any values lie
   beyond sqrt(20) times their RMS): a baseline-only taxtel whose standard deviation is at
   most ``target / sqrt(20)`` is not rendered, and for a rendered one the pixels beyond the
   target are counted only when its RMS error exceeds ``target / sqrt(20)``.

The palette (:mod:`.palette`) then shares textures between taxtels; the error each taxtel's own
texture leaves (:attr:`TaxtelTextures.own_rms`) tells it how far a shared texture may differ.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hcard import limits

from .geometry import Geometry
from .loading import GrayImage
from .reconstruct import FrictionMap, render_rows
from .spectral import TileSpectra, analyse_tiles, to_surface
from .textures import Textures

if TYPE_CHECKING:
    from .pursuit import Pursuit

CHUNK_PIXELS = 1 << 22
"""Tiles are analysed in chunks of about this many pixels, which bounds the memory used."""
GOAL_FRACTION = 0.5
"""The pursuit aims at an RMS error of this fraction of the target: the 95th percentile of
normally distributed errors is 1.96 RMS. Taxtels still over the target take more gratings."""
CHEBYSHEV_FRACTION = 0.05**0.5
"""A baseline-only taxtel whose deviation is at most this fraction of the target has its 95th
percentile error within the target (at most 1/20 of the values lie beyond sqrt(20) sigma)."""


@dataclass(frozen=True)
class Target:
    """Error target of an encode, relative friction.

    Attributes:
        p95: the 95th percentile of the absolute error over each taxtel's pixels should not
            exceed this.
        components: most components a texture may take (the user's cap).
    """

    p95: float
    components: int

    @property
    def goal_rms(self) -> float:
        """RMS error per taxtel the pursuit aims at when choosing gratings."""
        return GOAL_FRACTION * self.p95


@dataclass(frozen=True)
class TaxtelTextures:
    """One texture per taxtel (row-major) and how well each reproduces its own pixels.

    Attributes:
        textures: per-taxtel textures, surface units.
        spectral: the same before the residual pursuit (the spectral analysis' gratings only).
        own_rms: ``(n,)`` RMS error of each taxtel's own texture over its pixels, relative
            friction (0 where it was not measured: no target, or a baseline-only taxtel
            certainly within it).
        own_p95: ``(n,)`` 95th percentile of that error where it exceeds the target; elsewhere
            an upper bound of it that does not (``sqrt(20)`` RMS, at most the target), or 0
            where not measured.
        spectral_p95: ``(n,)`` the same for the ``spectral`` texture.
        pursued: ``(n,)`` taxtels that took gratings from the residual pursuit.
        rms_at_limit: ``(n,)`` RMS error the taxtel's texture would leave with the most
            components a texture can hold (``own_rms`` where it was not pursued).
    """

    textures: Textures
    spectral: Textures
    own_rms: np.ndarray
    own_p95: np.ndarray
    spectral_p95: np.ndarray
    pursued: np.ndarray
    rms_at_limit: np.ndarray


def analyse_image(
    image: GrayImage,
    geometry: Geometry,
    mapping: FrictionMap,
    *,
    peaks: int,
    min_amplitude: float,
    low: float,
    target: Target | None,
) -> TaxtelTextures:
    """Per-taxtel textures of ``image``; with a ``target``, more gratings where a taxtel's own
    texture is over it.

    Args:
        image, geometry, mapping: the image, its tiling and its gray-to-friction map.
        peaks: most gratings the spectral analysis keeps per taxtel.
        min_amplitude: weakest component kept, relative friction.
        low: lowest relative friction of the range (white).
        target: the error target, or None for the spectral analysis alone.
    """
    columns = geometry.tile_columns()
    per_chunk = geometry.tile_h * geometry.tile_w * geometry.cols
    step = max(1, CHUNK_PIXELS // per_chunk)
    parts = []
    for first in range(0, geometry.rows, step):
        stop = min(geometry.rows, first + step)
        tiles = geometry.gather(image.pixels, first, stop, columns)
        parts.append(_analyse_rows(tiles, geometry, mapping, first, stop, peaks, min_amplitude,
                                   low, target))
    if len(parts) == 1:
        return parts[0]
    return TaxtelTextures(
        textures=_stack([p.textures for p in parts]),
        spectral=_stack([p.spectral for p in parts]),
        own_rms=np.concatenate([p.own_rms for p in parts]),
        own_p95=np.concatenate([p.own_p95 for p in parts]),
        spectral_p95=np.concatenate([p.spectral_p95 for p in parts]),
        pursued=np.concatenate([p.pursued for p in parts]),
        rms_at_limit=np.concatenate([p.rms_at_limit for p in parts]),
    )


def _stack(parts: list[Textures]) -> Textures:
    """Textures of consecutive chunks in one set (padded to the widest)."""
    width = max(p.valid.shape[1] for p in parts)

    def pad(a: np.ndarray) -> np.ndarray:
        extra = [(0, 0), (0, width - a.shape[1])] + [(0, 0)] * (a.ndim - 2)
        return np.pad(a, extra)

    return Textures(
        np.concatenate([p.baseline for p in parts]),
        np.concatenate([pad(p.k) for p in parts]),
        np.concatenate([pad(p.coef) for p in parts]),
        np.concatenate([pad(p.valid) for p in parts]),
    )


def _analyse_rows(
    tiles: np.ndarray,
    geometry: Geometry,
    mapping: FrictionMap,
    first: int,
    stop: int,
    peaks: int,
    min_amplitude: float,
    low: float,
    target: Target | None,
) -> TaxtelTextures:
    """:func:`analyse_image` on the tiles ``(rows, tile_h, cols, tile_w)`` of rows
    ``first:stop``."""
    scale = mapping.scale
    spectra = analyse_tiles(tiles, n_peaks=peaks, min_amplitude=min_amplitude / scale)

    def surface(found: TileSpectra) -> Textures:
        return to_surface(found, geometry, high=mapping.high, low=low, scale=scale,
                          min_amplitude=min_amplitude, first_row=first)

    textures = surface(spectra)
    n = spectra.mean.size
    zeros = np.zeros(n)
    if target is None:
        return TaxtelTextures(textures, textures, zeros, zeros, zeros, np.zeros(n, dtype=bool),
                              zeros)
    # imported here: an encode without a target never needs it (start-up of hcard encode)
    from .pursuit import error_figures, over_target, pursue

    count = textures.valid.sum(axis=1)
    check = (count > 0) | (spectra.std * scale > CHEBYSHEV_FRACTION * target.p95)
    own_rms, own_p95 = zeros.copy(), zeros.copy()
    at_limit = zeros.copy()
    pursued = np.zeros(n, dtype=bool)
    checked = np.flatnonzero(check)
    if checked.size == 0:
        return TaxtelTextures(textures, textures, own_rms, own_p95, own_p95, pursued, at_limit)
    residual = _residual(tiles, textures, geometry, mapping, first, stop, checked)
    mask = _owned_mask(geometry, first, stop, checked)
    residual *= mask
    owned = mask.sum(axis=(1, 2)).astype(np.int64)
    squares = np.einsum("nij,nij->n", residual, residual, dtype=np.float64)
    own_rms[checked] = scale * np.sqrt(squares / np.maximum(owned, 1))
    at_limit[checked] = own_rms[checked]
    # The exact percentile only where the RMS leaves it open (Chebyshev) and the count of
    # pixels beyond the target puts the tile over it; elsewhere the bound sqrt(20) RMS.
    own_p95[checked] = own_rms[checked] / CHEBYSHEV_FRACTION
    open_ = np.flatnonzero(own_rms[checked] > CHEBYSHEV_FRACTION * target.p95)
    over = open_[over_target(residual[open_], owned[open_], target.p95 / scale)]
    if over.size == 0:
        own_p95[checked] = np.minimum(own_p95[checked], target.p95)
        return TaxtelTextures(textures, textures, own_rms, own_p95, own_p95, pursued, at_limit)
    own_p95[checked] = np.minimum(own_p95[checked], target.p95)
    own_p95[checked[over]] = scale * error_figures(residual[over], mask[over])[1]
    spectral, spectral_p95 = textures, own_p95.copy()
    tiles_over = checked[over]
    found = pursue(
        residual[over],
        mask=mask[over],
        free=np.maximum(target.components - count[tiles_over], 0),
        limit=np.maximum(limits.MAX_COMPONENTS_PER_TEXTURE - count[tiles_over], 0),
        goal_rms=target.goal_rms / scale,
        target=target.p95 / scale,
        allowed=_allowed_bins(geometry),
    )
    textures = surface(_combine(spectra, found, tiles_over))
    pursued[tiles_over] = found.count > 0
    own_p95[tiles_over] = scale * found.p95
    own_rms[tiles_over] = scale * _rms_after(residual[over], mask[over], found)
    at_limit[tiles_over] = scale * found.rms_at_limit
    return TaxtelTextures(textures, spectral, own_rms, own_p95, spectral_p95, pursued, at_limit)


def _residual(
    tiles: np.ndarray,
    textures: Textures,
    geometry: Geometry,
    mapping: FrictionMap,
    first: int,
    stop: int,
    chosen: np.ndarray,
) -> np.ndarray:
    """Image minus own texture on the ``chosen`` tiles of rows ``first:stop``, gray levels,
    ``(len(chosen), tile_h, tile_w)`` float32."""
    rendered = render_rows(textures, chosen, geometry, first, stop, mapping, where=chosen)
    rows, cols = np.divmod(chosen, geometry.cols)
    pixels = tiles[rows, :, cols, :]  # (n, tile_h, tile_w)
    return np.subtract(pixels, rendered, dtype=np.float32)


def _owned_mask(geometry: Geometry, first: int, stop: int, chosen: np.ndarray) -> np.ndarray:
    """``(len(chosen), tile_h, tile_w)`` float32: 1 on the pixels each chosen tile's taxtel
    owns."""
    rows, cols = np.divmod(chosen, geometry.cols)
    row_mask = geometry.owned_mask("y", first, stop)[rows]
    col_mask = geometry.owned_mask("x")[cols]
    return (row_mask[:, :, None] & col_mask[:, None, :]).astype(np.float32)


def _allowed_bins(geometry: Geometry) -> np.ndarray:
    """``(tile_h, tile_w // 2 + 1)``: tile harmonics at most the format's highest spatial
    frequency (cycles/mm)."""
    nh, nw = geometry.tile_h, geometry.tile_w
    ky = np.fft.fftfreq(nh, d=1.0 / nh) * geometry.ppy / nh
    kx = np.arange(nw // 2 + 1) * geometry.ppx / nw
    return np.hypot(ky[:, None], kx[None, :]) <= limits.MAX_SPATIAL_FREQUENCY


def _combine(spectra: TileSpectra, found: Pursuit, tiles: np.ndarray) -> TileSpectra:
    """The spectral analysis' gratings and the pursuit's on ``tiles``, in one set (the
    baseline takes the pursuit's mean)."""
    extra = found.spectra
    n, width = spectra.valid.shape[0], spectra.valid.shape[1] + extra.valid.shape[1]
    out = TileSpectra.empty(n, width)
    out.mean, out.std = spectra.mean.copy(), spectra.std
    k = spectra.valid.shape[1]
    for name in ("fx", "fy", "coef", "valid"):
        getattr(out, name)[:, :k] = getattr(spectra, name)
        getattr(out, name)[tiles, k:] = getattr(extra, name)
    out.mean[tiles] += extra.mean
    return out


def _rms_after(residual: np.ndarray, mask: np.ndarray, found: Pursuit) -> np.ndarray:
    """RMS per owned pixel the pursuit leaves (Parseval: the residual's sum of squares less
    the energy of the mean and of the gratings taken), gray levels."""
    pixels = residual.shape[1] * residual.shape[2]
    squares = np.einsum("nij,nij->n", residual, residual, dtype=np.float64)
    energy = (2.0 * np.abs(found.spectra.coef) ** 2 * pixels).sum(axis=1)
    energy += found.spectra.mean**2 * pixels
    owned = mask.sum(axis=(1, 2))
    return np.sqrt(np.maximum(squares - energy, 0.0) / np.maximum(owned, 1))
