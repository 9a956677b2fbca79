"""Validation of haptic cards against the rules of spec/README.md ("Validation rules").

:func:`validate` never raises for a bad card: it returns every problem it finds, each with the
field path and the reason, so that a tool can show them all at once.
"""

from __future__ import annotations

import math

from hcard import limits
from hcard.errors import Problem
from hcard.v1 import card_pb2 as pb

_CHANNELS = {pb.CHANNEL_UV, pb.CHANNEL_EV, pb.CHANNEL_BIPOLAR}
_LOCKINGS = {pb.LOCKING_POSITION, pb.LOCKING_VELOCITY, pb.LOCKING_AUTO}
_DOMAINS = {pb.DOMAIN_SPATIAL, pb.DOMAIN_TEMPORAL}


def validate(card: pb.Card) -> list[Problem]:
    """Return every problem of ``card``; an empty list means the card is valid.

    Errors make a card invalid; warnings (``severity == "warning"``) flag content that renders
    differently from how it is written (for example a UV swing clipped at relative friction 1).
    """
    problems: list[Problem] = []
    _check_version(card, problems)
    _check_metadata(card, problems)
    _check_surface_and_grid(card, problems)
    _check_textures(card, problems)
    return problems


def errors_of(problems: list[Problem]) -> list[Problem]:
    """The problems of severity ``"error"``."""
    return [p for p in problems if p.severity == "error"]


def _finite(value: float) -> bool:
    return math.isfinite(value)


def _check_version(card: pb.Card, out: list[Problem]) -> None:
    if not card.HasField("version"):
        out.append(Problem("version", "missing: a card must state its format version"))
    elif card.version.major != limits.FORMAT_MAJOR:
        out.append(
            Problem(
                "version.major",
                f"unsupported major version {card.version.major} "
                f"(this reader implements {limits.FORMAT_MAJOR})",
            )
        )


def _check_metadata(card: pb.Card, out: list[Problem]) -> None:
    for name in ("title", "author", "licence", "generator", "description"):
        text = getattr(card.metadata, name)
        if len(text) > limits.MAX_TEXT_LENGTH:
            out.append(
                Problem(
                    f"metadata.{name}",
                    f"{len(text)} characters, over the limit of {limits.MAX_TEXT_LENGTH}",
                )
            )


def _check_length(value: float, path: str, upper: float, lower: float, out: list[Problem]) -> bool:
    """Check a length in mm is finite and within (lower, upper]; report and return False if not."""
    if not _finite(value):
        out.append(Problem(path, f"must be a finite number of millimetres, got {value}"))
    elif value <= 0:
        out.append(Problem(path, f"must be > 0 mm, got {value}"))
    elif value < lower:
        out.append(Problem(path, f"must be at least {lower} mm, got {value}"))
    elif value > upper:
        out.append(Problem(path, f"must be at most {upper} mm, got {value}"))
    else:
        return True
    return False


def _check_surface_and_grid(card: pb.Card, out: list[Problem]) -> None:
    surface, grid = card.surface, card.grid
    width_ok = _check_length(surface.width_mm, "surface.width_mm", limits.MAX_SURFACE_MM, 0, out)
    height_ok = _check_length(surface.height_mm, "surface.height_mm", limits.MAX_SURFACE_MM, 0, out)
    tw_ok = _check_length(
        grid.taxtel_width_mm,
        "grid.taxtel_width_mm",
        limits.MAX_SURFACE_MM,
        limits.MIN_TAXTEL_MM,
        out,
    )
    th_ok = _check_length(
        grid.taxtel_height_mm,
        "grid.taxtel_height_mm",
        limits.MAX_SURFACE_MM,
        limits.MIN_TAXTEL_MM,
        out,
    )
    dims_ok = True
    for name, count, most in (
        ("cols", grid.cols, limits.MAX_GRID_COLS),
        ("rows", grid.rows, limits.MAX_GRID_ROWS),
    ):
        if count < 1:
            out.append(Problem(f"grid.{name}", "must be at least 1"))
            dims_ok = False
        elif count > most:
            out.append(Problem(f"grid.{name}", f"{count} exceeds the limit of {most}"))
            dims_ok = False
    if dims_ok and grid.cols * grid.rows > limits.MAX_TAXTELS:
        out.append(
            Problem(
                "grid",
                f"{grid.cols} x {grid.rows} = {grid.cols * grid.rows} taxtels exceeds the "
                f"limit of {limits.MAX_TAXTELS}",
            )
        )
        dims_ok = False
    if dims_ok and len(grid.texture_index) != grid.cols * grid.rows:
        out.append(
            Problem(
                "grid.texture_index",
                f"has {len(grid.texture_index)} entries but the grid is {grid.cols} x "
                f"{grid.rows} = {grid.cols * grid.rows} taxtels",
            )
        )
    if dims_ok and width_ok and tw_ok:
        _check_cover("cols", grid.cols, grid.taxtel_width_mm, surface.width_mm, out)
    if dims_ok and height_ok and th_ok:
        _check_cover("rows", grid.rows, grid.taxtel_height_mm, surface.height_mm, out)
    n_textures = len(card.textures)
    for i, index in enumerate(grid.texture_index):
        if index >= n_textures:
            out.append(
                Problem(
                    f"grid.texture_index[{i}]",
                    f"texture {index} is outside the palette of {n_textures} texture(s)",
                )
            )


def _check_cover(name: str, count: int, taxtel: float, extent: float, out: list[Problem]) -> None:
    """The grid must cover the surface with no spare column or row (spec rule G4)."""
    tolerance = 1e-9 * max(extent, 1.0)
    covered = count * taxtel
    if covered + tolerance < extent:
        out.append(
            Problem(
                f"grid.{name}",
                f"{count} taxtels of {taxtel} mm cover {covered:g} mm, less than the surface "
                f"({extent:g} mm)",
            )
        )
    elif (count - 1) * taxtel >= extent + tolerance:
        out.append(
            Problem(
                f"grid.{name}",
                f"{count} taxtels of {taxtel} mm reach {covered:g} mm: the last one lies "
                f"wholly outside the surface ({extent:g} mm)",
            )
        )


def _check_textures(card: pb.Card, out: list[Problem]) -> None:
    textures = card.textures
    if not textures:
        out.append(Problem("textures", "the palette is empty: a card needs at least one texture"))
    elif len(textures) > limits.MAX_TEXTURES:
        out.append(
            Problem(
                "textures", f"{len(textures)} textures exceed the limit of {limits.MAX_TEXTURES}"
            )
        )
    names: dict[str, int] = {}
    for t, texture in enumerate(textures):
        path = f"textures[{t}]"
        if texture.name:
            if texture.name in names:
                out.append(
                    Problem(
                        f"{path}.name",
                        f"duplicate name {texture.name!r} (also textures[{names[texture.name]}])",
                    )
                )
            names.setdefault(texture.name, t)
            if len(texture.name) > limits.MAX_TEXT_LENGTH:
                out.append(Problem(f"{path}.name", "name is too long"))
        _check_texture(texture, path, out)


def _check_amplitude_like(value: float, path: str, what: str, out: list[Problem]) -> bool:
    if not _finite(value):
        out.append(Problem(path, f"{what} must be finite, got {value}"))
    elif value < 0:
        out.append(Problem(path, f"{what} must be >= 0, got {value}"))
    elif value > limits.MAX_RELATIVE_FRICTION:
        out.append(
            Problem(path, f"{what} {value} exceeds the limit of {limits.MAX_RELATIVE_FRICTION}")
        )
    else:
        return True
    return False


def _check_texture(texture: pb.Texture, path: str, out: list[Problem]) -> None:
    baseline_ok = _check_amplitude_like(
        texture.baseline, f"{path}.baseline", "baseline relative friction", out
    )
    if texture.channel not in _CHANNELS:
        out.append(
            Problem(
                f"{path}.channel",
                "must be CHANNEL_UV, CHANNEL_EV or CHANNEL_BIPOLAR"
                + (" (unspecified)" if texture.channel == 0 else f" (got {texture.channel})"),
            )
        )
    if texture.locking not in _LOCKINGS:
        out.append(
            Problem(
                f"{path}.locking",
                "must be LOCKING_POSITION, LOCKING_VELOCITY or LOCKING_AUTO"
                + (" (unspecified)" if texture.locking == 0 else f" (got {texture.locking})"),
            )
        )
    if baseline_ok:
        if texture.channel == pb.CHANNEL_UV and texture.baseline > 1.0:
            out.append(
                Problem(
                    f"{path}.baseline",
                    f"UV can only lower friction: baseline {texture.baseline} > 1",
                )
            )
        elif texture.channel == pb.CHANNEL_EV and texture.baseline < 1.0:
            out.append(
                Problem(
                    f"{path}.baseline",
                    f"EV can only raise friction: baseline {texture.baseline} < 1",
                )
            )
    n = len(texture.components)
    if n > limits.MAX_COMPONENTS_PER_TEXTURE:
        out.append(
            Problem(
                f"{path}.components",
                f"{n} components exceed the limit of {limits.MAX_COMPONENTS_PER_TEXTURE}",
            )
        )
    swing = 0.0
    for c, component in enumerate(texture.components):
        if _check_component(component, f"{path}.components[{c}]", out):
            swing += component.amplitude
    if baseline_ok and texture.channel == pb.CHANNEL_UV and texture.baseline + swing > 1.0 + 1e-12:
        out.append(
            Problem(
                path,
                f"UV texture can reach {texture.baseline + swing:.3g} > 1: the part above 1 is "
                "clipped when rendered",
                "warning",
            )
        )
    if baseline_ok and texture.baseline - swing < 0.0:
        out.append(
            Problem(
                path,
                f"texture can fall to {texture.baseline - swing:.3g} < 0: the part below 0 is "
                "clipped when rendered",
                "warning",
            )
        )


def _check_component(component: pb.Component, path: str, out: list[Problem]) -> bool:
    """Check one component; return True when its amplitude is usable."""
    if component.domain not in _DOMAINS:
        out.append(
            Problem(f"{path}.domain", "must be DOMAIN_SPATIAL or DOMAIN_TEMPORAL")
        )
    upper = (
        limits.MAX_TEMPORAL_FREQUENCY
        if component.domain == pb.DOMAIN_TEMPORAL
        else limits.MAX_SPATIAL_FREQUENCY
    )
    unit = "Hz" if component.domain == pb.DOMAIN_TEMPORAL else "cycles/mm"
    frequency = component.frequency
    if not _finite(frequency):
        out.append(Problem(f"{path}.frequency", f"must be finite, got {frequency}"))
    elif frequency <= 0:
        out.append(Problem(f"{path}.frequency", f"must be > 0, got {frequency}"))
    elif frequency > upper:
        out.append(
            Problem(f"{path}.frequency", f"{frequency} {unit} exceeds the limit of {upper} {unit}")
        )
    amplitude_ok = _check_amplitude_like(component.amplitude, f"{path}.amplitude", "amplitude", out)
    for name in ("phase", "orientation"):
        value = getattr(component, name)
        if not _finite(value):
            out.append(Problem(f"{path}.{name}", f"must be finite, got {value}"))
    if component.channel != pb.CHANNEL_UNSPECIFIED and component.channel not in _CHANNELS:
        out.append(Problem(f"{path}.channel", f"unknown channel {component.channel}"))
    return amplitude_ok
