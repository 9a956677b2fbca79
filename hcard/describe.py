"""Human-readable descriptions of cards and their parts (used by ``hcard info``)."""

from __future__ import annotations

import math
from collections import Counter

from hcard import limits
from hcard.v1 import card_pb2 as pb

CHANNEL_NAMES = {
    pb.CHANNEL_UNSPECIFIED: "texture",
    pb.CHANNEL_UV: "UV",
    pb.CHANNEL_EV: "EV",
    pb.CHANNEL_BIPOLAR: "BIPOLAR",
}
LOCKING_NAMES = {
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


def describe_card(card: pb.Card) -> list[str]:
    """Lines of a readable summary of ``card``."""
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
            lines.append(f"{label}: {value}")
    lines.append(f"surface: {surface.width_mm:g} x {surface.height_mm:g} mm")
    lines.append(
        f"grid: {grid.cols} x {grid.rows} taxtels of {grid.taxtel_width_mm:g} x "
        f"{grid.taxtel_height_mm:g} mm"
    )
    counts = Counter(grid.texture_index)
    n_components = sum(len(t.components) for t in card.textures)
    lines.append(f"textures: {len(card.textures)} ({n_components} components in all)")
    for i, texture in enumerate(card.textures):
        name = f" '{texture.name}'" if texture.name else ""
        lines.append(
            f"  [{i}]{name}: baseline {texture.baseline:.4g}, "
            f"{enum_name(CHANNEL_NAMES, texture.channel)}, "
            f"{enum_name(LOCKING_NAMES, texture.locking)} locking, "
            f"{len(texture.components)} component(s), on {counts.get(i, 0)} taxtel(s)"
        )
        for component in texture.components:
            lines.append("      " + describe_component(component, texture.locking))
    return lines
