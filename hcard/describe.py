"""Human-readable descriptions of cards and their parts (used by ``hcard info``)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

import hcard.limits as limits
from hcard.channels import LABEL_OF_VALUE
from hcard.terminal_text import clipped
from hcard.v1 import card_pb2 as pb

CHANNEL_NAMES: dict[int, str] = {pb.CHANNEL_UNSPECIFIED: "texture", **LABEL_OF_VALUE}
LOCKING_NAMES: dict[int, str] = {
    pb.LOCKING_UNSPECIFIED: "unspecified",
    pb.LOCKING_POSITION: "position",
    pb.LOCKING_VELOCITY: "velocity",
    pb.LOCKING_AUTO: "auto",
}


def enum_name(table: dict[int, str], value: int) -> str:
    """Name of an enum value, or ``unknown(N)`` for a value of a newer minor version."""
    return table.get(value, f"unknown({value})")


def describe_component(component: pb.Component, locking: int) -> str:
    """One line: frequency, amplitude, phase, orientation and the resolved locking."""
    amplitude = f"A={component.amplitude:.4g}"
    phase = f"phase={math.degrees(component.phase):.1f} deg"
    channel = (
        f" channel={enum_name(CHANNEL_NAMES, component.channel)}" if component.channel else ""
    )
    if component.domain == pb.DOMAIN_TEMPORAL:
        return f"temporal {component.frequency:.6g} Hz  {amplitude}  {phase}{channel}"
    period = 1.0 / component.frequency if component.frequency > 0 else math.inf
    resolved = enum_name(LOCKING_NAMES, locking)
    if locking == pb.LOCKING_AUTO:
        resolved = "velocity" if period < limits.AUTO_LOCKING_PERIOD_MM else "position"
        resolved = f"auto->{resolved}"
    return (
        f"spatial {component.frequency:.6g} c/mm (period {period:.4g} mm)  {amplitude}  "
        f"{phase}  orientation={math.degrees(component.orientation):.1f} deg  "
        f"[{resolved}]{channel}"
    )


def taxtel_counts(card: pb.Card, shown: int) -> np.ndarray:
    """How many taxtels play each of the first ``shown`` textures (numpy: a card may hold
    millions of indices)."""
    import numpy as np  # here, not at import: card commands start without it

    if not card.grid.texture_index or shown == 0:
        return np.zeros(shown, dtype=np.int64)
    indices = np.fromiter(card.grid.texture_index, dtype=np.int64,
                          count=len(card.grid.texture_index))
    return np.bincount(indices[indices < shown], minlength=shown)


def describe_card(card: pb.Card) -> list[str]:
    """Lines of a readable summary of ``card``. Bounded for an invalid card too: at most
    :data:`~hcard.limits.MAX_TEXTURES` textures and :data:`~hcard.limits.MAX_COMPONENTS_PER_TEXTURE`
    components each are listed, the rest counted, and at most
    :data:`~hcard.terminal_text.MAX_SHOWN_CHARS` characters of each text are shown."""
    meta, surface, grid = card.metadata, card.surface, card.grid
    lines = [f"format version {card.version.major}.{card.version.minor}"]
    for label, value in (
        ("title", meta.title),
        ("author", meta.author),
        ("licence", meta.licence),
        ("generator", meta.generator),
        ("description", meta.description),
    ):
        if value:
            lines.append(f"{label}: {clipped(value)}")
    lines.append(f"surface: {surface.width_mm:g} x {surface.height_mm:g} mm")
    lines.append(
        f"grid: {grid.cols} x {grid.rows} taxtels of {grid.taxtel_width_mm:g} x "
        f"{grid.taxtel_height_mm:g} mm"
    )
    textures = card.textures
    shown = min(len(textures), limits.MAX_TEXTURES)
    counts = taxtel_counts(card, shown)
    n_components = sum(len(t.components) for t in textures) if shown == len(textures) else None
    lines.append(f"textures: {len(textures)}"
                 + (f" ({n_components} components in all)" if n_components is not None else ""))
    for i in range(shown):
        texture = textures[i]
        name = f" '{clipped(texture.name)}'" if texture.name else ""
        n = len(texture.components)
        lines.append(
            f"  [{i}]{name}: baseline {texture.baseline:.4g}, "
            f"{enum_name(CHANNEL_NAMES, texture.channel)}, "
            f"{enum_name(LOCKING_NAMES, texture.locking)} locking, "
            f"{n} component(s), on {int(counts[i])} taxtel(s)"
        )
        for c in range(min(n, limits.MAX_COMPONENTS_PER_TEXTURE)):
            lines.append("      " + describe_component(texture.components[c], texture.locking))
        if n > limits.MAX_COMPONENTS_PER_TEXTURE:
            lines.append(f"      ... {n - limits.MAX_COMPONENTS_PER_TEXTURE} more not shown")
    if len(textures) > shown:
        lines.append(f"  ... {len(textures) - shown} more textures not shown")
    return lines


def card_summary(card: pb.Card) -> dict[str, Any]:
    """The content of ``card`` as plain data for ``hcard info --json``: the same bounds as
    :func:`describe_card` (textures and components past the limits are counted, not listed,
    texts clipped)."""
    meta, surface, grid = card.metadata, card.surface, card.grid
    textures = card.textures
    shown = min(len(textures), limits.MAX_TEXTURES)
    counts = taxtel_counts(card, shown)
    listed = []
    for i in range(shown):
        texture = textures[i]
        listed.append({
            "index": i,
            "name": clipped(texture.name),
            "baseline": texture.baseline,
            "channel": enum_name(CHANNEL_NAMES, texture.channel),
            "locking": enum_name(LOCKING_NAMES, texture.locking),
            "components": len(texture.components),
            "taxtels": int(counts[i]),
        })
    return {
        "format_version": f"{card.version.major}.{card.version.minor}",
        "metadata": {name: clipped(getattr(meta, name))
                     for name in ("title", "author", "licence", "generator", "description")},
        "surface_mm": [surface.width_mm, surface.height_mm],
        "grid": {"cols": grid.cols, "rows": grid.rows,
                 "taxtel_mm": [grid.taxtel_width_mm, grid.taxtel_height_mm]},
        "texture_count": len(textures),
        "textures": listed,
    }
