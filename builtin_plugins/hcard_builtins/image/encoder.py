"""The image encoder: a grayscale picture of friction to a haptic card.

Black is high friction and white low (thesis section 5.4.2). The image covers the surface; the
surface is cut into square taxtels; every taxtel's friction is analysed into a baseline plus up
to ``components`` gratings (frequency, orientation, amplitude, phase); similar taxtels share a
palette texture. Gratings longer than a taxtel cannot be resolved inside it and show up as
baseline steps between taxtels (the hybrid position/texture representation of chapter 5).

With an error target (``max_error``, in JND) the encoder checks every taxtel against its
pixels and, where the 95th percentile of the absolute error exceeds the target, adds the
residual's strongest tile harmonics (:mod:`.pursuit`) and keeps the texture apart in the
palette, within the format's limits; :mod:`.shortfall` names the taxtels it could not bring
under the target and why.

>>> from hcard_builtins.image import encode_image
>>> result = encode_image("bumps.png", taxtel_mm=5.0, channel="uv")   # doctest: +SKIP
>>> result.stats["rms_error_jnd"]                                     # doctest: +SKIP
0.21
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from hcard import __version__, build, limits
from hcard.card_io import to_bytes
from hcard.channels import NAMES
from hcard.errors import UsageError
from hcard.plugins.kinds import Encoder, EncodeResult
from hcard.v1 import card_pb2 as pb

from .analysis import Target, TaxtelTextures, analyse_image
from .geometry import Geometry, resolve_geometry
from .loading import DEFAULT_MAX_PIXELS, TRANSPARENT_GRAYS, GrayImage, ImageHeader, load_gray
from .palette import Palette, build_palette
from .reconstruct import FrictionMap, ReconstructionError, reconstruction_error
from .spectral import tile_centres
from .textures import orientation_and_phase

DEFAULT_FRICTION_RANGE: dict[str, tuple[float, float]] = {
    "uv": (0.3, 1.0),
    "ev": (1.0, 1.6),
    "bipolar": (0.5, 1.5),
}
"""Relative friction of white and black per channel (UV only lowers friction, EV only raises)."""
CHANNELS = NAMES
LOCKINGS = ("auto", "position", "velocity")
WHITE_IS = ("low", "high")
"""Polarities of the gray scale: white is the low end of the friction range (the encoder's own
convention, black = high friction) or the high end (Tanvas bitmaps)."""
PROGRESS_MIN_PIXELS = 1_000_000
"""Images larger than this (pixels) report their stages through the progress callback."""
DEFAULT_COMPONENTS = 8
"""Most components per texture without an error target."""
DEFAULT_MAX_TEXTURES = 64
"""Most palette textures without an error target."""
SPECTRAL_PEAKS = 8
"""Most gratings per taxtel the spectral analysis keeps; with an error target the residual
pursuit adds more, up to the ``components`` option."""
GENERATOR = f"hcard {__version__} image encoder"


@dataclass(frozen=True)
class EncodeOptions:
    """Options of the image encoder (the ``hcard encode`` options, same names).

    Attributes:
        width_mm, height_mm: physical size of the image, millimetres (one keeps the aspect
            ratio; both allow rectangular pixels).
        dpi: resolution, dots per inch (instead of a size).
        taxtel_mm: taxtel side, millimetres.
        components: most components per texture (0 to 16); ``None``: 8, or 16 with
            ``max_error``.
        max_textures: most textures in the palette (1 to 256); ``None``: 64, or 256 with
            ``max_error``.
        min_amplitude: components weaker than this (relative friction) are dropped, and a
            taxtel whose friction standard deviation is below it keeps only its baseline.
        merge_tolerance: taxtels whose textures differ by less than this RMS relative friction
            share a texture (default half the 8 % friction JND).
        max_error: error target, multiples of the 8 % friction JND: the 95th percentile of the
            absolute error over each taxtel's pixels (the card evaluated position-locked at
            the pixel centres); ``None`` for none. It also bounds the image's 95th
            percentile: if 95 % of every taxtel's pixels are within it, so are 95 % of all.
        channel: ``"uv"``, ``"ev"`` or ``"bipolar"``.
        locking: ``"auto"``, ``"position"`` or ``"velocity"``.
        friction_range: relative friction of white and of black, ``(low, high)``; ``None`` for
            the channel's default (:data:`DEFAULT_FRICTION_RANGE`).
        max_pixels: largest image accepted, pixels (a guard against decompression bombs).
        white_is: ``"low"``: white is the low end of the friction range and black the high end
            (the default, thesis section 5.4.2); ``"high"``: the reverse (gray levels are
            inverted after decoding, exactly: ``full_scale - gray``).
        transparent: what a transparent pixel shows before the friction mapping, ``"white"``
            (the default) or ``"black"``: the image is composited over it
            (:func:`.loading.load_gray`).
        title: card title; ``None`` for the image file's stem.
        author, licence: card metadata.
    """

    width_mm: float | None = None
    height_mm: float | None = None
    dpi: float | None = None
    taxtel_mm: float = 5.0
    components: int | None = None
    max_textures: int | None = None
    min_amplitude: float = 0.01
    merge_tolerance: float = limits.RELATIVE_FRICTION_JND / 2
    max_error: float | None = None
    channel: str = "uv"
    locking: str = "auto"
    friction_range: tuple[float, float] | None = None
    max_pixels: int = DEFAULT_MAX_PIXELS
    white_is: str = "low"
    transparent: str = "white"
    title: str | None = None
    author: str = ""
    licence: str = ""

    @property
    def friction_limits(self) -> tuple[float, float]:
        """``(low, high)``: relative friction of white and of black (channel default if unset)."""
        low, high = self.friction_range or DEFAULT_FRICTION_RANGE[self.channel]
        return float(low), float(high)

    def checked(self) -> EncodeOptions:
        """These options with the friction range filled in; ``ValueError`` when one is bad."""
        for name in ("width_mm", "height_mm", "dpi"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if self.dpi is not None and (self.width_mm is not None or self.height_mm is not None):
            raise ValueError("give either a DPI or a width/height in millimetres, not both")
        if not (
            math.isfinite(self.taxtel_mm)
            and limits.MIN_TAXTEL_MM <= self.taxtel_mm <= limits.MAX_SURFACE_MM
        ):
            raise ValueError(
                f"taxtel_mm must be between {limits.MIN_TAXTEL_MM} and {limits.MAX_SURFACE_MM:g} "
                f"mm, got {self.taxtel_mm}"
            )
        targeted = self.max_error is not None
        components = self.components
        if components is None:
            components = limits.MAX_COMPONENTS_PER_TEXTURE if targeted else DEFAULT_COMPONENTS
        max_textures = self.max_textures
        if max_textures is None:
            max_textures = limits.MAX_TEXTURES if targeted else DEFAULT_MAX_TEXTURES
        if not 0 <= components <= limits.MAX_COMPONENTS_PER_TEXTURE:
            raise ValueError(
                f"components must be 0 to {limits.MAX_COMPONENTS_PER_TEXTURE}, got {components}"
            )
        if not 1 <= max_textures <= limits.MAX_TEXTURES:
            raise ValueError(f"max_textures must be 1 to {limits.MAX_TEXTURES}, got {max_textures}")
        for name in ("min_amplitude", "merge_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {value}")
        if self.max_error is not None and not (math.isfinite(self.max_error)
                                               and self.max_error > 0):
            raise ValueError(f"max_error must be a number > 0 (JND), got {self.max_error}")
        if self.channel not in CHANNELS:
            raise ValueError(f"channel must be one of {', '.join(CHANNELS)}, got {self.channel!r}")
        if self.locking not in LOCKINGS:
            raise ValueError(f"locking must be one of {', '.join(LOCKINGS)}, got {self.locking!r}")
        if self.max_pixels < 1:
            raise ValueError(f"max_pixels must be at least 1, got {self.max_pixels}")
        if self.white_is not in WHITE_IS:
            raise ValueError(f"white_is must be one of {', '.join(WHITE_IS)}, "
                             f"got {self.white_is!r}")
        if self.transparent not in TRANSPARENT_GRAYS:
            raise ValueError(f"transparent must be one of {', '.join(TRANSPARENT_GRAYS)}, "
                             f"got {self.transparent!r}")
        for name in ("title", "author", "licence"):
            text = getattr(self, name)
            if text is not None and len(text) > limits.MAX_TEXT_LENGTH:
                raise ValueError(f"{name} is longer than {limits.MAX_TEXT_LENGTH} characters")
        low, high = self.friction_limits
        _check_range(low, high, self.channel)
        return replace(self, friction_range=(low, high), components=components,
                       max_textures=max_textures)


def _check_range(low: float, high: float, channel: str) -> None:
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ValueError(f"friction range must be finite, got {low} .. {high}")
    if not 0.0 <= low < high <= limits.MAX_RELATIVE_FRICTION:
        raise ValueError(
            f"friction range must satisfy 0 <= low < high <= {limits.MAX_RELATIVE_FRICTION:g}, "
            f"got {low:g} .. {high:g}"
        )
    if channel == "uv" and high > 1.0:
        raise ValueError(
            f"UV can only lower friction: the range {low:g} .. {high:g} goes above 1 "
            "(use --channel ev or bipolar)"
        )
    if channel == "ev" and low < 1.0:
        raise ValueError(
            f"EV can only raise friction: the range {low:g} .. {high:g} goes below 1 "
            "(use --channel uv or bipolar)"
        )


def encode_image(
    path: str | Path,
    options: EncodeOptions | None = None,
    *,
    progress: Callable[[str], None] | None = None,
    **overrides: Any,
) -> EncodeResult:
    """Encode the image at ``path`` into a card.

    Args:
        path: image file.
        options: encoder options (defaults when ``None``); keyword ``overrides`` replace
            single fields, for example ``taxtel_mm=2.5``.
        progress: called with a line of text at each stage, for images over
            :data:`PROGRESS_MIN_PIXELS` pixels.

    Returns:
        The card, with figures in ``stats``: image size (``image_width_px``,
        ``image_height_px``), surface (``width_mm``, ``height_mm``, ``pixel_pitch_mm``,
        ``size_source``), grid (``cols``, ``rows``, ``taxtel_mm``), ``textures``,
        ``components`` (total over the palette), ``card_bytes`` (binary form),
        ``raw_bitmap_bytes`` (8-bit bitmap at 0.1 mm), the reconstruction error over the image
        ``rms_error``, ``p95_error``, ``max_error`` (relative friction) and the same in
        multiples of the 8 % JND (``..._jnd``), the per-taxtel figures ``taxtels_over_jnd``
        (RMS above 1 JND) and ``worst_taxtel``, and with ``max_error`` set, ``target``
        (:meth:`.shortfall.Shortfall.figures`). ``maps`` holds per-taxtel ``error_rms``,
        ``error_p95`` and ``error_max`` (relative friction) and, with a target, ``shortfall``
        (reason codes of :data:`.shortfall.REASONS`, 0 where the target is met).
        The card is not validated here: ``hcard encode`` validates it once, and
        :func:`hcard.card_io.save` does when it writes it.

    Raises:
        ImageError: the image cannot be read or is too large (see :func:`load_gray`), or the
            surface or grid exceed the card limits.
        ValueError: an option is out of range.
    """
    opts = _options(options, overrides)
    components, max_textures = opts.components, opts.max_textures
    assert components is not None and max_textures is not None  # filled in by checked()
    started = time.perf_counter()

    def check_geometry(header: ImageHeader) -> None:
        """The surface and grid of the image, checked before it is decoded."""
        resolve_geometry(header.width, header.height, taxtel_mm=opts.taxtel_mm,
                         width_mm=opts.width_mm, height_mm=opts.height_mm, dpi=opts.dpi,
                         embedded_dpi=header.dpi, source=header.path)

    image = load_gray(path, max_pixels=opts.max_pixels, check_header=check_geometry,
                      transparent=opts.transparent)
    if opts.white_is == "high":
        image = inverted(image)
    large = image.width * image.height > PROGRESS_MIN_PIXELS

    def say(line: str) -> None:
        if progress is not None and large:
            progress(line)

    say(f"decoded {image.width} x {image.height} pixels")
    geometry = resolve_geometry(
        image.width,
        image.height,
        taxtel_mm=opts.taxtel_mm,
        width_mm=opts.width_mm,
        height_mm=opts.height_mm,
        dpi=opts.dpi,
        embedded_dpi=image.dpi,
        source=image.path,
    )
    low, high = opts.friction_limits
    mapping = FrictionMap(high=high, scale=(high - low) / image.full_scale)
    say(f"analysing {geometry.n_taxtels} taxtels of {geometry.tile_w} x {geometry.tile_h} pixels")
    target = _target(opts)
    taxtels = analyse_image(
        image,
        geometry,
        mapping,
        peaks=components if target is None else min(components, SPECTRAL_PEAKS),
        min_amplitude=opts.min_amplitude,
        low=low,
        target=target,
    )
    say(f"merging {geometry.n_taxtels} taxtel textures into at most {opts.max_textures}")
    palette = build_palette(
        taxtels.textures,
        tile_centres(geometry),
        bin_width=1.0 / opts.taxtel_mm,
        tolerance=merge_tolerance(taxtels, target, opts.merge_tolerance),
        max_textures=max_textures,
        min_amplitude=opts.min_amplitude,
        keyed=target is not None,
        fixed=taxtels.pursued,
    )
    say("rendering the card back to measure the reconstruction error")
    error = reconstruction_error(image.pixels, geometry, palette, mapping)
    card = make_card(image, geometry, palette, opts)  # validated by the caller that keeps it
    stats = _stats(image, geometry, palette, error, card, opts)
    log = [f"physical size {geometry.size_source}"]
    if palette.leaders > len(card.textures):
        log.append(
            f"{palette.leaders} distinct textures merged into {len(card.textures)} "
            f"(--max-textures {opts.max_textures})"
        )
    maps = {"error_rms": error.taxtel_rms, "error_p95": error.taxtel_p95,
            "error_max": error.taxtel_max}
    if target is not None:
        from .shortfall import shortfall  # only with a target (start-up of hcard encode)

        missed = shortfall(error, taxtels, target,
                           palette_full=palette.leaders > max_textures)
        stats["target"] = missed.figures()
        maps["shortfall"] = missed.reason
    stats["seconds"] = time.perf_counter() - started
    return EncodeResult(card=card, stats=stats, log=log, maps=maps)


def inverted(image: GrayImage) -> GrayImage:
    """``image`` with its gray scale reversed, ``full_scale - gray`` (exact for the integer
    types): the encoder's black = high friction for an image whose white is high friction."""
    pixels = (image.full_scale - image.pixels.astype(np.float64)).astype(image.pixels.dtype)
    return replace(image, pixels=pixels)


def _target(opts: EncodeOptions) -> Target | None:
    """The error target of ``opts`` in relative friction, or None."""
    if opts.max_error is None:
        return None
    assert opts.components is not None  # filled in by checked()
    return Target(p95=opts.max_error * limits.RELATIVE_FRICTION_JND, components=opts.components)


def merge_tolerance(
    taxtels: TaxtelTextures, target: Target | None, tolerance: float
) -> float | np.ndarray:
    """How far (RMS relative friction) each taxtel's palette texture may differ from its own.

    Without a target: ``tolerance`` for all. With one, errors add in quadrature (the difference
    of two textures is nearly orthogonal to what neither reproduces), so a taxtel whose own
    texture leaves ``own_rms`` may differ by ``sqrt(goal^2 - own_rms^2)`` and stay at the RMS
    goal; at most ``tolerance``. A taxtel over the target on its own keeps ``tolerance``: it
    misses the target whatever it shares, and a texture of its own would take a palette entry
    from a taxtel that can meet it.
    """
    if target is None:
        return tolerance
    room = np.sqrt(np.maximum(target.goal_rms**2 - taxtels.own_rms**2, 0.0))
    hopeless = taxtels.own_p95 > target.p95
    return np.where(hopeless, tolerance, np.minimum(room, tolerance))


def make_card(
    image: GrayImage, geometry: Geometry, palette: Palette, opts: EncodeOptions
) -> pb.Card:
    """The card message for an analysed image."""
    textures = palette.textures
    low, high = opts.friction_limits
    high_end, low_end = ("black", "white") if opts.white_is == "low" else ("white", "black")
    frequency = np.hypot(textures.k[..., 0], textures.k[..., 1])
    orientation, phase = orientation_and_phase(textures)
    amplitude = np.abs(textures.coef)
    palette_textures = []
    for p in range(textures.baseline.size):
        parts = [
            build.spatial(
                float(frequency[p, j]),
                float(amplitude[p, j]),
                phase=float(phase[p, j]),
                orientation=float(orientation[p, j]),
            )
            for j in np.nonzero(textures.valid[p])[0]
        ]
        palette_textures.append(
            build.texture(
                float(textures.baseline[p]), parts, channel=opts.channel, locking=opts.locking
            )
        )
    card = build.card(
        geometry.width_mm,
        geometry.height_mm,
        taxtel_mm=opts.taxtel_mm,
        textures=palette_textures,
        texture_index=palette.index,
        title=image.path.stem if opts.title is None else opts.title,
        author=opts.author,
        licence=opts.licence,
        description=(
            f"Encoded from {image.path.name} ({image.width} x {image.height} pixels): "
            f"{high_end} = relative friction {high:g}, {low_end} = {low:g}, "
            f"channel {opts.channel}."
        ),
    )
    card.metadata.generator = GENERATOR
    return card


def raw_bitmap_bytes(width_mm: float, height_mm: float) -> int:
    """Size of an 8-bit friction bitmap of the surface at 0.1 mm resolution, bytes."""
    return math.ceil(width_mm * 10 - 1e-9) * math.ceil(height_mm * 10 - 1e-9)


def _options(options: EncodeOptions | None, overrides: dict[str, Any]) -> EncodeOptions:
    opts = options or EncodeOptions()
    known = {f.name for f in fields(EncodeOptions)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ValueError(f"unknown image encoder option(s): {', '.join(unknown)}")
    return replace(opts, **overrides).checked()


def _stats(
    image: GrayImage,
    geometry: Geometry,
    palette: Palette,
    error: ReconstructionError,
    card: pb.Card,
    opts: EncodeOptions,
) -> dict[str, Any]:
    jnd = limits.RELATIVE_FRICTION_JND
    card_bytes = len(to_bytes(card))
    raw = raw_bitmap_bytes(geometry.width_mm, geometry.height_mm)
    textured = np.asarray(palette.textures.valid.any(axis=1))[palette.index]
    return {
        "image": str(image.path),
        "image_width_px": image.width,
        "image_height_px": image.height,
        "image_mode": image.mode,
        "width_mm": geometry.width_mm,
        "height_mm": geometry.height_mm,
        "pixel_pitch_mm": geometry.pixel_pitch_mm,
        "size_source": geometry.size_source,
        "cols": geometry.cols,
        "rows": geometry.rows,
        "taxtel_mm": opts.taxtel_mm,
        "tile_px": (geometry.tile_w, geometry.tile_h),
        "channel": opts.channel,
        "locking": opts.locking,
        "friction_range": opts.friction_range,
        "white_is": opts.white_is,
        "textures": len(card.textures),
        "components": sum(len(t.components) for t in card.textures),
        "textured_taxtels": int(textured.sum()),
        "distinct_textures": palette.leaders,
        "card_bytes": card_bytes,
        "raw_bitmap_bytes": raw,
        "rms_error": error.rms,
        "max_error": error.max,
        "p95_error": error.p95,
        "rms_error_jnd": error.rms / jnd,
        "p95_error_jnd": error.p95 / jnd,
        "max_error_jnd": error.max / jnd,
        **_taxtel_figures(error, jnd),
    }


def _taxtel_figures(error: ReconstructionError, jnd: float) -> dict[str, Any]:
    """Per-taxtel error figures of the summary: how many taxtels have an RMS error above one
    JND, and the worst taxtel (by RMS; column, row, RMS and maximum in JND)."""
    if error.taxtel_rms is None or error.taxtel_max is None or not error.taxtel_rms.size:
        return {}
    rms, largest = error.taxtel_rms, error.taxtel_max
    row, col = np.unravel_index(int(np.argmax(rms)), rms.shape)
    return {
        "taxtels_over_jnd": int(np.count_nonzero(rms > jnd)),
        "worst_taxtel": {"col": int(col), "row": int(row), "rms_jnd": float(rms[row, col]) / jnd,
                         "max_jnd": float(largest[row, col]) / jnd},
    }


class ImageEncoder(Encoder):
    """Encoder plugin ``image``: see :func:`encode_image` for the options."""

    name = "image"
    description = (
        "Grayscale image to card (black = high friction): per-taxtel spectral analysis into a "
        "palette of grating textures"
    )

    def options(self, **values: Any) -> dict[str, Any]:
        """``values``, :class:`EncodeOptions` fields, checked (:meth:`EncodeOptions.checked`)
        and with the defaults filled in; a bad one is a :class:`~hcard.errors.UsageError`
        naming the field."""
        try:
            checked = _options(None, values)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        return {f.name: getattr(checked, f.name) for f in fields(checked)}

    def encode(self, source: Path, *, progress: Callable[[str], None] | None = None,
               **options: Any) -> EncodeResult:
        """Encode the image ``source``; ``options`` are :class:`EncodeOptions` fields (or
        ``options``, an :class:`EncodeOptions`), see :func:`encode_image`."""
        return encode_image(source, progress=progress, **options)
