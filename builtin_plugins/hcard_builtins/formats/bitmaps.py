"""Tanvas and TPad friction bitmaps: importers and exporters (spec/interchange/bitmaps.md).

Both formats are grayscale PNGs of friction, sampled one bitmap pixel per screen pixel (TPad's
library stretches the bitmap over its view). They differ in polarity and channel (IB1, IB2):

- **tanvas** (TanvasTouch, electroadhesion, channel EV): gray 0 is the surface's natural
  friction, 255 the most friction the device adds; default range 1.0 .. 1.6.
- **tpad** (TPad, ultrasonic, channel UV): the brightness 0..1 is the ultrasonic drive, 1 the
  slipperiest; default range 0.3 .. 1.0 (gray 0 = 1.0, gray 255 = 0.3).

Import goes through the image encoder (:func:`hcard_builtins.image.encode_image`) in the
format's polarity (``white_is``) with transparent pixels showing gray 0, the format's zero drive
(``transparent="black"``). Export draws the card position-locked at the pixel centres
(:mod:`.bitmap_raster`) and embeds the card in an iTXt chunk ``hcard`` (:mod:`.hcard_chunk`),
so that importing the export gives the card back.

This module imports nothing heavy: the work is in :mod:`.bitmap_import` and
:mod:`.bitmap_export`, imported when it runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from hcard.errors import UsageError
from hcard.plugins.kinds import EncodeResult, ExportResult
from hcard.v1 import card_pb2 as pb

from .png_chunks import is_png, sniff_hcard_format

DEFAULT_PX_PER_MM = 10.0
"""Default resolution of an export, pixels per millimetre (0.1 mm pixels, the image encoder's
default 254 dpi): finer than a fingertip resolves, and every card grating up to 5 cycles/mm
below the pixel Nyquist limit."""
MAX_PX_PER_MM = 1000.0
"""Finest export, pixels per millimetre (the image encoder's finest, 25,400 dpi)."""


@dataclass(frozen=True)
class BitmapFormat:
    """One bitmap format: its polarity, channel and defaults (spec/interchange/bitmaps.md).

    Attributes:
        name: the plugin name (``"tanvas"``).
        label: the name for people (``"Tanvas"``).
        channel: the card channel its friction is (``"ev"``, ``"uv"``).
        white_is: ``"high"`` when gray 255 is the high end of the friction range (Tanvas),
            ``"low"`` when it is the low end (TPad, and the image encoder's own convention).
        friction_range: default relative friction of the range's low and high ends.
        default_dpi: screen resolution assumed when neither the options nor the PNG give a
            size, dots per inch.
        dpi_reason: why that resolution, for the summary.
        pixel_is_screen_pixel: the format's runtime draws one bitmap pixel per screen pixel
            (Tanvas), so the screen's resolution sizes the surface and a PNG's stated
            resolution (pHYs: an authoring tool's setting, 72 dpi from Photoshop) does not;
            False when the runtime stretches the bitmap (TPad) and pHYs is the best guess.
    """

    name: str
    label: str
    channel: str
    white_is: str
    friction_range: tuple[float, float]
    default_dpi: float
    dpi_reason: str
    pixel_is_screen_pixel: bool = False

    def gray_ends(self, friction_range: tuple[float, float]) -> tuple[float, float]:
        """Relative friction of gray 0 and of gray 255 for ``friction_range`` (IB3)."""
        low, high = friction_range
        return (low, high) if self.white_is == "high" else (high, low)


TANVAS = BitmapFormat(
    name="tanvas", label="Tanvas", channel="ev", white_is="high",
    friction_range=(1.0, 1.6), default_dpi=149.4,
    dpi_reason="the Mimo Vue HD TanvasTouch screen, 10.1 in at 1280 x 800 pixels",
    pixel_is_screen_pixel=True,
)
TPAD = BitmapFormat(
    name="tpad", label="TPad", channel="uv", white_is="low",
    friction_range=(0.3, 1.0), default_dpi=254.0,
    dpi_reason="TPad stretches a bitmap over its view, so the format implies no screen "
    "resolution: hcard's own 0.1 mm pixels",
)
FORMATS: dict[str, BitmapFormat] = {TANVAS.name: TANVAS, TPAD.name: TPAD}

IMPORT_OPTIONS = ("width_mm", "height_mm", "dpi", "taxtel_mm", "friction_range", "max_error",
                  "title", "author", "licence", "max_pixels", "embedded")
"""Options of the bitmap importers: the image encoder's that apply, and ``embedded`` (use the
card of an ``hcard`` chunk, default True)."""
EXPORT_OPTIONS = ("px_per_mm", "friction_range")


def _unknown(values: dict[str, Any], known: tuple[str, ...], what: str) -> None:
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise UsageError(f"{', '.join(unknown)}: not an option of the {what} (its options: "
                         f"{', '.join(known)})")


def check_range(fmt: BitmapFormat, friction_range: Any) -> tuple[float, float]:
    """``friction_range`` as two floats ``(low, high)`` valid for the format's channel (the
    image encoder's rule: UV at most 1, EV at least 1); UsageError naming ``friction_range``."""
    try:
        low, high = (float(v) for v in friction_range)
    except (TypeError, ValueError):
        raise UsageError(f"friction_range must be two numbers LO HI, got {friction_range!r}"
                         ) from None
    from hcard_builtins.image.encoder import EncodeOptions

    try:
        EncodeOptions(channel=fmt.channel, friction_range=(low, high)).checked()
    except ValueError as exc:
        raise UsageError(f"friction_range: {exc} ({fmt.label} bitmaps are channel "
                         f"{fmt.channel})") from None
    return low, high


class BitmapImporter:
    """Importer of one bitmap format (kind ``importer``): see :mod:`.bitmap_import`."""

    kind: ClassVar[str] = "importer"
    format: ClassVar[BitmapFormat]
    suffixes: ClassVar[tuple[str, ...]] = (".png",)

    @property
    def name(self) -> str:
        """The format's name."""
        return self.format.name

    @property
    def description(self) -> str:
        """One line."""
        _low, _high = self.format.friction_range
        black, white = self.format.gray_ends(self.format.friction_range)
        return (f"{self.format.label} friction bitmap (PNG, channel {self.format.channel}, "
                f"gray 0 = {black:g}, 255 = {white:g} by default) to card, through the image "
                "encoder")

    def recognises(self, head: bytes) -> int:
        """2 when ``head`` is a PNG whose ``hcard`` chunk names this format (IB12), 1 for any
        other PNG (Tanvas and TPad share the container), else 0."""
        if not is_png(head):
            return 0
        return 2 if sniff_hcard_format(head) == self.format.name else 1

    def options(self, **values: Any) -> dict[str, Any]:
        """The options checked with the defaults filled in (IB5, IB6); UsageError naming a bad
        or unknown one."""
        _unknown(values, IMPORT_OPTIONS, f"{self.format.name} importer")
        from hcard_builtins.image.encoder import EncodeOptions

        friction_range = check_range(self.format, values.get("friction_range")
                                     or self.format.friction_range)
        embedded = values.get("embedded", True)
        if not isinstance(embedded, bool):
            raise UsageError(f"embedded must be true or false, got {embedded!r}")
        given = {name: values[name] for name in IMPORT_OPTIONS[:-1] if name in values}
        given["friction_range"] = friction_range
        try:
            checked = EncodeOptions(channel=self.format.channel, **given).checked()
        except (TypeError, ValueError) as exc:
            raise UsageError(str(exc)) from None
        out = {name: getattr(checked, name) for name in IMPORT_OPTIONS[:-1]}
        out["embedded"] = embedded
        return out

    def read(self, source: Path, *, progress: Callable[[str], None] | None = None,
             **options: Any) -> EncodeResult:
        """The card of the bitmap ``source`` (:func:`.bitmap_import.read_bitmap`)."""
        from .bitmap_import import read_bitmap

        return read_bitmap(self.format, Path(source), progress=progress,
                           **self.options(**options))


class BitmapExporter:
    """Exporter of one bitmap format (kind ``exporter``): see :mod:`.bitmap_export`."""

    kind: ClassVar[str] = "exporter"
    format: ClassVar[BitmapFormat]
    suffix: ClassVar[str] = ".png"

    @property
    def name(self) -> str:
        """The format's name."""
        return self.format.name

    @property
    def description(self) -> str:
        """One line."""
        return (f"card to a {self.format.label} friction bitmap (8-bit gray PNG, channel "
                f"{self.format.channel}), the card kept in its iTXt chunk hcard")

    def options(self, **values: Any) -> dict[str, Any]:
        """``px_per_mm`` (default :data:`DEFAULT_PX_PER_MM`) and ``friction_range`` (default
        ``None``: the range the card states, else the format's, IB9) checked."""
        _unknown(values, EXPORT_OPTIONS, f"{self.format.name} exporter")
        px_per_mm = values.get("px_per_mm", DEFAULT_PX_PER_MM)
        if isinstance(px_per_mm, bool) or not isinstance(px_per_mm, int | float) or not (
                math.isfinite(px_per_mm) and 0 < px_per_mm <= MAX_PX_PER_MM):
            raise UsageError(f"px_per_mm must be a number above 0 and at most "
                             f"{MAX_PX_PER_MM:g}, got {px_per_mm!r}")
        friction_range = values.get("friction_range")
        if friction_range is not None:
            friction_range = check_range(self.format, friction_range)
        return {"px_per_mm": float(px_per_mm), "friction_range": friction_range}

    def write(self, card: pb.Card, *, progress: Callable[[str], None] | None = None,
              **options: Any) -> ExportResult:
        """The PNG of ``card`` and what it cannot hold (:func:`.bitmap_export.write_bitmap`)."""
        from .bitmap_export import write_bitmap

        return write_bitmap(self.format, card, **self.options(**options))


class TanvasImporter(BitmapImporter):
    """``tanvas``: a TanvasTouch haptic PNG (white = most friction, EV) to a card."""

    format = TANVAS


class TPadImporter(BitmapImporter):
    """``tpad``: a TPad friction bitmap (white = slipperiest, UV) to a card."""

    format = TPAD


class TanvasExporter(BitmapExporter):
    """``tanvas``: a card to a TanvasTouch haptic PNG."""

    format = TANVAS


class TPadExporter(BitmapExporter):
    """``tpad``: a card to a TPad friction bitmap."""

    format = TPAD
