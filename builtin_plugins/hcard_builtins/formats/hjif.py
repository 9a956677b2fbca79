"""The ``hjif`` importer and exporter: MPEG-I haptics .hjif (ISO/IEC 23090-31) perceptions of
friction, electrotactile and vibrotactile texture, with a glTF companion for the taxtel map
(spec/interchange/hjif.md).

Nothing heavy is imported here: the work (:mod:`.hjif_export`, :mod:`.hjif_import`) is
imported when a file is read or written.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hcard import limits
from hcard.errors import UsageError
from hcard.plugins.kinds import EncodeResult, ExportResult
from hcard.v1 import card_pb2 as pb

IMPORT_OPTIONS = ("width_mm", "taxtel_mm", "friction_range", "title", "author", "licence")
"""Options the importer takes (``hcard import`` names)."""


class HjifImporter:
    """Importer ``hjif``: an .hjif's Friction, Electrotactile and Vibrotactile Texture
    perceptions to a card (spec/interchange/hjif.md IJ70-IJ79)."""

    kind = "importer"
    name = "hjif"
    description = ("MPEG-I haptics .hjif (ISO/IEC 23090-31): Friction, Electrotactile and "
                   "Vibrotactile Texture perceptions, with the glTF taxtel map beside it")
    suffixes = (".hjif",)

    def recognises(self, head: bytes) -> int:
        """2 for a JSON object whose first bytes hold ``"perceptions"`` and ``"timescale"`` or
        ``"version"``, or ``"version"``, ``"profile"`` and ``"level"`` (the keys the reference
        software writes first: a long top-level ``description``, as an hcard export's
        extension, puts ``"perceptions"`` past the first 4096 bytes) (IJ70), else 0."""
        text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
        if not text.startswith(b"{"):
            return 0
        if b'"perceptions"' in head and (b'"timescale"' in head or b'"version"' in head):
            return 2
        return 2 if all(key in head for key in (b'"version"', b'"profile"', b'"level"')) else 0

    def options(self, **values: Any) -> dict[str, Any]:
        """``values`` checked (UsageError naming the option): ``width_mm`` and ``taxtel_mm``
        positive within the card limits, ``friction_range`` ``(low, high)`` with
        ``0 <= low < high <= 4``, text options at most 1024 characters."""
        unknown = sorted(set(values) - set(IMPORT_OPTIONS))
        if unknown:
            raise UsageError(f"{', '.join(unknown)}: not an option of the hjif importer "
                             f"(it takes {', '.join(IMPORT_OPTIONS)})")
        for name, low, open_low in (("width_mm", 0.0, True),
                                    ("taxtel_mm", limits.MIN_TAXTEL_MM, False)):
            value = values.get(name)
            if value is None:
                continue
            above = value > low if open_low else value >= low
            if not (math.isfinite(value) and above and value <= limits.MAX_SURFACE_MM):
                raise UsageError(f"{name} must be a number of mm in {low:g}.."
                                 f"{limits.MAX_SURFACE_MM:g}, got {value:g}")
        if values.get("friction_range") is not None:
            low, high = (float(v) for v in values["friction_range"])
            if not (math.isfinite(low) and math.isfinite(high)
                    and 0.0 <= low < high <= limits.MAX_RELATIVE_FRICTION):
                raise UsageError(f"friction_range must satisfy 0 <= LO < HI <= "
                                 f"{limits.MAX_RELATIVE_FRICTION:g}, got {low:g} {high:g}")
            values["friction_range"] = (low, high)
        for name in ("title", "author", "licence"):
            text = values.get(name)
            if text is not None and len(text) > limits.MAX_TEXT_LENGTH:
                raise UsageError(f"{name} is longer than {limits.MAX_TEXT_LENGTH} characters")
        return {name: values.get(name) for name in IMPORT_OPTIONS}

    def read(self, source: Path, *, progress: Callable[[str], None] | None = None,
             **options: Any) -> EncodeResult:
        """The card of ``source``; AssetError (file, JSON path, reason) on a bad file."""
        from .hjif_import import ImportOptions, import_file

        return import_file(Path(source), ImportOptions(**self.options(**options)))


class HjifExporter:
    """Exporter ``hjif``: a card as an .hjif and, for more than one taxtel, a glTF companion
    with the taxtel map (spec/interchange/hjif.md IJ1-IJ56)."""

    kind = "exporter"
    name = "hjif"
    description = ("MPEG-I haptics .hjif (ISO/IEC 23090-31): Friction/Electrotactile "
                   "perceptions of sine gratings, glTF MPEG_haptic_material taxtel map")
    suffix = ".hjif"

    def options(self, **values: Any) -> dict[str, Any]:
        """No options: any is a UsageError naming it."""
        if values:
            raise UsageError(f"{', '.join(sorted(values))}: not an option of the hjif "
                             "exporter (it takes none)")
        return {}

    def write(self, card: pb.Card, *, progress: Callable[[str], None] | None = None,
              **options: Any) -> ExportResult:
        """The .hjif (and glTF) of ``card``, its losses and figures."""
        from .hjif_export import export_bytes

        self.options(**options)
        return export_bytes(card)
