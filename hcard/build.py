"""Constructors for cards, textures and components in code, with wire units and names.

Example (a 60 x 40 mm card in 5 mm taxtels: 12 x 8 of them)::

    >>> from hcard import build
    >>> grating = build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv", locking="velocity")
    >>> card = build.card(60.0, 40.0, taxtel_mm=5.0, textures=[grating])
    >>> card.grid.cols, card.grid.rows, len(card.grid.texture_index)
    (12, 8, 96)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np

import hcard.limits as limits
from hcard.channels import VALUE_OF_NAME
from hcard.errors import CardValidationError, Problem
from hcard.v1 import card_pb2 as pb
from hcard.version import __version__

CHANNELS: dict[str, int] = VALUE_OF_NAME
LOCKINGS: dict[str, int] = {
    "position": pb.LOCKING_POSITION,
    "velocity": pb.LOCKING_VELOCITY,
    "auto": pb.LOCKING_AUTO,
}


def _enum(value: str | int | None, table: dict[str, int], what: str, default: int) -> int:
    if value is None:
        return default
    if isinstance(value, str):
        try:
            return table[value.lower()]
        except KeyError:
            raise ValueError(f"unknown {what} {value!r}; choose from {sorted(table)}") from None
    return int(value)


def channel_value(name: str | int | None, default: int = pb.CHANNEL_UNSPECIFIED) -> pb.Channel:
    """The ``Channel`` enum value for ``"uv"``, ``"ev"``, ``"bipolar"`` (or an enum int)."""
    # protoc's stubs type an enum value as its wrapper class; at run time it is the int.
    return cast("pb.Channel", _enum(name, CHANNELS, "channel", default))


def locking_value(name: str | int | None, default: int = pb.LOCKING_AUTO) -> pb.Locking:
    """The ``Locking`` enum value for ``"position"``, ``"velocity"``, ``"auto"``."""
    return cast("pb.Locking", _enum(name, LOCKINGS, "locking", default))


def spatial(
    frequency: float,
    amplitude: float,
    phase: float = 0.0,
    orientation: float = 0.0,
    channel: str | int | None = None,
) -> pb.Component:
    """A grating: ``frequency`` cycles/mm, peak ``amplitude`` (relative friction), ``phase`` rad
    at the surface origin, wave-vector ``orientation`` in rad from +x towards +y."""
    return pb.Component(
        domain=pb.DOMAIN_SPATIAL,
        frequency=frequency,
        amplitude=amplitude,
        phase=phase,
        orientation=orientation,
        channel=channel_value(channel),
    )


def grating_period(period_mm: float, amplitude: float, **kwargs: float | str) -> pb.Component:
    """A grating given by its period in millimetres instead of its frequency."""
    return spatial(1.0 / period_mm, amplitude, **kwargs)  # type: ignore[arg-type]


def temporal(
    frequency: float, amplitude: float, phase: float = 0.0, channel: str | int | None = None
) -> pb.Component:
    """A vibration at ``frequency`` Hz running from touch-down, ``phase`` rad at touch-down."""
    return pb.Component(
        domain=pb.DOMAIN_TEMPORAL,
        frequency=frequency,
        amplitude=amplitude,
        phase=phase,
        channel=channel_value(channel),
    )


def texture(
    baseline: float = 1.0,
    components: Sequence[pb.Component] = (),
    *,
    channel: str | int = "bipolar",
    locking: str | int = "auto",
    name: str = "",
) -> pb.Texture:
    """A texture: ``baseline`` relative friction plus ``components``."""
    return pb.Texture(
        name=name,
        baseline=baseline,
        channel=channel_value(channel),
        locking=locking_value(locking),
        components=list(components),
    )


def card(
    width_mm: float,
    height_mm: float,
    *,
    taxtel_mm: float | tuple[float, float],
    textures: Sequence[pb.Texture],
    texture_index: Sequence[int] | np.ndarray | None = None,
    title: str = "",
    author: str = "",
    licence: str = "",
    description: str = "",
) -> pb.Card:
    """A card covering ``width_mm`` x ``height_mm`` with square (or ``(w, h)``) taxtels.

    ``texture_index`` is row-major (``rows x cols``, a 2-D array is accepted); by default
    every taxtel plays texture 0. The grid is sized to cover the surface.
    """
    tw, th = (taxtel_mm, taxtel_mm) if isinstance(taxtel_mm, int | float) else taxtel_mm
    cols = grid_count(width_mm, tw)
    rows = grid_count(height_mm, th)
    if cols > limits.MAX_GRID_COLS or rows > limits.MAX_GRID_ROWS or (
            cols * rows > limits.MAX_TAXTELS):
        # Checked before the index list is built: 1000 x 1000 mm at 0.05 mm once spent 25 s
        # and 3.7 GB making a card that validation then refused.
        raise CardValidationError([Problem(
            "grid", f"{width_mm:g} x {height_mm:g} mm in taxtels of {tw:g} x {th:g} mm needs "
            f"{cols} x {rows} taxtels, over the limits of {limits.MAX_GRID_COLS} x "
            f"{limits.MAX_GRID_ROWS} and {limits.MAX_TAXTELS} in all", "error", "G3")])
    index: np.ndarray
    if texture_index is None:
        index = np.zeros(cols * rows, dtype=np.uint32)
    else:
        index = np.asarray(texture_index, dtype=np.int64).ravel()
    return pb.Card(
        version=pb.FormatVersion(major=limits.FORMAT_MAJOR, minor=limits.FORMAT_MINOR),
        metadata=pb.Metadata(
            title=title,
            author=author,
            licence=licence,
            description=description,
            generator=f"hcard {__version__}",
        ),
        surface=pb.Surface(width_mm=width_mm, height_mm=height_mm),
        grid=pb.TaxtelGrid(
            taxtel_width_mm=tw,
            taxtel_height_mm=th,
            cols=cols,
            rows=rows,
            texture_index=[int(i) for i in index],
        ),
        textures=list(textures),
    )


def grid_count(extent_mm: float, taxtel_mm: float) -> int:
    """Taxtels needed to cover ``extent_mm`` (rule G4: the last one may overhang the edge)."""
    if not (math.isfinite(extent_mm) and math.isfinite(taxtel_mm)) or taxtel_mm <= 0:
        return 1
    return max(1, math.ceil(extent_mm / taxtel_mm - 1e-9))
