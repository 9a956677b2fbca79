"""Cards built byte by byte to the 16 MiB limit (spec/README.md F6) with a structure whose
problems multiply: millions of empty textures, of empty components, of out-of-range texture
indices. Each is a valid protobuf encoding of ``hcard.v1.Card``; none is a valid card."""

from __future__ import annotations

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


HOSTILE_CARDS = {
    "empty-textures": empty_textures,
    "empty-components": empty_components,
    "indices-out-of-range": indices_out_of_range,
}
"""Name -> builder of each hostile card."""


def empty_components_json(size: int = 2 * 1024 * 1024) -> bytes:
    """A card in the JSON form (README.md F5) of ``size`` bytes whose one texture holds as many
    empty components (``{}``, 3 bytes each with the comma) as fit: ~699 000 at 2 MiB, the
    largest card the reference device stores. Invalid (a component needs a frequency)."""
    card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    head, tail = card_io.to_json(card).split('"components": []')
    count = (size - len(head) - len(tail) - len('"components": []')) // 3
    text = head + '"components": [' + ",".join(["{}"] * count) + "]" + tail
    return text.encode().ljust(size)
