"""The glTF 2.0 companion of an .hjif export: the card's surface as a textured rectangle whose
``MPEG_haptic_material`` places the textures on it, the taxtel map as an index image (rules
IJ50-IJ56 of spec/interchange/hjif.md).

``MPEG_haptic`` (at the glTF root) and ``MPEG_haptic_material`` (on a material) are the MPEG
extensions of ISO/IEC 23090-14 2nd edition (KhronosGroup/glTF pull request 2502). The text of
the pull request was not available to this implementation; what it uses of them is stated as
assumptions in spec/interchange/hjif.md (IJ51): one haptic object stands for the .hjif beside
the glTF with the same file stem;
a material's ``friction`` property is a list of haptic textures, each a glTF ``textureInfo``
(``index``, ``texCoord``) with ``type`` ``"Reference"``: a pixel's value is the id of the
.hjif channel that plays there.
"""

from __future__ import annotations

import base64
import json
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from hcard import limits
from hcard.errors import AssetError
from hcard.v1 import card_pb2 as pb

MIME_PNG = "image/png"
NEAREST = 9728
CLAMP_TO_EDGE = 33071
FLOAT = 5126
UNSIGNED_SHORT = 5123
HAPTIC = "MPEG_haptic"
MATERIAL = "MPEG_haptic_material"
REFERENCE = "Reference"
HAPTIC_OBJECT = "hcard friction: the .hjif of the same file name stem"
"""The haptic object's name: the .hjif is the file beside the glTF with its stem (IJ51)."""
MAX_GLTF_BYTES = 16 * 1024 * 1024
"""Largest glTF companion read, bytes."""


def gltf_bytes(card: pb.Card, generator: str) -> bytes:
    """The glTF companion of ``card`` (IJ50-IJ55): UTF-8 JSON,
    two-space indented, keys in a fixed order, so the same card gives the same bytes."""
    cols, rows = card.grid.cols, card.grid.rows
    width_m = card.surface.width_mm / 1000.0
    height_m = card.surface.height_mm / 1000.0
    u1 = card.surface.width_mm / (cols * card.grid.taxtel_width_mm)
    v1 = card.surface.height_mm / (rows * card.grid.taxtel_height_mm)
    # +x right, hcard +y down is glTF -y; the rectangle faces +z (glTF is y-up, metres)
    positions = np.array([[0, 0, 0], [width_m, 0, 0], [width_m, -height_m, 0],
                          [0, -height_m, 0]], dtype="<f4")
    texcoords = np.array([[0, 0], [u1, 0], [u1, v1], [0, v1]], dtype="<f4")
    indices = np.array([0, 3, 2, 0, 2, 1], dtype="<u2")
    blob = positions.tobytes() + texcoords.tobytes() + indices.tobytes()
    index = np.asarray(card.grid.texture_index, dtype=np.uint8).reshape(rows, cols)
    document: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": generator},
        "extensionsUsed": [HAPTIC, MATERIAL],
        "extensions": {HAPTIC: {"hapticObjects": [{"name": HAPTIC_OBJECT}]}},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "surface", "mesh": 0}],
        "meshes": [{"name": "surface", "primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"name": "hcard taxtel map", "extensions": {MATERIAL: {"friction": [
            {"index": 0, "texCoord": 0, "type": REFERENCE, "hapticObject": 0}]}}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": NEAREST, "minFilter": NEAREST, "wrapS": CLAMP_TO_EDGE,
                      "wrapT": CLAMP_TO_EDGE}],
        "images": [{"name": "taxtel map: pixel value = hjif channel id",
                    "uri": "data:image/png;base64," + base64.b64encode(png_gray(index))
                    .decode("ascii")}],
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode("ascii")}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 32, "target": 34962},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12, "target": 34963}],
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "count": 4, "type": "VEC3",
             "min": [0.0, -_f32(height_m), 0.0], "max": [_f32(width_m), 0.0, 0.0]},
            {"bufferView": 1, "componentType": FLOAT, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": UNSIGNED_SHORT, "count": 6, "type": "SCALAR"}],
    }
    return (json.dumps(document, indent=2, ensure_ascii=False) + "\n").encode("utf-8")


def _f32(value: float) -> float:
    return float(np.float32(value))


def png_gray(pixels: np.ndarray) -> bytes:
    """An 8-bit grayscale PNG of ``pixels`` (rows x cols, uint8), unfiltered rows, zlib level
    9: deterministic bytes."""
    rows, cols = pixels.shape

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    raw = b"".join(b"\x00" + pixels[r].astype(np.uint8).tobytes() for r in range(rows))
    header = struct.pack(">IIBBBBB", cols, rows, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9))
            + chunk(b"IEND", b""))


class TaxtelMap:
    """What a glTF companion says of the surface: the index image (rows x cols of channel
    ids) and, when its rectangle gives them, the surface size and taxtel size in mm."""

    def __init__(self, ids: np.ndarray, surface_mm: tuple[float, float] | None,
                 taxtel_mm: tuple[float, float] | None) -> None:
        self.ids = ids
        self.surface_mm = surface_mm
        self.taxtel_mm = taxtel_mm


def read_taxtel_map(path: Path) -> TaxtelMap:
    """The taxtel map of the glTF companion ``path`` (IJ56).

    Raises:
        AssetError: not a glTF JSON within 16 MiB, no ``MPEG_haptic_material`` friction
            texture of type Reference, an image that is not an 8-bit grayscale PNG data URI
            (or a file beside the glTF) of at most 1024 x 1024 pixels.
    """
    from hcard.bounded_read import InputTooLarge, read_bounded
    from hcard.file_errors import read_reason
    from hcard.json_text import JsonInputError, parse_json

    try:
        doc = parse_json(read_bounded(path, MAX_GLTF_BYTES))
    except (JsonInputError, InputTooLarge) as exc:
        raise AssetError(f"glTF companion: {exc}", source=path) from None
    except OSError as exc:
        raise AssetError(read_reason(exc, "a glTF companion"), source=path) from None
    image_index = _haptic_image(doc, path)
    uri = _get(doc, ["images", image_index, "uri"], str, path)
    ids = _decode_png(_image_bytes(uri, path, f"images[{image_index}].uri"), path)
    return TaxtelMap(ids, *_geometry(doc, ids.shape, path))


def _haptic_image(doc: Any, path: Path) -> int:
    materials = _get(doc, ["materials"], list, path)
    for m, material in enumerate(materials):
        ext = material.get("extensions", {}).get(MATERIAL) if isinstance(material, dict) else None
        if not isinstance(ext, dict):
            continue
        for i in range(len(ext.get("friction", []))):
            where = ["materials", m, "extensions", MATERIAL, "friction", i]
            if _get(doc, [*where, "type"], str, path) != REFERENCE:
                continue
            texture = _get(doc, [*where, "index"], int, path)
            source: int = _get(doc, ["textures", texture, "source"], int, path)
            return source
    raise AssetError(f"no material with an {MATERIAL} friction texture of type {REFERENCE}",
                     source=path, field="materials")


def _get(doc: Any, keys: list[Any], kind: type, path: Path) -> Any:
    value = doc
    where = ""
    for key in keys:
        where += f"[{key}]" if isinstance(key, int) else (f".{key}" if where else key)
        ok = (isinstance(value, list) and isinstance(key, int) and 0 <= key < len(value)) or (
            isinstance(value, dict) and isinstance(key, str) and key in value)
        if not ok:
            raise AssetError("missing", source=path, field=where)
        value = value[key]
    if isinstance(value, bool) or not isinstance(value, kind):
        raise AssetError(f"must be a JSON {kind.__name__}", source=path, field=where)
    return value


def _image_bytes(uri: str, path: Path, where: str) -> bytes:
    from hcard.bounded_read import InputTooLarge, read_bounded

    prefix = "data:image/png;base64,"
    if uri.startswith(prefix):
        try:
            return base64.b64decode(uri[len(prefix):], validate=True)
        except ValueError:
            raise AssetError("not valid base64", source=path, field=where) from None
    if "/" in uri or "\\" in uri or uri.startswith("data:") or uri in ("", ".", ".."):
        raise AssetError("only a PNG data URI or a file name beside the glTF is read",
                         source=path, field=where)
    try:
        return read_bounded(path.parent / uri, MAX_GLTF_BYTES)
    except (OSError, InputTooLarge) as exc:
        raise AssetError(f"the image {uri} cannot be read: {exc}", source=path,
                         field=where) from None


def _decode_png(data: bytes, path: Path) -> np.ndarray:
    import io

    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format != "PNG" or image.mode not in ("L", "P"):
                raise AssetError(f"the taxtel map is a {image.format} image of mode "
                                 f"{image.mode}, not an 8-bit grayscale PNG", source=path,
                                 field="images")
            cols, rows = image.size
            if cols > limits.MAX_GRID_COLS or rows > limits.MAX_GRID_ROWS:
                raise AssetError(f"the taxtel map has {cols} x {rows} pixels, over the "
                                 f"card's {limits.MAX_GRID_COLS} x {limits.MAX_GRID_ROWS} "
                                 "taxtels", source=path, field="images")
            return np.asarray(image, dtype=np.uint8).copy()
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise AssetError(f"the taxtel map is not a readable PNG ({exc})", source=path,
                         field="images") from None


def _geometry(doc: Any, shape: tuple[int, ...], path: Path
              ) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """Surface and taxtel size in mm from the rectangle's POSITION bounds and the far
    corner's texture coordinates (IJ53), or None where the glTF does not give them."""
    try:
        accessors = doc["meshes"][0]["primitives"][0]["attributes"]
        low = doc["accessors"][accessors["POSITION"]]["min"]
        high = doc["accessors"][accessors["POSITION"]]["max"]
        width_mm = (float(high[0]) - float(low[0])) * 1000.0
        height_mm = (float(high[1]) - float(low[1])) * 1000.0
    except (KeyError, IndexError, TypeError, ValueError):
        return None, None
    if not (0 < width_mm <= limits.MAX_SURFACE_MM and 0 < height_mm <= limits.MAX_SURFACE_MM):
        raise AssetError(f"the surface rectangle is {width_mm:g} x {height_mm:g} mm",
                         source=path, field="accessors")
    rows, cols = shape
    far = _far_corner(doc, accessors)
    if far is None:
        return (width_mm, height_mm), (width_mm / cols, height_mm / rows)
    return (width_mm, height_mm), (width_mm / (far[0] * cols), height_mm / (far[1] * rows))


def _far_corner(doc: Any, attributes: Any) -> tuple[float, float] | None:
    """The largest texture coordinates of the rectangle, read from its buffer."""
    try:
        accessor = doc["accessors"][attributes["TEXCOORD_0"]]
        view = doc["bufferViews"][accessor["bufferView"]]
        uri = doc["buffers"][view["buffer"]]["uri"]
        blob = base64.b64decode(uri.split(",", 1)[1], validate=True)
        start = int(view.get("byteOffset", 0)) + int(accessor.get("byteOffset", 0))
        count = int(accessor["count"])
        if accessor["componentType"] != FLOAT or count > 65536 or start < 0:
            return None
        values = np.frombuffer(blob, dtype="<f4", count=2 * count, offset=start).reshape(-1, 2)
    except (KeyError, IndexError, TypeError, ValueError):
        return None
    u1, v1 = float(values[:, 0].max()), float(values[:, 1].max())
    return (u1, v1) if 0 < u1 <= 1 and 0 < v1 <= 1 else None
