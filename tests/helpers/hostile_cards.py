"""Cards built byte by byte to the 16 MiB limit (spec/README.md F6) with a structure whose
problems multiply: millions of empty textures, of empty components, of out-of-range texture
indices, a description of 16.7 million control characters, and the JSON form of the first two.
Each is a valid protobuf encoding (or protobuf JSON mapping) of ``hcard.v1.Card``; none is a
valid card."""

from __future__ import annotations

import json
import struct
import zlib

from hcard import build, card_io, limits


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte, value = value & 0x7F, value >> 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _field(number: int, payload: bytes) -> bytes:
    """A length-delimited field."""
    return _varint(number << 3 | 2) + _varint(len(payload)) + payload


def _valid_head() -> bytes:
    """version, metadata, surface and a 1 x 1 grid of a small valid card, without textures."""
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    del card.textures[:]
    card.grid.ClearField("texture_index")
    return card_io.to_bytes(card)


def _room(head: bytes, slack: int = 16) -> int:
    return limits.MAX_CARD_BYTES - len(head) - slack


def empty_textures(count: int | None = None) -> bytes:
    """``count`` empty textures (field 5, length 0: 2 bytes each); by default as many as fit
    in the size limit, ~8.4 million."""
    head = _valid_head()
    return head + b"\x2a\x00" * (_room(head) // 2 if count is None else count)


def empty_components(count: int | None = None) -> bytes:
    """One texture holding ``count`` empty components; by default as many as fit, ~8.4
    million."""
    head = _valid_head()
    count = (_room(head) - 8) // 2 if count is None else count
    texture = b"\x2a\x00" * count  # Texture.components (field 5), empty
    return head + _field(5, texture)


def indices_out_of_range(count: int | None = None) -> bytes:
    """One texture and ``count`` texture indices equal to 1 (packed, 1 byte each), all outside
    a palette of 1; by default as many as fit, ~16.8 million."""
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    card.grid.ClearField("texture_index")
    head = card_io.to_bytes(card)
    count = _room(head) - 16 if count is None else count
    grid_extra = _field(5, b"\x01" * count)  # TaxtelGrid.texture_index, packed
    return head + _field(4, grid_extra)  # a second grid field merges into the first


def control_description(count: int | None = None) -> bytes:
    """A small card whose metadata description is control characters (U+0001, one byte each,
    shown as a 4-character escape), ``count`` more than rule M1 allows; by default as many as
    fit, ~16.7 million in all."""
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    head = card_io.to_bytes(card)
    length = _room(head) - 16 if count is None else limits.MAX_TEXT_LENGTH + count
    return head + _field(2, _field(5, b"\x01" * length))  # Card.metadata.description


def _json_with_array(path: tuple[str | int, ...], unit: str, count: int | None,
                     size: int = limits.MAX_CARD_BYTES) -> bytes:
    """The JSON form of a small valid card whose field at ``path`` is an array of ``count``
    copies of ``unit``; by default as many as fit in ``size`` bytes (the format's limit)."""
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    obj = json.loads(card_io.to_json(card))
    target = obj
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = "@"
    text = json.dumps(obj, separators=(",", ":"))
    count = (size - len(text)) // (len(unit) + 1) if count is None else count
    return text.replace('"@"', "[" + ",".join([unit] * count) + "]").encode()


def json_empty_components(count: int | None = None,
                          size: int = limits.MAX_CARD_BYTES) -> bytes:
    """A JSON card whose one texture holds ``count`` empty components ``{}``; by default as
    many as fit in ``size`` bytes: ~5.6 million in the format's 16 MiB, ~699 000 in the 2 MiB
    the reference device stores. Invalid (a component needs a frequency)."""
    return _json_with_array(("textures", 0, "components"), "{}", count, size)


def json_empty_textures(count: int | None = None) -> bytes:
    """A JSON card of ``count`` empty textures ``{}``; by default as many as fit, ~5.6
    million."""
    return _json_with_array(("textures",), "{}", count)


HOSTILE_CARDS = {
    "empty-textures": empty_textures,
    "empty-components": empty_components,
    "indices-out-of-range": indices_out_of_range,
    "control-description": control_description,
    "json-empty-components": json_empty_components,
    "json-empty-textures": json_empty_textures,
}
"""Name -> builder of each hostile card."""


# -- images that declare more than they hold -----------------------------------------------------
def _chunk(kind: bytes, payload: bytes) -> bytes:
    return (struct.pack(">I", len(payload)) + kind + payload
            + struct.pack(">I", zlib.crc32(kind + payload)))


def png_declaring(width: int, height: int, *, bit_depth: int = 8, colour_type: int = 0,
                  rows: int = 0) -> bytes:
    """A PNG whose header declares ``width`` x ``height`` pixels (``colour_type`` 0 gray, 2 RGB,
    6 RGBA, at ``bit_depth`` bits a sample) and whose data holds the first ``rows`` rows, zero
    (a file of a few hundred bytes: decoding it past those rows fails as truncated; with
    ``rows=height`` it is a whole image, all black, which zlib compresses ~1000-fold)."""
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[colour_type]
    row = b"\x00" * (1 + width * channels * bit_depth // 8)
    packer = zlib.compressobj(9)
    data = b"".join(packer.compress(row) for _ in range(rows)) + packer.flush()
    header = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", data)
            + _chunk(b"IEND", b""))
