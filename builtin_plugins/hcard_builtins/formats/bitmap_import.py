"""A Tanvas or TPad bitmap to a card (spec/interchange/bitmaps.md IB1-IB7, IB13).

A PNG whose ``hcard`` chunk carries a card and whose pixels are still those the chunk was
written with gives that card (IB13); any other goes through the image encoder in the format's
polarity and channel. Either way the fidelity in JND is of the card against the pixels' own
friction, the card evaluated position-locked at the pixel centres.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hcard import limits
from hcard.plugins.kinds import EncodeResult
from hcard_builtins.image.encoder import EncodeOptions, encode_image
from hcard_builtins.image.loading import load_gray

from .bitmap_raster import friction_rows, plan_raster
from .bitmaps import BitmapFormat
from .hcard_chunk import Extension, parse_extension, pixels_digest
from .png_chunks import PngFacts, read_png_facts

SHAPING_OPTIONS = ("width_mm", "height_mm", "dpi", "taxtel_mm", "max_error")
"""Options that shape an encoding: an embedded card ignores them (IB13)."""


def read_bitmap(fmt: BitmapFormat, source: Path, *,
                progress: Callable[[str], None] | None = None, **options: Any) -> EncodeResult:
    """The card of the bitmap ``source``; ``options`` are the importer's, checked.

    Raises:
        AssetError: not a PNG, a PNG broken before its pixels, or a bad ``hcard`` chunk.
        ImageError: the pixels cannot be decoded or exceed the limits (the image encoder's).
    """
    facts = read_png_facts(source)
    notes: list[str] = []
    if facts.hcard is not None and options["embedded"]:
        extension = parse_extension(facts.hcard, source, facts.field)
        _check_matches(fmt, extension, source, facts)
        result = embedded_result(fmt, source, facts, extension, options)
        if result is not None:
            return result
        notes.append(f"the pixels differ from those its {facts.field} was written with "
                     "(edited after the export): the card is encoded from the pixels")
    return encoded_result(fmt, source, facts, options, progress, notes)


def _check_matches(fmt: BitmapFormat, extension: Extension, source: Path,
                   facts: PngFacts) -> None:
    from hcard.errors import AssetError

    if extension.format != fmt.name or extension.channel != fmt.channel:
        raise AssetError(
            f"the chunk says format {extension.format} (channel {extension.channel}); read as "
            f"{fmt.name} (channel {fmt.channel}) its pixels would mean other friction: import "
            f"it with --from {extension.format}", source=source, field=f"{facts.field} format")


def encoded_result(fmt: BitmapFormat, source: Path, facts: PngFacts, options: dict[str, Any],
                   progress: Callable[[str], None] | None, notes: list[str]) -> EncodeResult:
    """The card the image encoder makes of the pixels in the format's polarity (IB1-IB7)."""
    sized = any(options[name] is not None for name in ("width_mm", "height_mm", "dpi"))
    assumed = not sized and (facts.dpi is None or fmt.pixel_is_screen_pixel)
    encode = EncodeOptions(
        width_mm=options["width_mm"], height_mm=options["height_mm"],
        dpi=fmt.default_dpi if assumed else options["dpi"], taxtel_mm=options["taxtel_mm"],
        max_error=options["max_error"], channel=fmt.channel,
        friction_range=options["friction_range"], white_is=fmt.white_is,
        transparent="black", max_pixels=options["max_pixels"], title=options["title"],
        author=options["author"], licence=options["licence"])
    result = encode_image(source, encode, progress=progress)
    if assumed:
        result.stats["size_source"] = (
            f"assumed {fmt.default_dpi:g} dpi, the {fmt.label} default ({fmt.dpi_reason}): "
            + ("no size given; a Tanvas bitmap pixel is a screen pixel, whatever the PNG's "
               "pHYs says" if fmt.pixel_is_screen_pixel else
               "no size given and no pHYs in the PNG"))
    black, white = fmt.gray_ends(options["friction_range"])
    result.stats.update({
        "format_detail": (f"{fmt.label} bitmap, gray 0 = relative friction {black:g}, "
                          f"255 = {white:g} (channel {fmt.channel}), transparent = gray 0; "
                          f"{result.stats['size_source']}"),
        "fidelity_basis": "the card evaluated position-locked at the pixel centres against "
                          "the pixels' friction (the image encoder's reconstruction error)",
        "embedded_card": False,
    })
    result.log[:0] = notes
    return result


def embedded_result(fmt: BitmapFormat, source: Path, facts: PngFacts, extension: Extension,
                    options: dict[str, Any]) -> EncodeResult | None:
    """The embedded card with its fidelity to the pixels, or ``None`` when the pixels are not
    those the chunk was written with (IB13)."""
    image = load_gray(source, max_pixels=options["max_pixels"], transparent="black")
    if image.pixels.dtype != np.uint8 or pixels_digest(
            np.ascontiguousarray(image.pixels)) != extension.pixels_sha256:
        return None
    card = extension.card
    for name in ("title", "author", "licence"):
        if options[name]:  # given: the encoder's defaults are None and ""
            setattr(card.metadata, name, options[name])
    black, white = fmt.gray_ends(extension.friction_range)
    per_level = (white - black) / 255.0
    squares, largest = 0.0, 0.0
    plan = plan_raster(card, image.width, image.height)
    for top, friction in friction_rows(card, plan):
        rows = image.pixels[top:top + friction.shape[0]].astype(np.float64)
        error = black + per_level * rows - friction
        squares += float(np.dot(error.ravel(), error.ravel()))
        largest = max(largest, float(np.abs(error).max(initial=0.0)))
    jnd = limits.RELATIVE_FRICTION_JND
    rms = math.sqrt(squares / (image.width * image.height))
    defaults = EncodeOptions()
    ignored = [name for name in SHAPING_OPTIONS if options[name] != getattr(defaults, name)]
    if options["friction_range"] != fmt.friction_range:
        ignored.append("friction_range")
    log = [f"the card is the one embedded in its {facts.field} (IB13)"]
    if ignored:
        log.append(f"ignored {', '.join(ignored)}: the embedded card is used as it is")
    stats = {
        "format_detail": (f"{fmt.label} bitmap {image.width} x {image.height} px exported by "
                          f"hcard: gray 0 = relative friction {black:g}, 255 = {white:g} "
                          f"(channel {fmt.channel}), card embedded in its {facts.field}"),
        "fidelity_basis": "the embedded card evaluated position-locked at the pixel centres "
                          "against the pixels' friction",
        "embedded_card": True,
        "width_px": image.width, "height_px": image.height,
        "friction_range": extension.friction_range,
        "rms_error": rms, "max_error": largest,
        "rms_error_jnd": rms / jnd, "max_error_jnd": largest / jnd,
    }
    return EncodeResult(card=card, stats=stats, log=log)
