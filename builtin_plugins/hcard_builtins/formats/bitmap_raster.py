"""A card's relative friction at the centres of a bitmap's pixels, position-locked: the picture
a Tanvas or TPad export draws and the reference an embedded card is checked against
(spec/interchange/bitmaps.md IB8).

No new evaluator: each channel group's textures go through the image encoder's reconstruction
(:func:`hcard_builtins.image.reconstruct.render_rows`, the card evaluated position-locked at
pixel centres, thesis section 5.4.2), and the groups are combined by the renderer's own channel
split (:func:`hcard.render.synthesis.channel_targets`, rule R11): the friction of a pixel is
``m = u * e`` there. What a still picture cannot hold is left out and counted
(:class:`RasterPlan`): temporal components (they run in time from touch-down, rule R9) and
gratings at or beyond the pixel grid's Nyquist limit (half a cycle per pixel along x or y,
which would alias: the renderer attenuates such signals rather than alias them, rule R10).
Velocity-locked components are drawn position-locked, phase at the surface origin.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from hcard.channels import GROUP_OF_VALUE
from hcard.v1 import card_pb2 as pb
from hcard_builtins.image.geometry import Geometry, taxtel_spans
from hcard_builtins.image.reconstruct import FrictionMap, render_rows
from hcard_builtins.image.textures import Textures

CHUNK_PIXELS = 1 << 21
"""Pixels rendered at a time (bounds the memory of the tiles of a block of taxtel rows)."""
_AS_IS = FrictionMap(high=0.0, scale=-1.0)
"""The identity map of render_rows: its 'gray level' is then the friction deviation itself."""


@dataclass(frozen=True)
class RasterPlan:
    """How a card is drawn on a pixel grid.

    Attributes:
        geometry: the pixel grid over the card's surface and its taxtels.
        groups: per channel group (R11 order: UV, EV, BIPOLAR) the palette's deviations
            (baseline - 1 on the texture's group) and its drawable components.
        temporal: components left out because they are temporal.
        aliased: spatial components left out at or beyond the Nyquist limit.
        velocity_locked: spatial components drawn position-locked although the card
            velocity-locks them (rule R8).
    """

    geometry: Geometry
    groups: tuple[Textures, Textures, Textures]
    temporal: int
    aliased: int
    velocity_locked: int


def raster_geometry(card: pb.Card, width_px: int, height_px: int) -> Geometry:
    """The pixel grid of ``width_px`` x ``height_px`` pixels covering the card's surface
    exactly, with the card's taxtels (square or not): pixel (row r, column c) covers
    ``[c, c+1) * width_mm / width_px`` along x, and belongs to the taxtel holding its centre
    (rule R7 at the centre)."""
    ppx, ppy = width_px / card.surface.width_mm, height_px / card.surface.height_mm
    tw, th = card.grid.taxtel_width_mm, card.grid.taxtel_height_mm
    cols, rows = int(card.grid.cols), int(card.grid.rows)
    tile_w = max(1, min(math.ceil(tw * ppx - 1e-9), width_px))
    tile_h = max(1, min(math.ceil(th * ppy - 1e-9), height_px))
    col_start, col_owned = taxtel_spans(cols, tw * ppx, width_px, tile_w)
    row_start, row_owned = taxtel_spans(rows, th * ppy, height_px, tile_h)
    return Geometry(
        width_px=width_px, height_px=height_px,
        width_mm=card.surface.width_mm, height_mm=card.surface.height_mm,
        ppx=ppx, ppy=ppy, taxtel_mm=tw, cols=cols, rows=rows, tile_w=tile_w, tile_h=tile_h,
        col_start=col_start, row_start=row_start, col_owned=col_owned, row_owned=row_owned,
        col_tile=np.minimum(col_start, max(width_px - tile_w, 0)),
        row_tile=np.minimum(row_start, max(height_px - tile_h, 0)),
        size_source="the card's surface",
    )


def velocity_locks(component: pb.Component, locking: int) -> bool:
    """Whether the renderer velocity-locks this spatial component (rule R8)."""
    if locking == pb.LOCKING_VELOCITY:
        return True
    return locking == pb.LOCKING_AUTO and 1.0 / component.frequency < 10.0


def plan_raster(card: pb.Card, width_px: int, height_px: int) -> RasterPlan:
    """The drawing of ``card`` on ``width_px`` x ``height_px`` pixels (:class:`RasterPlan`)."""
    geometry = raster_geometry(card, width_px, height_px)
    n = len(card.textures)
    width = max((len(t.components) for t in card.textures), default=0)
    baseline = np.zeros((3, n))
    k = np.zeros((3, n, max(width, 1), 2))
    coef = np.zeros((3, n, max(width, 1)), dtype=np.complex128)
    valid = np.zeros((3, n, max(width, 1)), dtype=bool)
    temporal = aliased = locked = 0
    for p, texture in enumerate(card.textures):
        baseline[GROUP_OF_VALUE[texture.channel], p] = texture.baseline - 1.0
        for j, component in enumerate(texture.components):
            if component.domain != pb.DOMAIN_SPATIAL:
                temporal += 1
                continue
            kx = component.frequency * math.cos(component.orientation)
            ky = component.frequency * math.sin(component.orientation)
            if abs(kx) >= geometry.ppx / 2 or abs(ky) >= geometry.ppy / 2:
                aliased += 1
                continue
            locked += velocity_locks(component, texture.locking)
            group = GROUP_OF_VALUE[component.channel or texture.channel]
            k[group, p, j] = (kx, ky)
            coef[group, p, j] = component.amplitude * np.exp(1j * component.phase)
            valid[group, p, j] = True
    groups = tuple(Textures(baseline[g], k[g], coef[g], valid[g]) for g in range(3))
    return RasterPlan(geometry, groups, temporal, aliased, locked)  # type: ignore[arg-type]


def friction_rows(card: pb.Card, plan: RasterPlan) -> Iterator[tuple[int, np.ndarray]]:
    """The card's relative friction ``m`` (rule R11) at every pixel centre, position-locked,
    in blocks of whole taxtel rows: ``(first pixel row, (rows, width_px) float64 array)``,
    top to bottom, covering the image."""
    from hcard.render.synthesis import channel_targets  # the renderer: at export time only

    geometry = plan.geometry
    index = np.asarray(card.grid.texture_index, dtype=np.int64)
    cols, nh, nw = geometry.cols, geometry.tile_h, geometry.tile_w
    step = max(1, CHUNK_PIXELS // (nh * nw * cols))
    owner = np.minimum(np.searchsorted(geometry.col_start, np.arange(geometry.width_px),
                                       side="right") - 1, cols - 1)
    x_in_tile = np.minimum(np.arange(geometry.width_px) - geometry.col_tile[owner], nw - 1)
    for first in range(0, geometry.rows, step):
        stop = min(geometry.rows, first + step)
        top = int(geometry.row_start[first])
        bottom = (geometry.height_px if stop == geometry.rows
                  else int(geometry.row_start[stop]))
        if bottom <= top:
            continue
        deviation = np.empty((3, bottom - top, geometry.width_px))
        tiles_index = index[first * cols:stop * cols]
        for g, textures in enumerate(plan.groups):
            tiles = render_rows(textures, tiles_index, geometry, first, stop, _AS_IS)
            tiles = tiles.reshape(stop - first, cols, nh, nw)
            deviation[g] = _owned_pixels(tiles, geometry, first, stop, top, bottom, owner,
                                         x_in_tile)
        u, e = channel_targets(deviation.reshape(3, -1))
        yield top, (u * e).reshape(bottom - top, geometry.width_px)


def _owned_pixels(tiles: np.ndarray, geometry: Geometry, first: int, stop: int, top: int,
                  bottom: int, owner: np.ndarray, x_in_tile: np.ndarray) -> np.ndarray:
    """Pixel rows ``top:bottom`` assembled from the tiles of taxtel rows ``first:stop``
    (``(rows, cols, tile_h, tile_w)``): every pixel from the tile of the taxtel owning it."""
    y = np.arange(top, bottom)
    row_owner = np.minimum(np.searchsorted(geometry.row_start[first:stop], y, side="right")
                           - 1 + first, stop - 1)
    y_in_tile = np.minimum(y - geometry.row_tile[row_owner], geometry.tile_h - 1)
    return np.asarray(tiles[(row_owner - first)[:, None], owner[None, :],
                            y_in_tile[:, None], x_in_tile[None, :]], dtype=np.float64)
