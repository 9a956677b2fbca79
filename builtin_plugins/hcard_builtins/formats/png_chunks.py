"""The chunks of a PNG file that precede its image data, read in bounded time and memory:
the header, the stated resolution (pHYs) and the ``hcard`` text chunk of the bitmap exports
(spec/interchange/bitmaps.md IB11-IB14).

Every chunk's CRC is checked, the image data's too (Pillow does not check IDAT's), reading
the file once in blocks: at most :data:`MAX_CHUNKS_BEFORE_DATA` chunks before the image data
and :data:`MAX_CHUNKS` in all. The ``hcard`` chunk is looked for only before the image data (it
must precede it, rule IB11, so that its first bytes tell the format). The pixels themselves are
Pillow's (through the image encoder's bounded loader).
"""

from __future__ import annotations

import math
import re
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from hcard import limits
from hcard.errors import AssetError
from hcard.file_errors import reading

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
HCARD_KEYWORD = b"hcard"
"""Keyword of the text chunk that carries the card of a bitmap export (IB11)."""
TEXT_CHUNKS = (b"tEXt", b"zTXt", b"iTXt")
MAX_CHUNKS_BEFORE_DATA = 1000
"""Most chunks a PNG may have before its image data (a real file has a dozen at most)."""
MAX_CHUNKS = 100_000
"""Most chunks a PNG may have in all (64 megapixels in 8 KiB IDAT chunks take about 8000)."""
_BLOCK_BYTES = 1 << 20
"""Chunk data is read this much at a time to check its CRC."""
MAX_HCARD_CHUNK_BYTES = 4 * math.ceil(limits.MAX_CARD_BYTES / 3) + 65536
"""Largest ``hcard`` chunk accepted, bytes: the base64 text of the largest card (rule F6's
16 MiB) and 64 KiB for the rest of the JSON. The same bound holds for the text a compressed
chunk inflates to."""
_KEYWORD_BYTES = 80
"""A text chunk's keyword is 1-79 bytes and a NUL."""
_POINTS_PER_INCH_METRES = 0.0254
_SIGNATURE_FORMAT = re.compile(rb'^\{\s*"format"\s*:\s*"([A-Za-z0-9_-]{1,32})"')


@dataclass(frozen=True)
class PngFacts:
    """What a PNG states before its pixels.

    Attributes:
        width, height: IHDR size, pixels.
        dpi: the pHYs resolution in dots per inch along x and y when its unit is the metre,
            else ``None``.
        hcard: the text of the ``hcard`` chunk (JSON), or ``None``.
        hcard_chunk: the type of that chunk (``"iTXt"``, ``"zTXt"``, ``"tEXt"``), or ``""``.
    """

    width: int
    height: int
    dpi: tuple[float, float] | None
    hcard: str | None
    hcard_chunk: str = ""

    @property
    def field(self) -> str:
        """The chunk named as the field of an error: ``PNG chunk iTXt "hcard"``."""
        return chunk_field(self.hcard_chunk or "iTXt")


def chunk_field(chunk_type: str) -> str:
    """The field an :class:`AssetError` about the ``hcard`` chunk names."""
    return f'PNG chunk {chunk_type} "hcard"'


def is_png(head: bytes) -> bool:
    """Whether ``head`` starts with the PNG signature."""
    return head.startswith(PNG_SIGNATURE)


def sniff_hcard_format(head: bytes) -> str | None:
    """The ``format`` an uncompressed ``hcard`` iTXt or tEXt chunk within ``head`` (a file's
    first bytes) names first in its JSON (IB12), or ``None``: a cheap look for
    :meth:`recognises`, which never raises; the full check is :func:`read_png_facts`'s."""
    if not is_png(head):
        return None
    at = len(PNG_SIGNATURE)
    for _ in range(MAX_CHUNKS_BEFORE_DATA):
        if at + 8 > len(head):
            return None
        length, kind = struct.unpack(">I4s", head[at:at + 8])
        data = head[at + 8:at + 8 + min(length, 4096)]
        if kind == b"IDAT":
            return None
        if kind in (b"iTXt", b"tEXt") and data.startswith(HCARD_KEYWORD + b"\0"):
            text = data[len(HCARD_KEYWORD) + 1:]
            if kind == b"iTXt":
                if text[:1] != b"\0":  # compressed: not sniffed
                    return None
                parts = text[2:].split(b"\0", 2)
                if len(parts) < 3:
                    return None
                text = parts[2]
            match = _SIGNATURE_FORMAT.match(text)
            return match.group(1).decode("ascii") if match else None
        at += 12 + length
    return None


def read_png_facts(path: Path) -> PngFacts:
    """The header, resolution and ``hcard`` chunk of the PNG at ``path``.

    Raises:
        AssetError: not a PNG, truncated before its image data, no IHDR first, more than
            :data:`MAX_CHUNKS_BEFORE_DATA` chunks before the data, or an ``hcard`` chunk that
            is too large, fails its CRC, is compressed badly, is not text or appears twice.
    """
    with reading(path, AssetError, "a PNG bitmap"), path.open("rb") as stream:
        return _walk(stream, path)


def _walk(stream: BinaryIO, path: Path) -> PngFacts:
    signature = stream.read(len(PNG_SIGNATURE))
    if signature != PNG_SIGNATURE:
        raise AssetError("not a PNG file (no PNG signature)", source=path, field="signature")
    width = height = -1
    dpi: tuple[float, float] | None = None
    hcard: str | None = None
    hcard_type = ""
    before_data = True
    for index in range(MAX_CHUNKS):
        header = stream.read(8)
        if len(header) < 8:
            where = "before its image data" if before_data else "before its IEND chunk"
            raise AssetError(f"the file ends {where} (truncated PNG)", source=path,
                             field=f"PNG chunk {index}")
        length, raw_kind = struct.unpack(">I4s", header)
        kind = raw_kind.decode("latin-1")
        if index == 0:
            width, height = _ihdr(stream, path, raw_kind, length)
            continue
        if raw_kind == b"IDAT":
            before_data = False
        elif before_data and index > MAX_CHUNKS_BEFORE_DATA:
            raise AssetError(f"more than {MAX_CHUNKS_BEFORE_DATA} chunks before the image "
                             "data", source=path, field="PNG chunks")
        if before_data and raw_kind in TEXT_CHUNKS and _keyword(stream, length) == HCARD_KEYWORD:
            if hcard is not None:
                raise AssetError("a second hcard chunk: a PNG carries at most one (IB11)",
                                 source=path, field=chunk_field(kind))
            hcard, hcard_type = _hcard_text(stream, path, raw_kind, length), kind
            continue
        data = _checked_data(stream, path, raw_kind, length, 9)
        if before_data and raw_kind == b"pHYs" and length == 9:
            dpi = _phys(data)
        if raw_kind == b"IEND":
            return PngFacts(width, height, dpi, hcard, hcard_type)
    raise AssetError(f"more than {MAX_CHUNKS} chunks", source=path, field="PNG chunks")


def _keyword(stream: BinaryIO, length: int) -> bytes:
    """The keyword of the text chunk whose data starts at the stream's position (which it
    leaves there)."""
    start = stream.tell()
    keyword = stream.read(min(length, _KEYWORD_BYTES)).split(b"\0", 1)[0]
    stream.seek(start)
    return keyword


def _checked_data(stream: BinaryIO, path: Path, kind: bytes, length: int, keep: int) -> bytes:
    """The first ``keep`` bytes of a chunk's data, after reading all of it in blocks and its
    CRC, which must match (IB7)."""
    field = f"PNG chunk {kind.decode('latin-1')}"
    crc, left, kept = zlib.crc32(kind), length, b""
    while left:
        block = stream.read(min(left, _BLOCK_BYTES))
        if not block:
            raise AssetError("the file ends inside the chunk (truncated PNG)", source=path,
                             field=field)
        crc = zlib.crc32(block, crc)
        if len(kept) < keep:
            kept += block[:keep - len(kept)]
        left -= len(block)
    stored = stream.read(4)
    if len(stored) < 4:
        raise AssetError("the file ends inside the chunk (truncated PNG)", source=path,
                         field=field)
    if struct.unpack(">I", stored)[0] != crc:
        raise AssetError("CRC mismatch: the chunk is corrupt", source=path, field=field)
    return kept


def _ihdr(stream: BinaryIO, path: Path, kind: bytes, length: int) -> tuple[int, int]:
    if kind != b"IHDR" or length != 13:
        raise AssetError("the first chunk is not a 13-byte IHDR (corrupt PNG)", source=path,
                         field="PNG chunk IHDR")
    data = _checked_data(stream, path, kind, length, 13)
    width, height = struct.unpack(">II", data[:8])
    return int(width), int(height)


def _phys(data: bytes) -> tuple[float, float] | None:
    """Dots per inch of a pHYs chunk whose unit is the metre; ``None`` for no unit."""
    if len(data) < 9:
        return None
    x, y, unit = struct.unpack(">IIB", data)
    if unit != 1 or x == 0 or y == 0:
        return None
    return x * _POINTS_PER_INCH_METRES, y * _POINTS_PER_INCH_METRES


def _hcard_text(stream: BinaryIO, path: Path, kind: bytes, length: int) -> str:
    """The text of the ``hcard`` chunk starting at the stream's position (its data)."""
    field = chunk_field(kind.decode("latin-1"))
    if length > MAX_HCARD_CHUNK_BYTES:
        raise AssetError(f"{length} bytes, over the limit of {MAX_HCARD_CHUNK_BYTES} bytes "
                         "(the base64 of the largest card, rule F6, and its JSON)",
                         source=path, field=field)
    data = stream.read(length)
    crc = stream.read(4)
    if len(data) < length or len(crc) < 4:
        raise AssetError("the file ends inside the chunk (truncated PNG)", source=path,
                         field=field)
    if struct.unpack(">I", crc)[0] != zlib.crc32(kind + data):
        raise AssetError("CRC mismatch: the chunk is corrupt", source=path, field=field)
    body = data[len(HCARD_KEYWORD) + 1:]
    if kind == b"tEXt":
        return body.decode("latin-1")
    if kind == b"zTXt":
        if body[:1] != b"\0":
            raise AssetError("unknown compression method (PNG knows 0, zlib)", source=path,
                             field=field)
        return _utf8(_inflate(body[1:], path, field), path, field)
    if len(body) < 2 or body[1:2] != b"\0" or body[:1] not in (b"\0", b"\1"):
        raise AssetError("bad iTXt compression flag or method", source=path, field=field)
    parts = body[2:].split(b"\0", 2)
    if len(parts) < 3:
        raise AssetError("iTXt without its language tag and translated keyword", source=path,
                         field=field)
    text = parts[2]
    return _utf8(_inflate(text, path, field) if body[:1] == b"\1" else text, path, field)


def _inflate(data: bytes, path: Path, field: str) -> bytes:
    """zlib ``data`` inflated to at most :data:`MAX_HCARD_CHUNK_BYTES` bytes."""
    inflater = zlib.decompressobj()
    try:
        out = inflater.decompress(data, MAX_HCARD_CHUNK_BYTES + 1)
    except zlib.error as exc:
        raise AssetError(f"corrupt compressed text ({exc})", source=path, field=field) from None
    if len(out) > MAX_HCARD_CHUNK_BYTES or inflater.unconsumed_tail:
        raise AssetError(f"inflates to more than {MAX_HCARD_CHUNK_BYTES} bytes", source=path,
                         field=field)
    if not inflater.eof:
        raise AssetError("truncated compressed text", source=path, field=field)
    return out


def _utf8(data: bytes, path: Path, field: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise AssetError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", source=path,
                         field=field) from None
