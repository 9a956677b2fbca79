"""Built-in importers and exporters of other tools' formats (spec/interchange.md), registered
through the entry point ``hcard.plugins`` like a vendor's:

- ``tanvas`` and ``tpad``: grayscale bitmaps of friction (:mod:`.bitmaps`), through the
  image encoder;
- ``haps``: Interhaptics .haps texture perceptions (:mod:`.haps`);
- ``hjif``: MPEG-I haptics .hjif (ISO/IEC 23090-31) perceptions of friction, electrotactile
  and vibrotactile texture, with a glTF material for the taxtel map (:mod:`.hjif`).

The modules import nothing heavy at the top (Pillow, the renderer): listing the plugins stays
cheap; the work imports what it needs when it runs.
"""

from __future__ import annotations

from typing import Any

from hcard.plugins.hookspecs import hookimpl


@hookimpl
def hcard_importers() -> list[Any]:
    """The built-in importers."""
    from . import bitmaps, haps, hjif

    return [bitmaps.TanvasImporter(), bitmaps.TPadImporter(), haps.HapsImporter(),
            hjif.HjifImporter()]


@hookimpl
def hcard_exporters() -> list[Any]:
    """The built-in exporters."""
    from . import bitmaps, hjif

    return [bitmaps.TanvasExporter(), bitmaps.TPadExporter(), hjif.HjifExporter()]
