"""Reconstruction error: the card rendered back at pixel resolution against the image.

Every taxtel's palette texture is evaluated position-locked (absolute surface coordinates) at the
centres of the pixels the taxtel owns. Per tile the texture is separable,

    f(y_i, x_j) = b + sum_k Re(C_k e^{2 pi i ky_k y_i} e^{2 pi i kx_k x_j}),

so a tile is one real matrix product ``[Re(C e_y), -Im(C e_y), b] @ [Re e_x; Im e_x; 1]`` with
inner size ``2K + 1``; all tiles of a chunk go through one batched ``matmul``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Geometry
from .palette import Palette
from .textures import Textures


@dataclass(frozen=True)
class ReconstructionError:
    """Difference between the card and the image, relative friction units, over all pixels and
    per taxtel (the pixels each taxtel owns).

    Attributes:
        rms: root-mean-square error.
        max: largest absolute error.
        pixels: number of pixels compared.
        p95: 95th percentile of the absolute error over the pixels (nearest rank, exact).
        taxtel_rms: (rows, cols) RMS error of each taxtel's pixels.
        taxtel_max: (rows, cols) largest absolute error of each taxtel's pixels.
        taxtel_p95: (rows, cols) 95th percentile of the absolute error of each taxtel's
            pixels, exact (nearest rank: the smallest value that at least 95 % of the taxtel's
            pixels do not exceed).
    """

    rms: float
    max: float
    pixels: int
    p95: float = 0.0
    taxtel_rms: np.ndarray | None = None
    taxtel_max: np.ndarray | None = None
    taxtel_p95: np.ndarray | None = None


@dataclass(frozen=True)
class FrictionMap:
    """Linear map from gray levels to relative friction: ``friction = high - scale * gray``."""

    high: float
    scale: float


def render_tiles(
    palette: Palette, geometry: Geometry, first: int, stop: int, mapping: FrictionMap
) -> np.ndarray:
    """The card's gray levels (the inverse of ``mapping``) on the tiles of taxtel rows
    ``first:stop``: array ``((stop-first) * cols, tile_h, tile_w)``, float32."""
    cols = geometry.cols
    return render_rows(
        palette.textures, palette.index[first * cols : stop * cols], geometry, first, stop, mapping
    )


def render_rows(
    textures: Textures,
    index: np.ndarray,
    geometry: Geometry,
    first: int,
    stop: int,
    mapping: FrictionMap,
    where: np.ndarray | None = None,
) -> np.ndarray:
    """Gray levels (the inverse of ``mapping``) of ``textures[index]`` on tiles of taxtel rows
    ``first:stop``: array ``(len(index), tile_h, tile_w)``, float32.

    ``index`` holds one texture per tile: of every tile of those rows in row-major order, or of
    the tiles at positions ``where`` in that order. Tiles are grouped by the number of
    components of their texture, so that each group's matrix product is no wider than it needs
    to be; baseline-only tiles are just filled.
    """
    cols, nh, nw = geometry.cols, geometry.tile_h, geometry.tile_w
    if where is None:
        where = np.arange((stop - first) * cols)
    tile_row, tile_col = np.divmod(where, cols)
    tile_row = tile_row + first
    # Gray-level palette: gray = (high - friction) / scale.
    baseline = (mapping.high - textures.baseline) / mapping.scale
    coef = np.where(textures.valid, -textures.coef / mapping.scale, 0.0)
    count = textures.valid.sum(axis=1)[index]
    out = np.empty((index.size, nh, nw), dtype=np.float32)
    for slots in counts_present(count):
        tiles = np.nonzero(count == slots)[0]
        p, r, c = index[tiles], tile_row[tiles], tile_col[tiles]
        if slots == 0:
            out[tiles] = baseline[p][:, None, None]
            continue
        # Left factor per (texture, tile row), right factor per (texture, tile column):
        # computed once for each pair in use, then gathered per tile.
        rows_used, row_of_tile = np.unique(p * geometry.rows + r, return_inverse=True)
        cols_used, col_of_tile = np.unique(p * geometry.cols + c, return_inverse=True)
        p_row, r_used = rows_used // geometry.rows, rows_used % geometry.rows
        p_col, c_used = cols_used // geometry.cols, cols_used % geometry.cols
        y = (geometry.row_tile[r_used][:, None] + 0.5 + np.arange(nh)[None, :]) / geometry.ppy
        x = (geometry.col_tile[c_used][:, None] + 0.5 + np.arange(nw)[None, :]) / geometry.ppx
        # Cycles, reduced modulo 1 in double precision before the (single precision) factors.
        turns_y = np.mod(textures.k[p_row, :slots, 1][:, :, None] * y[:, None, :], 1.0)
        turns_x = np.mod(textures.k[p_col, :slots, 0][:, :, None] * x[:, None, :], 1.0)
        wave_y = coef[p_row, :slots][:, :, None] * np.exp(2j * np.pi * turns_y)
        wave_x = np.exp(2j * np.pi * turns_x)
        left = np.empty((rows_used.size, nh, 2 * slots + 1), dtype=np.float32)
        right = np.empty((cols_used.size, 2 * slots + 1, nw), dtype=np.float32)
        left[:, :, :slots] = wave_y.real.transpose(0, 2, 1)
        left[:, :, slots : 2 * slots] = -wave_y.imag.transpose(0, 2, 1)
        left[:, :, 2 * slots] = baseline[p_row][:, None]
        right[:, :slots, :] = wave_x.real
        right[:, slots : 2 * slots, :] = wave_x.imag
        right[:, 2 * slots, :] = 1.0
        out[tiles] = np.matmul(left[row_of_tile.ravel()], right[col_of_tile.ravel()])
    return out


def reconstruction_error(
    pixels: np.ndarray,
    geometry: Geometry,
    palette: Palette,
    mapping: FrictionMap,
    *,
    chunk_pixels: int = 1 << 21,
) -> ReconstructionError:
    """RMS, 95th percentile and maximum of (card - image) in relative friction over the image's
    pixels, and RMS, 95th percentile and maximum per taxtel.

    Args:
        pixels: gray levels of the image (as analysed).
        geometry: the tiling used for the card.
        palette: palette and taxtel indices of the card.
        mapping: gray to friction map used for the card.
        chunk_pixels: work on about this many pixels at a time (bounds memory).
    """
    cols, nh, nw = geometry.cols, geometry.tile_h, geometry.tile_w
    columns = geometry.tile_columns()
    col_owned = geometry.owned_mask("x")
    partial_cols = np.flatnonzero(~col_owned.all(axis=1))
    col_mask = col_owned[partial_cols].astype(np.float32)
    step = max(1, chunk_pixels // (nh * nw * cols))
    count = int(geometry.row_owned.sum()) * int(geometry.col_owned.sum())
    # the 95th percentile is the (count - rank + 1)-th largest absolute error
    largest_values = Largest(count - percentile_rank(count) + 1 if count else 0)
    squares = np.zeros((geometry.rows, cols))
    largest = np.zeros((geometry.rows, cols))
    percentile = np.zeros((geometry.rows, cols))
    owned_per_tile = geometry.row_owned[:, None] * geometry.col_owned[None, :]
    # values at or above each taxtel's 95th percentile: at least this many per taxtel
    tail = owned_per_tile - (95 * owned_per_tile + 99) // 100 + 1
    for first in range(0, geometry.rows, step):
        stop = min(geometry.rows, first + step)
        tiles = geometry.gather(pixels, first, stop, columns).transpose(0, 2, 1, 3)
        error = render_tiles(palette, geometry, first, stop, mapping).reshape(tiles.shape)
        np.subtract(tiles, error, out=error)  # (rows, cols, tile_h, tile_w), in place
        # zero the pixels a taxtel does not own (only the tile rows and columns that have any)
        row_owned = geometry.owned_mask("y", first, stop)
        for r in np.flatnonzero(~row_owned.all(axis=1)):
            error[r] *= row_owned[r].astype(np.float32)[None, :, None]
        if partial_cols.size:
            error[:, partial_cols] *= col_mask[None, :, None, :]
        squares[first:stop] = np.einsum("abij,abij->ab", error, error)
        np.abs(error, out=error)
        percentile[first:stop], largest[first:stop] = owned_percentile(
            error, geometry.row_owned[first:stop], geometry.col_owned
        )
        # the pixels a taxtel does not own were zeroed: below every owned value (>= 0), they
        # never displace one from the largest. Each taxtel so far holds ``tail`` values at or
        # above its percentile: the largest level that enough of them reach is a floor.
        floor = certified_floor(percentile[:stop].ravel(), tail[:stop].ravel(),
                                largest_values.keep)
        largest_values.add(error.reshape(-1), floor=floor, reorder=True)  # error: done with
    scale = mapping.scale
    return ReconstructionError(
        rms=scale * float(np.sqrt(squares.sum() / max(count, 1))),
        max=scale * float(largest.max(initial=0.0)),
        pixels=count,
        p95=scale * largest_values.smallest,
        taxtel_rms=scale * np.sqrt(squares / np.maximum(owned_per_tile, 1)),
        taxtel_max=scale * largest,
        taxtel_p95=scale * percentile,
    )


class Largest:
    """The ``keep`` largest of values that arrive in chunks: an exact order statistic without
    holding all the values. Each chunk adds only its values above the smallest kept, or, when
    the caller lets it reorder a chunk many times larger than ``keep``, the chunk's own
    ``keep`` largest, found by partitioning it where it lies."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self.values = np.zeros(0, dtype=np.float32)

    def add(self, values: np.ndarray, floor: float = 0.0, *, reorder: bool = False) -> None:
        """Take ``values`` (1-D) into account; ``floor``: a level that at least ``keep`` of the
        values seen so far (these included) reach, below which none can be kept.

        ``values`` must not be NaN (a NaN would sort above every number).

        With ``reorder``, ``values`` may be reordered in place. A chunk of at least 4 ``keep``
        values is then partitioned without a copy: selecting the values above ``floor`` by a
        mask costs more on such a chunk (the 95th percentile of a 1024^2 image's errors:
        0.35 million values of 1.1 million pass a typical floor; 1.1-1.6 ms -> 0.8 ms)."""
        if self.keep <= 0:
            return
        if self.values.size >= self.keep:
            floor = max(floor, float(self.values[0]))
        if reorder and values.size >= 4 * self.keep:
            cut = values.size - self.keep
            values.partition(cut)
            values = values[cut:]
        elif floor > 0.0:
            values = values[values >= floor]
        merged = np.concatenate([self.values, values])
        if merged.size > self.keep:
            cut = merged.size - self.keep
            merged.partition(cut)
            merged = merged[cut:]  # its first value is its smallest
        elif merged.size:
            low = int(np.argmin(merged))
            merged[[0, low]] = merged[[low, 0]]  # the smallest first
        self.values = merged

    @property
    def smallest(self) -> float:
        """The ``keep``-th largest value so far (0 before any)."""
        return float(self.values[0]) if self.values.size else 0.0


def certified_floor(levels: np.ndarray, counts: np.ndarray, keep: int) -> float:
    """The largest of ``levels`` such that the groups at or above it hold at least ``keep``
    values in all (each group ``i`` holds ``counts[i]`` values at or above ``levels[i]``), so
    that the ``keep``-th largest value is at least it; 0 when they hold fewer."""
    if keep <= 0 or int(counts.sum()) < keep:
        return 0.0
    order = np.argsort(-levels, kind="stable")
    reached = np.cumsum(counts[order])
    return float(levels[order][int(np.searchsorted(reached, keep))])


def percentile_rank(owned: int, percent: int = 95) -> int:
    """Nearest rank (1-based) of the ``percent``-th percentile of ``owned`` values:
    ``ceil(percent * owned / 100)``, in integers (``0.95 * n`` is not exact in floating point)."""
    return (percent * owned + 99) // 100


def owned_percentile(
    magnitude: np.ndarray, row_owned: np.ndarray, col_owned: np.ndarray, percent: int = 95
) -> tuple[np.ndarray, np.ndarray]:
    """Per tile, the ``percent``-th percentile (nearest rank) and the maximum of the values of
    the pixels the tile's taxtel owns.

    Args:
        magnitude: ``(rows, cols, tile_h, tile_w)`` values >= 0, zero on pixels a taxtel does not
            own (so those sort first and the rank is shifted past them). The values of each
            tile are reordered in place.
        row_owned, col_owned: pixels owned by each tile row and column (:class:`Geometry`).

    Returns:
        ``(percentile, maximum)``, each ``(rows, cols)``; 0 for a taxtel that owns no pixel.
        The maximum is read from the values at or above the percentile, where the partition
        puts them.
    """
    rows, cols, nh, nw = magnitude.shape
    flat = magnitude.reshape(rows, cols, nh * nw)
    out = np.zeros((rows, cols))
    top = np.zeros((rows, cols))
    for owned_y in counts_present(row_owned):
        r = np.nonzero(row_owned == owned_y)[0]
        for owned_x in counts_present(col_owned):
            owned = int(owned_y) * int(owned_x)
            if owned == 0:
                continue
            c = np.nonzero(col_owned == owned_x)[0]
            kth = nh * nw - owned + percentile_rank(owned, percent) - 1
            if _contiguous(r) and _contiguous(c):
                rs, cs = slice(int(r[0]), int(r[-1]) + 1), slice(int(c[0]), int(c[-1]) + 1)
                block = flat[rs, cs]
                block.partition(kth, axis=-1)  # in place: the caller needs no pixel order
                out[rs, cs] = block[..., kth]
                top[rs, cs] = block[..., kth:].max(axis=-1)
            else:
                block = np.partition(flat[np.ix_(r, c)], kth, axis=-1)
                out[np.ix_(r, c)] = block[..., kth]
                top[np.ix_(r, c)] = block[..., kth:].max(axis=-1)
    return out, top


def _contiguous(index: np.ndarray) -> bool:
    """Whether ``index`` (ascending) is a run of consecutive integers."""
    return index.size > 0 and int(index[-1]) - int(index[0]) + 1 == index.size


def counts_present(counts: np.ndarray) -> np.ndarray:
    """The distinct values of ``counts`` (small integers >= 0), ascending. (A plain
    ``np.unique`` imports ``numpy.ma`` on first use in numpy 2, 10 ms of a command's start.)"""
    return np.flatnonzero(np.bincount(counts.ravel()))
