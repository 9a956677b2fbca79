"""Physical size of the image and its tiling into taxtels.

The image covers the surface exactly: pixel (row r, column c) covers x in [c/ppx, (c+1)/ppx) mm
and y in [r/ppy, (r+1)/ppy) mm, with ``ppx``, ``ppy`` pixels per millimetre, origin at the top-left
corner, +y down. Taxtel (column c, row r) covers [c*T, (c+1)*T) x [r*T, (r+1)*T) mm. A pixel
belongs to the taxtel that contains its centre.

For the analysis every taxtel gets a tile of a uniform size in pixels, ``ceil(T * pp)``, starting
at the first pixel the taxtel owns; a tile may reach one pixel into the next taxtel when ``T * pp``
is not a whole number. The last column or row of taxtels may overhang the surface: its tile is
moved back inside the image (ending at the image edge) so that it is analysed on real pixels
rather than on a mirrored copy, which would show the taxtel's gratings reflected; a tile is at
most the image's size. Every tile pixel is therefore a pixel of the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np

from hcard import limits
from hcard.build import grid_count
from hcard.errors import ImageError
from hcard.quantities import UM_PER_MM

MM_PER_INCH = 25.4
MAX_DPI = 25_400.0
"""Finest resolution accepted, dots per inch (1 um pixels, far finer than a finger resolves and
than any grating a card can hold at 50 cycles/mm)."""
MIN_STORED_DPI = 10.0
"""Coarsest resolution taken from an image's metadata, dots per inch (2.5 mm pixels); a stored
value outside MIN_STORED_DPI..MAX_DPI is reported and the default assumed."""
DEFAULT_DPI = 254.0
"""Resolution assumed when neither the options nor the file give one: 0.1 mm per pixel."""


@dataclass(frozen=True)
class Geometry:
    """How pixels map to the surface and to taxtels.

    Attributes:
        width_px, height_px: image size, pixels.
        width_mm, height_mm: surface size, millimetres.
        ppx, ppy: pixels per millimetre along x and y.
        taxtel_mm: taxtel side, millimetres.
        cols, rows: taxtel grid.
        tile_w, tile_h: analysis tile size, pixels.
        col_start, row_start: first pixel owned by each taxtel column / row (``int64``).
        col_owned, row_owned: pixels owned by each taxtel column / row (their centres lie in the
            taxtel and inside the image); always at most the tile size.
        col_tile, row_tile: first pixel of each column's / row's analysis tile (``int64``);
            the owned pixels are ``col_start - col_tile`` onwards within the tile.
        size_source: how the physical size was found, in words (for the summary).
    """

    width_px: int
    height_px: int
    width_mm: float
    height_mm: float
    ppx: float
    ppy: float
    taxtel_mm: float
    cols: int
    rows: int
    tile_w: int
    tile_h: int
    col_start: np.ndarray
    row_start: np.ndarray
    col_owned: np.ndarray
    row_owned: np.ndarray
    col_tile: np.ndarray
    row_tile: np.ndarray
    size_source: str

    @property
    def n_taxtels(self) -> int:
        """Number of taxtels, ``cols * rows``."""
        return self.cols * self.rows

    @property
    def pixel_pitch_mm(self) -> tuple[float, float]:
        """Pixel size along x and y, millimetres."""
        return 1.0 / self.ppx, 1.0 / self.ppy

    def tile_columns(self) -> np.ndarray:
        """Image column of every pixel of every tile column, ``(cols * tile_w,)``."""
        return (self.col_tile[:, None] + np.arange(self.tile_w)[None, :]).ravel()

    def tile_rows(self, first: int = 0, stop: int | None = None) -> np.ndarray:
        """Image row of every pixel of tile rows ``first:stop``, ``(n * tile_h,)``."""
        return (self.row_tile[first:stop, None] + np.arange(self.tile_h)[None, :]).ravel()

    def owned_mask(self, axis: str, first: int = 0, stop: int | None = None) -> np.ndarray:
        """``(n, tile)`` booleans: which pixels of each tile (``axis`` ``"x"``: columns,
        ``"y"``: rows ``first:stop``) belong to the tile's taxtel."""
        if axis == "x":
            start, tile, owned, size = self.col_start, self.col_tile, self.col_owned, self.tile_w
        else:
            start, tile, owned, size = self.row_start, self.row_tile, self.row_owned, self.tile_h
        offset = (start - tile)[first:stop, None]
        j = np.arange(size)[None, :]
        return (j >= offset) & (j < offset + owned[first:stop, None])

    def gather(
        self, pixels: np.ndarray, first: int, stop: int, columns: np.ndarray | None = None
    ) -> np.ndarray:
        """Tiles of taxtel rows ``first:stop``: array ``(stop-first, tile_h, cols, tile_w)``.

        ``columns`` is :meth:`tile_columns` (pass it to avoid recomputing it per chunk). Runs
        of consecutive pixels are copied as slices, in one copy (a tiling of whole pixels is a
        reshaped view of the image); an axis of many runs (overlapping tiles of a pixel pitch
        that does not divide the taxtel) is gathered with ``take``.
        """
        cols_index = self.tile_columns() if columns is None else columns
        rows_index = self.tile_rows(first, stop)
        row_runs, col_runs = _runs(rows_index), _runs(cols_index)
        if row_runs is None or col_runs is None:
            block = _along(pixels, rows_index, row_runs, axis=0)
            block = _along(block, cols_index, col_runs, axis=1)
        elif len(row_runs) == 1 and len(col_runs) == 1:
            (top, bottom), (left, right) = row_runs[0], col_runs[0]
            block = pixels[top:bottom, left:right]
        else:  # one copy, block by block (slicing twice would copy twice)
            block = np.empty((rows_index.size, cols_index.size), dtype=pixels.dtype)
            out_row = 0
            for top, bottom in row_runs:
                out_col = 0
                for left, right in col_runs:
                    block[out_row : out_row + bottom - top, out_col : out_col + right - left] = (
                        pixels[top:bottom, left:right])
                    out_col += right - left
                out_row += bottom - top
        return block.reshape(stop - first, self.tile_h, self.cols, self.tile_w)


def _along(
    array: np.ndarray, index: np.ndarray, runs: list[tuple[int, int]] | None, axis: int
) -> np.ndarray:
    """``array.take(index, axis)``; a view when ``index`` is one run (see :func:`_runs`)."""
    if runs is not None and len(runs) == 1:
        start, stop = runs[0]
        return array[start:stop] if axis == 0 else array[:, start:stop]
    return array.take(index, axis=axis)


def _runs(index: np.ndarray) -> list[tuple[int, int]] | None:
    """``index`` as ``(start, stop)`` runs of consecutive integers, or None when it has more
    than five (copying a few slices is several times faster than ``take``)."""
    breaks = np.flatnonzero(np.diff(index) != 1) + 1
    if breaks.size > 4:
        return None
    bounds = [0, *breaks.tolist(), index.size]
    return [(int(index[a]), int(index[b - 1]) + 1) for a, b in pairwise(bounds)]


def resolve_geometry(
    width_px: int,
    height_px: int,
    *,
    taxtel_mm: float,
    width_mm: float | None = None,
    height_mm: float | None = None,
    dpi: float | None = None,
    embedded_dpi: tuple[float, float] | None = None,
    source: Path | str = "",
) -> Geometry:
    """The geometry of an image of ``width_px`` x ``height_px`` pixels.

    The physical size comes from ``width_mm``/``height_mm`` (one of them keeps the aspect ratio
    with square pixels; both allow rectangular pixels), else from ``dpi``, else from the file's
    ``embedded_dpi``, else from :data:`DEFAULT_DPI`.

    Raises:
        ValueError: ``dpi`` given together with a width or height.
        ImageError: the surface or the taxtel grid exceeds the card limits.
    """
    if dpi is not None and (width_mm is not None or height_mm is not None):
        raise ValueError("give either a DPI or a width/height in millimetres, not both")
    if width_mm is not None and height_mm is not None:
        ppx, ppy = width_px / width_mm, height_px / height_mm
        how = "from --width-mm and --height-mm"
    elif width_mm is not None:
        ppx = ppy = width_px / width_mm
        how = "from --width-mm, square pixels"
    elif height_mm is not None:
        ppx = ppy = height_px / height_mm
        how = "from --height-mm, square pixels"
    elif dpi is not None:
        ppx = ppy = dpi / MM_PER_INCH
        how = f"from --dpi {dpi:g}"
    elif embedded_dpi is not None and all(
            MIN_STORED_DPI <= value <= MAX_DPI for value in embedded_dpi):
        ppx, ppy = embedded_dpi[0] / MM_PER_INCH, embedded_dpi[1] / MM_PER_INCH
        how = f"from the DPI stored in the image ({embedded_dpi[0]:g} x {embedded_dpi[1]:g})"
    elif embedded_dpi is not None:
        ppx = ppy = DEFAULT_DPI / MM_PER_INCH
        how = (f"assumed {DEFAULT_DPI:g} dpi: the image stores {embedded_dpi[0]:g} x "
               f"{embedded_dpi[1]:g} dpi, outside {MIN_STORED_DPI:g}-{MAX_DPI:g}")
    else:
        ppx = ppy = DEFAULT_DPI / MM_PER_INCH
        how = f"assumed {DEFAULT_DPI:g} dpi: no size given and no DPI stored in the image"
    finest = MAX_DPI / MM_PER_INCH
    if max(ppx, ppy) > finest * (1 + 1e-9):
        raise ImageError(
            f"{str(source) + ': ' if str(source) else ''}pixels of "
            f"{UM_PER_MM / max(ppx, ppy):.3g} um "
            f"({how}) are finer than the {UM_PER_MM / finest:g} um ({MAX_DPI:g} dpi) an encoder "
            "accepts; give a larger --width-mm/--height-mm or a lower --dpi")
    surface_w, surface_h = width_px / ppx, height_px / ppy
    prefix = f"{source}: " if str(source) else ""
    if max(surface_w, surface_h) > limits.MAX_SURFACE_MM:
        raise ImageError(
            f"{prefix}the surface would be {surface_w:g} x {surface_h:g} mm ({how}), over the "
            f"limit of {limits.MAX_SURFACE_MM:g} mm; give --width-mm/--height-mm or --dpi"
        )
    cols, rows = grid_count(surface_w, taxtel_mm), grid_count(surface_h, taxtel_mm)
    if (
        cols > limits.MAX_GRID_COLS
        or rows > limits.MAX_GRID_ROWS
        or cols * rows > limits.MAX_TAXTELS
    ):
        raise ImageError(
            f"{prefix}{surface_w:g} x {surface_h:g} mm in {taxtel_mm:g} mm taxtels needs a "
            f"{cols} x {rows} grid, over the card limits ({limits.MAX_GRID_COLS} x "
            f"{limits.MAX_GRID_ROWS}, {limits.MAX_TAXTELS} taxtels); use a larger --taxtel-mm"
        )
    # A tile never holds more than the image: a taxtel wider than the whole image at a high
    # resolution (a stored 150,000 dpi, --dpi 1e6) once asked for a 29,528-pixel-square tile
    # (6.5 GB) from a 32-pixel image.
    tile_w = max(1, min(math.ceil(taxtel_mm * ppx - 1e-9), width_px))
    tile_h = max(1, min(math.ceil(taxtel_mm * ppy - 1e-9), height_px))
    col_start, col_owned = taxtel_spans(cols, taxtel_mm * ppx, width_px, tile_w)
    row_start, row_owned = taxtel_spans(rows, taxtel_mm * ppy, height_px, tile_h)
    # Tiles end inside the image where it is large enough (see the module docstring).
    col_tile = np.minimum(col_start, max(width_px - tile_w, 0))
    row_tile = np.minimum(row_start, max(height_px - tile_h, 0))
    return Geometry(
        width_px=width_px,
        height_px=height_px,
        width_mm=surface_w,
        height_mm=surface_h,
        ppx=ppx,
        ppy=ppy,
        taxtel_mm=taxtel_mm,
        cols=cols,
        rows=rows,
        tile_w=tile_w,
        tile_h=tile_h,
        col_start=col_start,
        row_start=row_start,
        col_owned=col_owned,
        row_owned=row_owned,
        col_tile=col_tile,
        row_tile=row_tile,
        size_source=how,
    )


def taxtel_spans(
    count: int, taxtel_px: float, size_px: int, tile_px: int
) -> tuple[np.ndarray, np.ndarray]:
    """First pixel and number of owned pixels of each of ``count`` taxtels along one axis.

    Pixel ``j`` belongs to taxtel ``floor((j + 0.5) / taxtel_px)``, so taxtel ``c`` starts at
    ``ceil(c * taxtel_px - 0.5)``.
    """
    edges = np.ceil(np.arange(count + 1) * taxtel_px - 0.5 - 1e-9).astype(np.int64)
    edges = np.clip(edges, 0, size_px)
    edges[-1] = size_px
    start = np.minimum(edges[:-1], size_px - 1)
    owned = np.clip(edges[1:] - edges[:-1], 0, tile_px)
    return start, owned
