"""The ``haps`` importer: an Interhaptics .haps texture perception to a card
(spec/interchange/haps.md).

A .haps file (JSON, ``m_version`` "5") holds up to three perceptions; the texture one
(``m_texture``) is a sum of notes whose amplitude and frequency are keyframed over a position
axis. It becomes a card whose taxtels run along x, each playing the notes under it as
position-locked gratings. The length unit of that axis is not documented: ``length_unit_mm``
says how many millimetres it is (default :data:`DEFAULT_LENGTH_UNIT_MM`, IH3).

This module imports nothing heavy at the top: numpy and the renderer come with :meth:`read`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from hcard import limits
from hcard.errors import UsageError
from hcard.plugins.kinds import EncodeResult

if TYPE_CHECKING:
    from .haps_card import Layout
    from .haps_parse import HapsTexture

DEFAULT_LENGTH_UNIT_MM = 100.0
"""Millimetres per .haps length unit when ``length_unit_mm`` is not given (IH3: the one public
texture sample, 1.017 units with a carrier of 181 cycles per unit, becomes a 102 mm swipe with
0.55 mm grain and ridges every 10 mm)."""
DEFAULT_FRICTION_RANGE = (0.3, 1.0)
"""The device's friction range when not given: ultrasonic (UV), as the image encoder's
default for ``uv`` (IH9)."""
MAX_DEFAULT_TAXTELS = limits.MAX_TEXTURES
"""The default taxtel is the width over this, so that every taxtel can have its own texture."""
OPTIONS = ("width_mm", "height_mm", "length_unit_mm", "taxtel_mm", "friction_range", "title",
           "author", "licence")
"""The options this importer takes (IH14)."""
_HEAD_KEYS = (b'"m_texture"', b'"m_length_unit"', b'"m_HDFlag"', b'"m_vibration"',
              b'"m_stiffness"')


class HapsImporter:
    """Interhaptics .haps (v5) texture perception to a card (spec/interchange/haps.md)."""

    kind: ClassVar[str] = "importer"
    name: ClassVar[str] = "haps"
    description: ClassVar[str] = ("Interhaptics .haps texture perception (Haptic Composer, "
                                  "v5 JSON) to a row of position-locked gratings")
    suffixes: ClassVar[tuple[str, ...]] = (".haps",)

    def recognises(self, head: bytes) -> int:
        """2 for a JSON object whose first bytes hold a key only .haps uses, else 0 (IH1)."""
        text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
        if not text.startswith(b"{"):
            return 0
        return 2 if any(key in text for key in _HEAD_KEYS) else 0

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` checked, defaults left to :meth:`read` (they depend on the file)."""
        unknown = sorted(set(values) - set(OPTIONS))
        if unknown:
            raise UsageError(f"{unknown[0]} does not apply to .haps import (it takes "
                             f"{', '.join(OPTIONS)})")
        checked = dict(values)
        for key in ("width_mm", "height_mm", "taxtel_mm", "length_unit_mm"):
            if checked.get(key) is not None:
                checked[key] = _positive(key, checked[key])
        if checked.get("taxtel_mm") is not None and checked["taxtel_mm"] < limits.MIN_TAXTEL_MM:
            raise UsageError(f"taxtel_mm {checked['taxtel_mm']:g} is below the card's smallest "
                             f"taxtel, {limits.MIN_TAXTEL_MM:g} mm")
        for key in ("width_mm", "height_mm"):
            if checked.get(key) is not None and checked[key] > limits.MAX_SURFACE_MM:
                raise UsageError(f"{key} {checked[key]:g} is above the card's largest surface "
                                 f"side, {limits.MAX_SURFACE_MM:g} mm")
        if checked.get("friction_range") is not None:
            checked["friction_range"] = _friction_range(checked["friction_range"])
        for key in ("title", "author", "licence"):
            if checked.get(key) is not None and not isinstance(checked[key], str):
                raise UsageError(f"{key} must be text")
        return checked

    def read(self, source: Path, *, progress: Callable[[str], None] | None = None,
             **options: Any) -> EncodeResult:
        """The card of the .haps file ``source`` and its fidelity (IH1-IH14)."""
        from .haps_card import FrictionMapping, build_card
        from .haps_fidelity import fidelity
        from .haps_parse import read_haps

        options = self.options(**options)
        texture = read_haps(Path(source))
        unit = options.get("length_unit_mm") or DEFAULT_LENGTH_UNIT_MM
        layout = _layout(texture.extent, unit, options, str(source))
        low, high = options.get("friction_range") or DEFAULT_FRICTION_RANGE
        mapping = FrictionMapping(low, high)
        if progress is not None:
            progress(f"{len(texture.notes)} texture notes over {texture.extent:g} units, "
                     f"{layout.cols} taxtels of {layout.taxtel_mm:.4g} mm")
        title = options.get("title") or texture.name or Path(source).stem
        card, log = build_card(texture, layout, mapping, title=title,
                               author=options.get("author") or "",
                               licence=options.get("licence") or "", source=str(source))
        stats: dict[str, Any] = {
            "format_detail": _detail(texture, unit, options),
            "length_unit_mm": unit,
            "width_mm": layout.width_mm,
            "taxtel_mm": layout.taxtel_mm,
            "friction_range": (low, high),
            "channel": mapping.channel,
            "notes": len(texture.notes),
        }
        stats.update(fidelity(card, texture, length_unit_mm=unit, low=low, high=high))
        return EncodeResult(card=card, stats=stats, log=_notes(texture, layout, unit) + log)


def _positive(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
            math.isfinite(value) and value > 0):
        raise UsageError(f"{key} must be a finite number > 0, got {value!r}")
    return float(value)


def _friction_range(value: Any) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise UsageError(f"friction_range must be two numbers LO HI, got {value!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low < high
            <= limits.MAX_RELATIVE_FRICTION):
        raise UsageError(f"friction_range {low:g} {high:g} must satisfy 0 <= LO < HI <= "
                         f"{limits.MAX_RELATIVE_FRICTION:g}")
    return low, high


def _layout(extent: float, unit: float, options: dict[str, Any], source: str) -> Layout:
    """The card's geometry from the options and the texture's extent (IH7)."""
    from hcard.errors import AssetError

    from .haps_card import Layout

    width = options.get("width_mm") or extent * unit
    if not (math.isfinite(width) and width <= limits.MAX_SURFACE_MM):
        raise AssetError(
            f"the texture's {extent:g} units at {unit:g} mm per unit make {width:g} mm, above "
            f"the card's largest surface side, {limits.MAX_SURFACE_MM:g} mm; give a smaller "
            f"length_unit_mm or width_mm", source=source, field="m_texture")
    height = options.get("height_mm") or width
    taxtel = options.get("taxtel_mm") or max(limits.MIN_TAXTEL_MM, width / MAX_DEFAULT_TAXTELS)
    if _columns(width, taxtel) > limits.MAX_GRID_COLS:
        raise UsageError(f"taxtel_mm {taxtel:g} over {width:g} mm makes more than "
                         f"{limits.MAX_GRID_COLS} taxtel columns; give a larger taxtel_mm")
    return Layout(width, height, taxtel, unit)


def _columns(width: float, taxtel: float) -> int:
    """Taxtel columns over ``width`` mm."""
    from hcard import build

    return build.grid_count(width, taxtel)


def _detail(texture: HapsTexture, unit: float, options: dict[str, Any]) -> str:
    """The one-line ``format_detail``."""
    given = "given" if options.get("length_unit_mm") else "default"
    return (f"Interhaptics .haps v{texture.version or '?'}, texture perception: "
            f"{len(texture.notes)} notes in {texture.melodies} melodies over "
            f"{texture.extent:.6g} length units; m_length_unit {texture.length_unit_code} "
            f"taken as {unit:g} mm ({given})")


def _notes(texture: HapsTexture, layout: Layout, unit: float) -> list[str]:
    """What the card leaves out of the file (IH2, IH6, IH12)."""
    lines = [f"{key}: {count} notes not imported (only the texture perception maps to "
             f"friction)" for key, count in texture.others.items() if count]
    lines += [f"skipped {what}" for what in texture.notes_skipped[:5]]
    if len(texture.notes_skipped) > 5:
        lines.append(f"skipped {len(texture.notes_skipped) - 5} more notes")
    lines += [f"ignored {what}" for what in texture.ignored]
    extent_mm = texture.extent * unit
    if layout.width_mm < extent_mm - 1e-9:
        lines.append(f"the texture's {extent_mm:g} mm cut at the card's width, "
                     f"{layout.width_mm:g} mm")
    return lines
