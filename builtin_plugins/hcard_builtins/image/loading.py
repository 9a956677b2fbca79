"""Image loading for the encoder: checks, pixel limit, conversion to a gray array.

Every problem with the input file raises :class:`hcard.errors.ImageError` with a one-line
reason. What the header declares is checked *before* any pixel is decoded, so a decompression
bomb (a small file declaring a huge image) costs no memory: PNG headers are read directly, other
formats through Pillow's lazy :func:`PIL.Image.open`, which reads the header only. Checked
there: the pixel count (``max_pixels``), the memory the pixels take while they are decoded and
turned gray (:func:`decode_bytes`: a 0.5 MB PNG declaring 8000 x 8000 pixels of 16-bit RGBA,
under the pixel limit, took 34 s and 1.0 GB), and whatever the caller checks on the header
(``check_header``: the encoder's surface and grid, which refused a 64,000,000 x 1 image only
after its 221 MB were decoded).

Gray follows ITU-R 601 luma (Pillow mode ``"L"``); transparent images are composited over white
(or over black, ``transparent="black"``: formats whose zero drive is black); 16-bit gray images
keep their 16 bits; an EXIF orientation tag is applied, so the surface is
the picture as viewers show it. Black is 0, white is :attr:`GrayImage.full_scale`.
"""

from __future__ import annotations

import struct
import threading
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from hcard.bounded_read import DECODE_BYTES_PER_ALLOWED_PIXEL, DEFAULT_MAX_PIXELS
from hcard.errors import ImageError
from hcard.file_errors import reading

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_HEADER_BYTES = 64
_ALPHA_MODES = frozenset({"RGBA", "RGBa", "LA", "La", "PA"})
_SIXTEEN_BIT_MODES = frozenset({"I;16", "I;16L", "I;16B", "I;16N"})
_EXIF_ORIENTATION = 0x0112
TRANSPARENT_GRAYS: dict[str, int] = {"white": 255, "black": 0}
"""The backgrounds a transparent image may be composited over, by name: their 8-bit gray."""
_pillow_limit_lock = threading.Lock()


@dataclass(frozen=True)
class GrayImage:
    """A decoded image as gray levels.

    Attributes:
        pixels: ``(height, width)`` array, row 0 at the top; ``uint8``, ``uint16`` or
            ``float32``. 0 is black.
        full_scale: the value of white (255, 65535, or 255 for float images).
        dpi: resolution stored in the file, dots per inch along x and y, or ``None``.
        mode: Pillow mode of the file (for the summary), for example ``"L"`` or ``"RGBA"``.
        path: the file it came from.
    """

    pixels: np.ndarray
    full_scale: float
    dpi: tuple[float, float] | None
    mode: str
    path: Path

    @property
    def width(self) -> int:
        """Width in pixels."""
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        """Height in pixels."""
        return int(self.pixels.shape[0])


@dataclass(frozen=True)
class ImageHeader:
    """What an image file declares before any pixel is decoded.

    Attributes:
        path: the file.
        width, height: size in pixels as the image is displayed (after its EXIF orientation).
        mode: Pillow mode of the file (``"L"``, ``"I;16"``, ``"RGBA"``, ...).
        dpi: resolution stored in the file (as :attr:`GrayImage.dpi`), or ``None``.
    """

    path: Path
    width: int
    height: int
    mode: str
    dpi: tuple[float, float] | None


def load_gray(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS,
              check_header: Callable[[ImageHeader], None] | None = None,
              transparent: str = "white") -> GrayImage:
    """Read an image file as gray levels (black = 0).

    Args:
        path: image file in any format Pillow reads (PNG, JPEG, TIFF, BMP, GIF, WebP, ...).
        max_pixels: largest accepted width x height, pixels; checked from the header before
            decoding, with the memory decoding takes (:func:`check_decode_bytes`).
        check_header: called with the header before decoding; it raises to refuse the image.
        transparent: what a transparent pixel shows, ``"white"`` or ``"black"``: the image is
            composited over it (:data:`TRANSPARENT_GRAYS`).

    Raises:
        ImageError: the file is missing, a directory, empty, not an image, declares zero width
            or height, exceeds ``max_pixels`` or the memory that allows, or its pixel data is
            corrupt or truncated; or what ``check_header`` raises.
    """
    if max_pixels < 1:
        raise ValueError(f"max_pixels must be at least 1, got {max_pixels}")
    if transparent not in TRANSPARENT_GRAYS:
        raise ValueError(f"transparent must be one of {', '.join(TRANSPARENT_GRAYS)}, "
                         f"got {transparent!r}")
    file = Path(path)
    head = _read_head(file)
    png_size = png_header_size(head)
    if png_size is not None:
        check_size(file, *png_size, max_pixels=max_pixels)
    image = _open(file, max_pixels)
    try:
        check_size(file, image.width, image.height, max_pixels=max_pixels)
        check_decode_bytes(file, image.width, image.height, image.mode, max_pixels=max_pixels)
        if check_header is not None:
            check_header(header_of(image, file))
        try:
            image.load()
            upright = _upright(image)
        except (OSError, SyntaxError, ValueError, EOFError, struct.error, zlib.error) as exc:
            raise ImageError(f"{file}: corrupt or truncated image data ({exc})") from None
        pixels, full_scale = to_gray(upright, file, transparent=transparent)
        return GrayImage(pixels, full_scale, _dpi_of(image), image.mode, file)
    finally:
        image.close()


def check_size(file: Path, width: int, height: int, *, max_pixels: int) -> None:
    """Reject an image of zero width or height, or of more than ``max_pixels`` pixels."""
    if width <= 0 or height <= 0:
        raise ImageError(f"{file}: empty image ({width} x {height} pixels)")
    if width * height > max_pixels:
        raise ImageError(
            f"{file}: {width} x {height} = {width * height} pixels exceed the limit of "
            f"{max_pixels} pixels (raise it with --max-pixels if the image is genuine)"
        )


_ONE_BYTE_MODES = frozenset({"1", "L"})
_COLOUR_BYTES = 4
"""Bytes Pillow keeps a pixel of any colour or multi-band mode in (``RGB`` too)."""


def decode_bytes(mode: str) -> int:
    """Bytes a pixel of Pillow ``mode`` takes at the peak of decoding it and turning it gray
    (:func:`to_gray`): 1 for 8-bit gray, 2 for 16-bit gray, 4 for 32-bit and float gray, 5 for
    colour (the image and its gray), 13 with alpha (the image, a white image and their
    composite, and the gray), 9 for a palette (its RGB or RGBA conversion, and the gray)."""
    if mode in _ONE_BYTE_MODES:
        return 1
    if mode in _SIXTEEN_BIT_MODES:
        return 2
    if mode in ("I", "F"):
        return 4
    if mode == "P":
        return 1 + 2 * _COLOUR_BYTES
    if mode in _ALPHA_MODES:
        return 3 * _COLOUR_BYTES + 1
    return _COLOUR_BYTES + 1


def check_decode_bytes(file: Path, width: int, height: int, mode: str, *,
                       max_pixels: int) -> None:
    """Reject an image whose decoding would take more than
    :data:`~hcard.bounded_read.DECODE_BYTES_PER_ALLOWED_PIXEL` bytes per pixel of
    ``max_pixels`` (:func:`decode_bytes`): 256 MB at the default 64 megapixels, which 64
    megapixels of 8-bit gray take in 64 MB and 16 megapixels of RGBA in 208 MB."""
    need = width * height * decode_bytes(mode)
    budget = DECODE_BYTES_PER_ALLOWED_PIXEL * max_pixels
    if need > budget:
        raise ImageError(
            f"{file}: {width} x {height} pixels of mode {mode} take {need / 1e6:.0f} MB to "
            f"decode ({decode_bytes(mode)} bytes a pixel), over the limit of "
            f"{budget / 1e6:.0f} MB ({DECODE_BYTES_PER_ALLOWED_PIXEL} bytes a pixel of the "
            "pixel limit; raise it with --max-pixels if the image is genuine)")


def header_of(image: Image.Image, file: Path) -> ImageHeader:
    """The header of an opened, not yet decoded, image: its size as displayed (a photo
    stored sideways, EXIF orientation 5-8, has width and height swapped)."""
    width, height = image.width, image.height
    if _declared_orientation(image) in (5, 6, 7, 8):
        width, height = height, width
    return ImageHeader(file, width, height, image.mode, _dpi_of(image))


def _declared_orientation(image: Image.Image) -> int:
    """The EXIF orientation an opened image declares, read without decoding it (Pillow's
    ``getexif`` decodes a PNG to look for an eXIf chunk after its pixel data); 1 when it
    declares none or a corrupt one."""
    tags = getattr(image, "tag_v2", None)  # TIFF
    if tags is not None:
        return int(tags.get(_EXIF_ORIENTATION, 1))
    raw = image.info.get("exif")  # JPEG, WebP, and a PNG whose eXIf precedes its data
    if not isinstance(raw, bytes):
        return 1
    exif = Image.Exif()
    try:
        exif.load(raw)
        return int(exif.get(_EXIF_ORIENTATION, 1))
    except (OSError, SyntaxError, ValueError, TypeError, struct.error):
        return 1


def png_header_size(head: bytes) -> tuple[int, int] | None:
    """Width and height declared by a PNG IHDR chunk at the start of ``head``, or ``None``.

    ``None`` when ``head`` is not the start of a PNG file. Used to check the size of a PNG before
    Pillow sees it, so that zero sizes and decompression bombs get a precise message.
    """
    if len(head) < 24 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", head[16:24])
    return int(width), int(height)


def to_gray(image: Image.Image, file: Path, *, transparent: str = "white"
            ) -> tuple[np.ndarray, float]:
    """Gray levels of a loaded Pillow image and the value of white.

    8-bit and colour images become ``uint8`` ITU-R 601 luma; alpha is composited over white
    (``transparent="black"``: over black);
    16-bit gray stays ``uint16``; 32-bit integer images (mode ``"I"``) are read as 16-bit values
    clipped to 0..65535; float images (mode ``"F"``) as 0..255 like Pillow's own conversion.
    """
    mode = image.mode
    try:
        if mode == "P":
            image = image.convert("RGBA" if "transparency" in image.info else "RGB")
            mode = image.mode
        if mode == "L":
            return np.asarray(image), 255.0
        if mode in _SIXTEEN_BIT_MODES:
            return np.asarray(image).astype(np.uint16, copy=False), 65535.0
        if mode == "I":
            return np.clip(np.asarray(image), 0, 65535).astype(np.uint16), 65535.0
        if mode == "F":
            return np.clip(np.asarray(image, dtype=np.float32), 0.0, 255.0), 255.0
        if mode in _ALPHA_MODES:
            level = TRANSPARENT_GRAYS[transparent]
            background = Image.new("RGBA", image.size, (level, level, level, 255))
            return np.asarray(
                Image.alpha_composite(background, image.convert("RGBA")).convert("L")
            ), 255.0
        if mode in ("1", "RGB", "RGBX", "CMYK", "YCbCr"):
            return np.asarray(image.convert("L")), 255.0
        return np.asarray(image.convert("RGB").convert("L")), 255.0
    except (ValueError, OSError) as exc:
        raise ImageError(f"{file}: cannot convert image mode {mode!r} to gray ({exc})") from None


def _read_head(file: Path) -> bytes:
    with reading(file, ImageError, "an image"), file.open("rb") as stream:
        head = stream.read(_HEADER_BYTES)
    if not head:
        raise ImageError(f"{file}: empty file (0 bytes), not an image")
    return head


def _open(file: Path, max_pixels: int) -> Image.Image:
    """``Image.open`` (header only) with Pillow's own bomb check set no lower than ours."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            pillow_limit = Image.MAX_IMAGE_PIXELS
            if pillow_limit is None or 2 * pillow_limit >= max_pixels:
                return Image.open(file)
            # The caller allows more than Pillow would: lift Pillow's limit for this call only.
            # Our own check on the header size follows in load_gray.
            with _pillow_limit_lock:
                Image.MAX_IMAGE_PIXELS = max_pixels
                try:
                    return Image.open(file)
                finally:
                    Image.MAX_IMAGE_PIXELS = pillow_limit
    except Image.DecompressionBombError as exc:
        raise ImageError(f"{file}: over the pixel limit of {max_pixels} pixels ({exc})") from None
    except UnidentifiedImageError:
        raise ImageError(f"{file}: not an image (unrecognised or corrupt format)") from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error) as exc:
        raise ImageError(f"{file}: not a readable image ({exc})") from None


def _upright(image: Image.Image) -> Image.Image:
    """The image as it is displayed: rotated or flipped as its EXIF orientation tag says
    (cameras store portrait photos sideways); unchanged when there is no such tag."""
    if image.getexif().get(_EXIF_ORIENTATION, 1) in (0, 1):
        return image
    from PIL import ImageOps  # only for rotated images (start-up of hcard encode)

    return ImageOps.exif_transpose(image)


_TIFF_RESOLUTION_UNIT = 296
"""TIFF tag ResolutionUnit: 1 none, 2 inch, 3 centimetre."""


def _dpi_of(image: Image.Image) -> tuple[float, float] | None:
    """The resolution the file states in a physical unit, when it is a positive number; None
    where the number is Pillow's rather than the file's: a JPEG without a JFIF density in dots
    per inch or centimetre gets 72 dpi from Pillow whenever it carries EXIF, and a TIFF without
    a ResolutionUnit of inch or centimetre has no physical resolution (Pillow then reports its
    bare XResolution, 1 by default). Taken at face value those changed the surface of the same
    pixels 3.5-fold with the metadata."""
    if image.format == "JPEG" and image.info.get("jfif_unit") not in (1, 2):
        return None
    if image.format == "TIFF":
        tags = getattr(image, "tag_v2", {})
        if tags.get(_TIFF_RESOLUTION_UNIT) not in (2, 3):
            return None
    dpi = image.info.get("dpi")
    try:
        x, y = (float(v) for v in dpi)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        return None
    if not (np.isfinite(x) and np.isfinite(y)) or x <= 0 or y <= 0:
        return None
    return x, y
