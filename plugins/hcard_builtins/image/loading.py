"""Image loading for the encoder: checks, pixel limit, conversion to a gray array.

Every problem with the input file raises :class:`hcard.errors.ImageError` with a one-line
reason. The pixel count is checked from the image header *before* any pixel is decoded, so a
decompression bomb (a small file declaring a huge image) costs no memory: PNG headers are read
directly, other formats through Pillow's lazy :func:`PIL.Image.open`, which reads the header only.

Gray follows ITU-R 601 luma (Pillow mode ``"L"``); transparent images are composited over white;
16-bit gray images keep their 16 bits; an EXIF orientation tag is applied, so the surface is
the picture as viewers show it. Black is 0, white is :attr:`GrayImage.full_scale`.
"""

from __future__ import annotations

import struct
import threading
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from hcard.bounded_read import DEFAULT_MAX_PIXELS
from hcard.errors import ImageError

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_HEADER_BYTES = 64
_ALPHA_MODES = frozenset({"RGBA", "RGBa", "LA", "La", "PA"})
_SIXTEEN_BIT_MODES = frozenset({"I;16", "I;16L", "I;16B", "I;16N"})
_EXIF_ORIENTATION = 0x0112
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


def load_gray(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> GrayImage:
    """Read an image file as gray levels (black = 0).

    Args:
        path: image file in any format Pillow reads (PNG, JPEG, TIFF, BMP, GIF, WebP, ...).
        max_pixels: largest accepted width x height, pixels; checked from the header before
            decoding.

    Raises:
        ImageError: the file is missing, a directory, empty, not an image, declares zero width
            or height, exceeds ``max_pixels``, or its pixel data is corrupt or truncated.
    """
    if max_pixels < 1:
        raise ValueError(f"max_pixels must be at least 1, got {max_pixels}")
    file = Path(path)
    head = _read_head(file)
    png_size = png_header_size(head)
    if png_size is not None:
        check_size(file, *png_size, max_pixels=max_pixels)
    image = _open(file, max_pixels)
    try:
        check_size(file, image.width, image.height, max_pixels=max_pixels)
        try:
            image.load()
            upright = _upright(image)
        except (OSError, SyntaxError, ValueError, EOFError, struct.error, zlib.error) as exc:
            raise ImageError(f"{file}: corrupt or truncated image data ({exc})") from None
        pixels, full_scale = to_gray(upright, file)
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


def png_header_size(head: bytes) -> tuple[int, int] | None:
    """Width and height declared by a PNG IHDR chunk at the start of ``head``, or ``None``.

    ``None`` when ``head`` is not the start of a PNG file. Used to check the size of a PNG before
    Pillow sees it, so that zero sizes and decompression bombs get a precise message.
    """
    if len(head) < 24 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", head[16:24])
    return int(width), int(height)


def to_gray(image: Image.Image, file: Path) -> tuple[np.ndarray, float]:
    """Gray levels of a loaded Pillow image and the value of white.

    8-bit and colour images become ``uint8`` ITU-R 601 luma; alpha is composited over white;
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
            white = Image.new("RGBA", image.size, (255, 255, 255, 255))
            return np.asarray(
                Image.alpha_composite(white, image.convert("RGBA")).convert("L")
            ), 255.0
        if mode in ("1", "RGB", "RGBX", "CMYK", "YCbCr"):
            return np.asarray(image.convert("L")), 255.0
        return np.asarray(image.convert("RGB").convert("L")), 255.0
    except (ValueError, OSError) as exc:
        raise ImageError(f"{file}: cannot convert image mode {mode!r} to gray ({exc})") from None


def _read_head(file: Path) -> bytes:
    try:
        with file.open("rb") as stream:
            head = stream.read(_HEADER_BYTES)
    except FileNotFoundError:
        raise ImageError(f"{file}: no such file") from None
    except IsADirectoryError:
        raise ImageError(f"{file}: is a directory, not an image") from None
    except OSError as exc:
        raise ImageError(f"{file}: cannot read ({exc.strerror or exc})") from None
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
