"""Validation of haptic cards against the rules of spec/README.md ("Validation rules").

:func:`validate` never raises for a bad card: it returns the problems it finds, each with the
field path, the reason and the rule it breaks, so that a tool can show them all at once.

The work and the report are bounded whatever the card holds (spec/README.md section 4): a card
under the 16 MiB limit may hold 8.4 million empty textures or 16.8 million out-of-range texture
indices, and listing a problem for each once cost 30-90 s and ~5 GB. Past :data:`MAX_TEXTURES`
textures or :data:`MAX_COMPONENTS_PER_TEXTURE` components the count is reported and the
excess is not examined; texture indices are checked with numpy; at most
:data:`MAX_LISTED_PROBLEMS` problems are listed and the others counted by rule.
"""

from __future__ import annotations

import math
import os
from collections import Counter

import hcard.limits as limits
from hcard.channels import VALUES
from hcard.errors import CardValidationError, Problem
from hcard.terminal_text import clipped
from hcard.v1 import card_pb2 as pb

_LOCKINGS = {pb.LOCKING_POSITION, pb.LOCKING_VELOCITY, pb.LOCKING_AUTO}
_DOMAINS = {pb.DOMAIN_SPATIAL, pb.DOMAIN_TEMPORAL}

MAX_LISTED_PROBLEMS = 100
"""Most problems :func:`validate` lists one by one; the rest are counted per rule."""


class Findings:
    """The problems of one card: the first :data:`MAX_LISTED_PROBLEMS` kept, the rest counted
    by (rule, severity)."""

    def __init__(self, limit: int = MAX_LISTED_PROBLEMS) -> None:
        self.listed: list[Problem] = []
        self.unlisted: Counter[tuple[str, str]] = Counter()
        self._limit = limit

    def add(self, path: str, reason: str, rule: str, severity: str = "error") -> None:
        """Record a problem of ``path`` breaking ``rule``."""
        if len(self.listed) < self._limit:
            self.listed.append(Problem(path, reason, severity, rule))
        else:
            self.unlisted[rule, severity] += 1

    def count(self, rule: str, severity: str, n: int) -> None:
        """Record ``n`` problems of ``rule`` that are counted, not listed."""
        if n > 0:
            self.unlisted[rule, severity] += n

    def problems(self) -> list[Problem]:
        """The listed problems, then one summary per rule of those left unlisted."""
        summaries = [
            Problem("", f"{n} more problem{'s' * (n > 1)} of rule {rule} not listed", severity,
                    rule, n)
            for (rule, severity), n in sorted(self.unlisted.items())
        ]
        return self.listed + summaries


def validate(card: pb.Card) -> list[Problem]:
    """Return the problems of ``card``; an empty list means the card is valid.

    Errors make a card invalid; warnings (``severity == "warning"``) flag content that renders
    differently from how it is written (for example a UV swing clipped at relative friction 1).
    Each problem names its rule (``Problem.rule``).
    """
    out = Findings()
    _check_version(card, out)
    _check_metadata(card, out)
    _check_surface_and_grid(card, out)
    _check_textures(card, out)
    return out.problems()


def errors_of(problems: list[Problem]) -> list[Problem]:
    """The problems of severity ``"error"``."""
    return [p for p in problems if p.severity == "error"]


def card_errors(card: pb.Card) -> list[Problem]:
    """The errors of ``card`` (:func:`validate`'s problems of severity ``"error"``); empty
    for a valid card."""
    return errors_of(validate(card))


def require_valid(card: pb.Card, *, source: str | os.PathLike[str] | None = None) -> pb.Card:
    """``card`` itself when it is valid (warnings allowed), else a
    :class:`~hcard.errors.CardValidationError` listing its errors, naming ``source`` (a file,
    ``"<stdout>"``) when given.

    The one check of a card a command makes on the host: where a card enters the command
    (:func:`hcard.card_io.load`, an encoder's result). What it hands the card to afterwards
    (the renderer, the preview, the writer) is told ``check=False``; a device still checks
    the card it is sent, as every device must.
    """
    problems = card_errors(card)
    if problems:
        raise CardValidationError(problems, source=source)
    return card


def _finite(value: float) -> bool:
    return math.isfinite(value)


def _check_version(card: pb.Card, out: Findings) -> None:
    if not card.HasField("version"):
        out.add("version", "missing: a card must state its format version", "V1")
    elif card.version.major != limits.FORMAT_MAJOR:
        out.add(
            "version.major",
            f"unsupported major version {card.version.major} "
            f"(this reader implements {limits.FORMAT_MAJOR})",
            "V1",
        )


def _check_metadata(card: pb.Card, out: Findings) -> None:
    for name in ("title", "author", "licence", "generator", "description"):
        text = getattr(card.metadata, name)
        if len(text) > limits.MAX_TEXT_LENGTH:
            out.add(
                f"metadata.{name}",
                f"{len(text)} characters, over the limit of {limits.MAX_TEXT_LENGTH}",
                "M1",
            )


def _check_length(
    value: float, path: str, upper: float, lower: float, rule: str, out: Findings
) -> bool:
    """Check a length in mm is finite and within (lower, upper]; report and return False if not."""
    if not _finite(value):
        out.add(path, f"must be a finite number of millimetres, got {value}", rule)
    elif value <= 0:
        out.add(path, f"must be > 0 mm, got {value}", rule)
    elif value < lower:
        out.add(path, f"must be at least {lower} mm, got {value}", rule)
    elif value > upper:
        out.add(path, f"must be at most {upper} mm, got {value}", rule)
    else:
        return True
    return False


def _check_surface_and_grid(card: pb.Card, out: Findings) -> None:
    surface, grid = card.surface, card.grid
    most = limits.MAX_SURFACE_MM
    width_ok = _check_length(surface.width_mm, "surface.width_mm", most, 0, "G1", out)
    height_ok = _check_length(surface.height_mm, "surface.height_mm", most, 0, "G1", out)
    smallest = limits.MIN_TAXTEL_MM
    tw_ok = _check_length(grid.taxtel_width_mm, "grid.taxtel_width_mm", most, smallest, "G2", out)
    th_ok = _check_length(grid.taxtel_height_mm, "grid.taxtel_height_mm", most, smallest, "G2",
                          out)
    dims_ok = True
    for name, count, largest in (
        ("cols", grid.cols, limits.MAX_GRID_COLS),
        ("rows", grid.rows, limits.MAX_GRID_ROWS),
    ):
        if count < 1:
            out.add(f"grid.{name}", "must be at least 1", "G3")
            dims_ok = False
        elif count > largest:
            out.add(f"grid.{name}", f"{count} exceeds the limit of {largest}", "G3")
            dims_ok = False
    if dims_ok and grid.cols * grid.rows > limits.MAX_TAXTELS:
        out.add(
            "grid",
            f"{grid.cols} x {grid.rows} = {grid.cols * grid.rows} taxtels exceeds the "
            f"limit of {limits.MAX_TAXTELS}",
            "G3",
        )
        dims_ok = False
    if dims_ok and len(grid.texture_index) != grid.cols * grid.rows:
        out.add(
            "grid.texture_index",
            f"has {len(grid.texture_index)} entries but the grid is {grid.cols} x "
            f"{grid.rows} = {grid.cols * grid.rows} taxtels",
            "G5",
        )
    if dims_ok and width_ok and tw_ok:
        _check_cover("cols", grid.cols, grid.taxtel_width_mm, surface.width_mm, out)
    if dims_ok and height_ok and th_ok:
        _check_cover("rows", grid.rows, grid.taxtel_height_mm, surface.height_mm, out)
    _check_texture_indices(grid, len(card.textures), out)


def _check_texture_indices(grid: pb.TaxtelGrid, n_textures: int, out: Findings) -> None:
    """Rule G6 for every entry, in numpy: only the entries that are listed become problems."""
    if not grid.texture_index:
        return
    import numpy as np  # here, not at import: card commands start without it (0.1-0.2 s)

    indices = np.fromiter(grid.texture_index, dtype=np.int64, count=len(grid.texture_index))
    outside = np.flatnonzero(indices >= n_textures)
    shown = outside[: MAX_LISTED_PROBLEMS]
    for i in shown.tolist():
        out.add(
            f"grid.texture_index[{i}]",
            f"texture {indices[i]} is outside the palette of {n_textures} texture(s)",
            "G6",
        )
    out.count("G6", "error", outside.size - shown.size)


def _check_cover(name: str, count: int, taxtel: float, extent: float, out: Findings) -> None:
    """The grid must cover the surface with no spare column or row (spec rule G4)."""
    tolerance = 1e-9 * max(extent, 1.0)
    covered = count * taxtel
    if covered + tolerance < extent:
        out.add(
            f"grid.{name}",
            f"{count} taxtels of {taxtel} mm cover {covered:g} mm, less than the surface "
            f"({extent:g} mm)",
            "G4",
        )
    elif (count - 1) * taxtel >= extent + tolerance:
        out.add(
            f"grid.{name}",
            f"{count} taxtels of {taxtel} mm reach {covered:g} mm: the last one lies "
            f"wholly outside the surface ({extent:g} mm)",
            "G4",
        )


def _check_textures(card: pb.Card, out: Findings) -> None:
    textures = card.textures
    if not textures:
        out.add("textures", "the palette is empty: a card needs at least one texture", "T1")
    elif len(textures) > limits.MAX_TEXTURES:
        out.add(
            "textures",
            f"{len(textures)} textures exceed the limit of {limits.MAX_TEXTURES} (those past "
            "the limit are not checked)",
            "T1",
        )
    names: dict[str, int] = {}
    for t in range(min(len(textures), limits.MAX_TEXTURES)):
        texture = textures[t]
        path = f"textures[{t}]"
        if texture.name:
            if texture.name in names:
                out.add(
                    f"{path}.name",
                    f"duplicate name {clipped(texture.name)!r} (also "
                    f"textures[{names[texture.name]}])",
                    "T2",
                )
            names.setdefault(texture.name, t)
            if len(texture.name) > limits.MAX_TEXT_LENGTH:
                out.add(f"{path}.name", "name is too long", "T2")
        _check_texture(texture, path, out)


def _check_amplitude_like(value: float, path: str, what: str, rule: str, out: Findings) -> bool:
    if not _finite(value):
        out.add(path, f"{what} must be finite, got {value}", rule)
    elif value < 0:
        out.add(path, f"{what} must be >= 0, got {value}", rule)
    elif value > limits.MAX_RELATIVE_FRICTION:
        out.add(path, f"{what} {value} exceeds the limit of {limits.MAX_RELATIVE_FRICTION}", rule)
    else:
        return True
    return False


def _check_texture(texture: pb.Texture, path: str, out: Findings) -> None:
    baseline_ok = _check_amplitude_like(
        texture.baseline, f"{path}.baseline", "baseline relative friction", "T3", out
    )
    if texture.channel not in VALUES:
        out.add(
            f"{path}.channel",
            "must be CHANNEL_UV, CHANNEL_EV or CHANNEL_BIPOLAR"
            + (" (unspecified)" if texture.channel == 0 else f" (got {texture.channel})"),
            "T4",
        )
    if texture.locking not in _LOCKINGS:
        out.add(
            f"{path}.locking",
            "must be LOCKING_POSITION, LOCKING_VELOCITY or LOCKING_AUTO"
            + (" (unspecified)" if texture.locking == 0 else f" (got {texture.locking})"),
            "T5",
        )
    if baseline_ok:
        if texture.channel == pb.CHANNEL_UV and texture.baseline > 1.0:
            out.add(f"{path}.baseline",
                    f"UV can only lower friction: baseline {texture.baseline} > 1", "T6")
        elif texture.channel == pb.CHANNEL_EV and texture.baseline < 1.0:
            out.add(f"{path}.baseline",
                    f"EV can only raise friction: baseline {texture.baseline} < 1", "T6")
    n = len(texture.components)
    if n > limits.MAX_COMPONENTS_PER_TEXTURE:
        out.add(
            f"{path}.components",
            f"{n} components exceed the limit of {limits.MAX_COMPONENTS_PER_TEXTURE} (those "
            "past the limit are not checked)",
            "T7",
        )
    swing = 0.0
    for c in range(min(n, limits.MAX_COMPONENTS_PER_TEXTURE)):
        component = texture.components[c]
        if _check_component(component, f"{path}.components[{c}]", out):
            swing += component.amplitude
    if baseline_ok and texture.channel == pb.CHANNEL_UV and texture.baseline + swing > 1.0 + 1e-12:
        out.add(
            path,
            f"UV texture can reach {texture.baseline + swing:.3g} > 1: the part above 1 is "
            "clipped when rendered",
            "W1",
            "warning",
        )
    if baseline_ok and texture.baseline - swing < 0.0:
        out.add(
            path,
            f"texture can fall to {texture.baseline - swing:.3g} < 0: the part below 0 is "
            "clipped when rendered",
            "W2",
            "warning",
        )


def _check_component(component: pb.Component, path: str, out: Findings) -> bool:
    """Check one component; return True when its amplitude is usable."""
    if component.domain not in _DOMAINS:
        out.add(f"{path}.domain", "must be DOMAIN_SPATIAL or DOMAIN_TEMPORAL", "C1")
    upper = (
        limits.MAX_TEMPORAL_FREQUENCY
        if component.domain == pb.DOMAIN_TEMPORAL
        else limits.MAX_SPATIAL_FREQUENCY
    )
    unit = "Hz" if component.domain == pb.DOMAIN_TEMPORAL else "cycles/mm"
    frequency = component.frequency
    if not _finite(frequency):
        out.add(f"{path}.frequency", f"must be finite, got {frequency}", "C2")
    elif frequency <= 0:
        out.add(f"{path}.frequency", f"must be > 0, got {frequency}", "C2")
    elif frequency > upper:
        out.add(f"{path}.frequency", f"{frequency} {unit} exceeds the limit of {upper} {unit}",
                "C2")
    amplitude_ok = _check_amplitude_like(component.amplitude, f"{path}.amplitude", "amplitude",
                                         "C3", out)
    for name in ("phase", "orientation"):
        value = getattr(component, name)
        if not _finite(value):
            out.add(f"{path}.{name}", f"must be finite, got {value}", "C4")
    if component.channel != pb.CHANNEL_UNSPECIFIED and component.channel not in VALUES:
        out.add(f"{path}.channel", f"unknown channel {component.channel}", "C5")
    return amplitude_ok
