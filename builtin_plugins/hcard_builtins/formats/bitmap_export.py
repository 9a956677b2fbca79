"""A card to a Tanvas or TPad bitmap: the card's friction drawn position-locked at the pixel
centres, mapped linearly to 8-bit gray in the format's polarity, clipped to the range, written
as a PNG with the card in its ``hcard`` chunk (spec/interchange/bitmaps.md IB8-IB12, IB15).
"""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass

import numpy as np

from hcard import limits
from hcard.bounded_read import DEFAULT_MAX_PIXELS
from hcard.channels import LABEL_OF_VALUE, VALUE_OF_NAME
from hcard.errors import UsageError
from hcard.plugins.kinds import ExportResult, Loss
from hcard.v1 import card_pb2 as pb

from .bitmap_raster import RasterPlan, friction_rows, plan_raster
from .bitmaps import BitmapFormat, check_range
from .hcard_chunk import Extension, extension_text, pixels_digest
from .png_chunks import HCARD_KEYWORD, chunk_field

CARRIED = chunk_field("iTXt")
"""Where an export keeps what the pixels cannot hold (:attr:`Loss.carried`)."""
MM_PER_INCH = 25.4
_STATED_RANGE = re.compile(
    r"\b(black|white) = relative friction ([0-9.]+), (white|black) = ([0-9.]+), "
    r"channel (uv|ev|bipolar)\b")
"""The range a card states it was made for, as the image encoder (and so a bitmap import)
writes it in the description: ``white = relative friction 1.6, black = 1, channel ev``."""


@dataclass
class GrayFigures:
    """What drawing the card at 8 bits did: errors of the written pixels against the card's
    friction (relative friction) and the pixels clipped at each end of the range."""

    squares: float = 0.0
    largest: float = 0.0
    pixels: int = 0
    clipped_low: int = 0
    clipped_high: int = 0
    lowest: float = math.inf
    highest: float = -math.inf


def write_bitmap(fmt: BitmapFormat, card: pb.Card, *, px_per_mm: float,
                 friction_range: tuple[float, float] | None) -> ExportResult:
    """The PNG of ``card`` in format ``fmt`` at ``px_per_mm``, its losses and figures.

    Raises:
        UsageError: the surface at ``px_per_mm`` takes more than the pixel limit.
    """
    width_px, height_px = pixel_size(card, px_per_mm)
    friction_range, range_source = chosen_range(fmt, card, friction_range)
    plan = plan_raster(card, width_px, height_px)
    gray, figures = draw(fmt, card, plan, friction_range)
    extension = Extension(fmt.name, fmt.channel, friction_range, px_per_mm,
                          pixels_digest(gray), card)
    data = png_bytes(gray, plan, extension_text(extension))
    jnd = limits.RELATIVE_FRICTION_JND
    rms = math.sqrt(figures.squares / max(figures.pixels, 1))
    black, white = fmt.gray_ends(friction_range)
    stats = {
        "width_px": width_px, "height_px": height_px,
        "px_per_mm": (plan.geometry.ppx, plan.geometry.ppy),
        "friction_range": friction_range, "range_source": range_source,
        "gray_0": black, "gray_255": white, "channel": fmt.channel,
        "card_friction_min": figures.lowest, "card_friction_max": figures.highest,
        "clipped_pixels": figures.clipped_low + figures.clipped_high,
        "rms_error": rms, "max_error": figures.largest,
        "rms_error_jnd": rms / jnd, "max_error_jnd": figures.largest / jnd,
        "fidelity_basis": "the 8-bit pixels as written against the card's friction at the "
                          "pixel centres, position-locked (quantisation and clipping)",
    }
    return ExportResult(files=[("", data)], losses=losses(fmt, card, plan, figures,
                                                          friction_range), stats=stats)


def pixel_size(card: pb.Card, px_per_mm: float) -> tuple[int, int]:
    """Pixels across and down: the surface at ``px_per_mm``, rounded, at least 1 (IB10)."""
    width = max(1, round(card.surface.width_mm * px_per_mm))
    height = max(1, round(card.surface.height_mm * px_per_mm))
    if width * height > DEFAULT_MAX_PIXELS:
        raise UsageError(
            f"px_per_mm: {card.surface.width_mm:g} x {card.surface.height_mm:g} mm at "
            f"{px_per_mm:g} px/mm is {width} x {height} = {width * height} pixels, over the "
            f"limit of {DEFAULT_MAX_PIXELS} (an importer's default); lower px_per_mm")
    return width, height


def chosen_range(fmt: BitmapFormat, card: pb.Card, given: tuple[float, float] | None
                 ) -> tuple[tuple[float, float], str]:
    """The friction range of the export and where it came from (IB9): the option, else the
    range the card's description states for this format's channel, else the format's."""
    if given is not None:
        return given, "the friction_range option"
    match = _STATED_RANGE.search(card.metadata.description)
    if match is not None and match.group(5) == fmt.channel:
        ends = {match.group(1): float(match.group(2)), match.group(3): float(match.group(4))}
        if set(ends) == {"black", "white"}:
            stated = (min(ends.values()), max(ends.values()))
            try:
                return check_range(fmt, stated), "the range the card's description states"
            except UsageError:
                pass
    return fmt.friction_range, f"the {fmt.label} default"


def draw(fmt: BitmapFormat, card: pb.Card, plan: RasterPlan,
         friction_range: tuple[float, float]) -> tuple[np.ndarray, GrayFigures]:
    """The 8-bit gray pixels of the card (IB8) and the figures of drawing them."""
    black, white = fmt.gray_ends(friction_range)
    per_level = (white - black) / 255.0
    geometry = plan.geometry
    gray = np.empty((geometry.height_px, geometry.width_px), dtype=np.uint8)
    figures = GrayFigures()
    for top, friction in friction_rows(card, plan):
        level = np.rint((friction - black) / per_level)
        figures.clipped_low += int(np.count_nonzero(level < 0))
        figures.clipped_high += int(np.count_nonzero(level > 255))
        block = np.clip(level, 0, 255)
        gray[top:top + friction.shape[0]] = block
        error = black + per_level * block - friction
        figures.squares += float(np.dot(error.ravel(), error.ravel()))
        figures.largest = max(figures.largest, float(np.abs(error).max(initial=0.0)))
        figures.pixels += error.size
        figures.lowest = min(figures.lowest, float(friction.min()))
        figures.highest = max(figures.highest, float(friction.max()))
    return gray, figures


def png_bytes(gray: np.ndarray, plan: RasterPlan, chunk: str) -> bytes:
    """An 8-bit gray PNG of ``gray`` stating its resolution (pHYs) with the ``hcard`` iTXt
    chunk, uncompressed, before the image data (IB11)."""
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    info = PngInfo()
    info.add_itxt(HCARD_KEYWORD.decode("ascii"), chunk, zip=False)
    out = io.BytesIO()
    dpi = (plan.geometry.ppx * MM_PER_INCH, plan.geometry.ppy * MM_PER_INCH)
    Image.fromarray(gray, mode="L").save(out, format="PNG", pnginfo=info, dpi=dpi,
                                         optimize=False)
    return out.getvalue()


def losses(fmt: BitmapFormat, card: pb.Card, plan: RasterPlan, figures: GrayFigures,
           friction_range: tuple[float, float]) -> list[Loss]:
    """What the bitmap cannot hold of ``card`` (IB15), each kept in the ``hcard`` chunk."""
    found: list[Loss] = []
    own = VALUE_OF_NAME[fmt.channel]
    others = sorted({LABEL_OF_VALUE[t.channel] for t in card.textures if t.channel != own}
                    | {LABEL_OF_VALUE[c.channel] for t in card.textures for c in t.components
                       if c.channel not in (pb.CHANNEL_UNSPECIFIED, own)})
    if others:
        found.append(Loss("channel", (
            f"a {fmt.label} bitmap is {fmt.channel.upper()} friction only; the card's "
            f"{'/'.join(others)} friction is drawn on the same gray scale, clipped to "
            f"{friction_range[0]:g} .. {friction_range[1]:g}"), CARRIED))
    if plan.velocity_locked:
        found.append(Loss("locking", (
            f"{plan.velocity_locked} velocity-locked component(s) (rule R8) drawn "
            "position-locked, phase at the surface origin"), CARRIED))
    spatial = sum(c.domain == pb.DOMAIN_SPATIAL for t in card.textures for c in t.components)
    if spatial:
        for name in ("orientation", "phase"):
            found.append(Loss(name, (
                f"the {name}s of {spatial} grating(s) are kept only as the picture draws them "
                "(a re-encoding estimates them from the pixels)"), CARRIED))
    black, white = fmt.gray_ends(friction_range)
    found.append(Loss("friction-scale", (
        f"relative friction becomes gray levels: gray 0 = {black:g}, 255 = {white:g} "
        f"({abs(white - black) / 255:.4f} a level); "
        f"the card spans {figures.lowest:.3f} .. {figures.highest:.3f}, "
        f"{figures.clipped_low + figures.clipped_high} pixel(s) clipped"), CARRIED))
    found.append(Loss("taxtel-map", (
        f"the {card.grid.cols} x {card.grid.rows} taxtel grid and its {len(card.textures)} "
        "palette texture(s) become pixels"), CARRIED))
    if plan.temporal or plan.aliased:
        found.append(Loss("components", (
            f"{plan.temporal} temporal component(s) and {plan.aliased} grating(s) at or "
            f"beyond the pixels' Nyquist limit ({plan.geometry.ppx / 2:g} cycles/mm) are not "
            "drawn"), CARRIED))
    found.append(Loss("metadata", "title, author, licence and description are not part of "
                                  f"a {fmt.label} bitmap", CARRIED))
    return found
