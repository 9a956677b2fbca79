"""Hostile and broken PNGs given to the bitmap importers: each fails in bounded time and memory
with one line naming the file, the field (the chunk) and the reason
(spec/interchange/bitmaps.md IB7, IB11-IB14)."""

from __future__ import annotations

import base64
import io
import json
import struct
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hcard import build
from hcard.card_io import to_bytes
from hcard.errors import AssetError, ImageError
from hcard_builtins.formats.bitmaps import TanvasExporter, TanvasImporter, TPadImporter
from hcard_builtins.formats.png_chunks import MAX_HCARD_CHUNK_BYTES
from tests.interchange.bitmap_helpers import save_png

FIELD = 'PNG chunk iTXt "hcard"'


def chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk with its CRC."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_with(*extra: bytes, width: int = 4, height: int = 4,
             declared: tuple[int, int] | None = None) -> bytes:
    """An 8-bit gray PNG of ``width`` x ``height`` black pixels with ``extra`` chunks after
    IHDR; its header declares ``declared`` (width, height) instead when given."""
    ihdr = struct.pack(">IIBBBBB", *(declared or (width, height)), 8, 0, 0, 0, 0)
    rows = b"".join(b"\0" + bytes(width) for _ in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + b"".join(extra)
            + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


def hcard_chunk(text: str | bytes) -> bytes:
    """An uncompressed iTXt chunk ``hcard`` holding ``text``."""
    body = text.encode() if isinstance(text, str) else text
    return chunk(b"iTXt", b"hcard\0\0\0\0\0" + body)


def extension(**changes: object) -> str:
    """A valid chunk JSON for a 4 x 4 px black Tanvas bitmap, with ``changes``."""
    card = build.card(4.0, 4.0, taxtel_mm=2.0, textures=[build.texture(1.0, channel="ev")])
    value: dict[str, object] = {
        "format": "tanvas", "channel": "ev", "friction_range": [1.0, 1.6], "px_per_mm": 1.0,
        "pixels_sha256": "0" * 64, "card": base64.b64encode(to_bytes(card)).decode()}
    value.update(changes)
    return json.dumps(value)


def read(tmp_path: Path, data: bytes, importer: object = None) -> None:
    path = tmp_path / "hostile.png"
    path.write_bytes(data)
    (importer or TanvasImporter()).read(path)  # type: ignore[attr-defined]


@pytest.mark.parametrize(("text", "member", "reason"), [
    ("[1, 2]", "", "not a JSON object"),
    ("{\"format\": ", "", "not valid JSON"),
    (extension(card="!!not base64!!"), "card", "not base64"),
    (extension(card=base64.b64encode(b"\xff\xff\xff").decode()), "card", "not a valid card"),
    (extension(card=base64.b64encode(to_bytes(build.card(
        4.0, 4.0, taxtel_mm=2.0, textures=[build.texture(9.0, channel="ev")]))).decode()),
     "card", "not a valid card"),
    (extension(friction_range=[1.6, 1.0]), "friction_range", "LO < HI"),
    (extension(friction_range=["a", 2]), "friction_range", "two numbers"),
    (extension(px_per_mm=-1), "px_per_mm", "above 0"),
    (extension(channel="xx"), "channel", "must be one of uv, ev, bipolar"),
    (extension(pixels_sha256="abc"), "pixels_sha256", "64 lower-case hex"),
    (json.dumps({"format": "tanvas"}), "", "missing member(s) channel, friction_range"),
    (extension(format="tpad", channel="uv"), "format", "import it with --from tpad"),
])
def test_a_bad_hcard_chunk_is_an_asset_error_naming_the_chunk(tmp_path: Path, text: str,
                                                              member: str, reason: str):
    """IB12, IB14: every fault of the chunk's JSON names the chunk and the member."""
    with pytest.raises(AssetError) as caught:
        read(tmp_path, png_with(hcard_chunk(text)))
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'hostile.png'}: {FIELD}")
    assert f'"hcard" {member}'.rstrip() in message and reason in message


def test_a_huge_hcard_chunk_is_refused_before_it_is_read(tmp_path: Path):
    """IB14: a chunk over MAX_HCARD_CHUNK_BYTES (22.4 MB: the base64 of a 16 MiB card) is
    refused by its declared length, real (a file of that size) or not (a length of 2 GB in a
    100-byte file), in well under a second."""
    big = hcard_chunk(b"x" * (MAX_HCARD_CHUNK_BYTES + 1 - 10))
    declared = (struct.pack(">I", 0x7FFFFFFF) + b"iTXt" + b"hcard\0\0\0\0\0" + bytes(50))
    for data in (png_with(big), png_with() [:33] + declared):
        started = time.perf_counter()
        with pytest.raises(AssetError, match=f"{FIELD}: .* bytes, over the limit of "
                                             f"{MAX_HCARD_CHUNK_BYTES} bytes"):
            read(tmp_path, data)
        assert time.perf_counter() - started < 1.0


def test_a_corrupt_or_repeated_or_badly_compressed_hcard_chunk_is_refused(tmp_path: Path):
    """IB11, IB14: a CRC mismatch, a second hcard chunk, a compressed text that does not
    inflate or inflates past the limit (a zlib bomb of 23 MB from 23 kB)."""
    good = hcard_chunk(extension())
    corrupt = good[:-1] + bytes([good[-1] ^ 1])
    with pytest.raises(AssetError, match=f"{FIELD}: CRC mismatch"):
        read(tmp_path, png_with(corrupt))
    with pytest.raises(AssetError, match=f"{FIELD}: a second hcard chunk"):
        read(tmp_path, png_with(good, good))
    broken = chunk(b"iTXt", b"hcard\0\1\0\0\0" + b"not zlib")
    with pytest.raises(AssetError, match=f"{FIELD}: corrupt compressed text"):
        read(tmp_path, png_with(broken))
    bomb = chunk(b"zTXt", b"hcard\0\0" + zlib.compress(b" " * (MAX_HCARD_CHUNK_BYTES + 10), 9))
    assert len(bomb) < 100_000
    with pytest.raises(AssetError, match='PNG chunk zTXt "hcard": inflates to more than'):
        read(tmp_path, png_with(bomb))


def test_broken_pngs_fail_with_one_clear_line(tmp_path: Path):
    """IB7: not a PNG, truncated in the header, before the pixels and in them, a corrupt
    image-data CRC (Pillow does not check it), 0 x 0, and a decompression bomb (40000 x 40000
    declared in 100 bytes)."""
    path = tmp_path / "hostile.png"
    cases: list[tuple[bytes, type[Exception], str]] = [
        (b"GIF89a" + bytes(40), AssetError, "signature: not a PNG file"),
        (png_with()[:20], AssetError,
         "PNG chunk IHDR: the file ends inside the chunk (truncated PNG)"),
        (png_with()[:37], AssetError, "the file ends before its image data"),
        (png_with(width=0, height=0), ImageError, "empty image (0 x 0 pixels)"),
        (png_with(declared=(40000, 40000)), ImageError,
         "40000 x 40000 = 1600000000 pixels exceed the limit of 64000000 pixels"),
    ]
    data = png_with()
    at = data.index(b"IDAT")
    length = struct.unpack(">I", data[at - 4:at])[0]
    crc_at = at + 4 + length
    cases.append((data[:crc_at] + bytes(4) + data[crc_at + 4:], AssetError,
                  "PNG chunk IDAT: CRC mismatch: the chunk is corrupt"))
    truncated = png_with(width=64, height=64)
    cases.append((truncated[:-30], AssetError,
                  "PNG chunk IDAT: the file ends inside the chunk (truncated PNG)"))
    cases.append((truncated[:-12], AssetError,
                  "PNG chunk 2: the file ends before its IEND chunk (truncated PNG)"))
    for content, error, reason in cases:
        path.write_bytes(content)
        started = time.perf_counter()
        with pytest.raises(error) as caught:
            TanvasImporter().read(path)
        assert str(caught.value).startswith(str(path)) and reason in str(caught.value), (
            reason, str(caught.value))
        assert "\n" not in str(caught.value)
        assert time.perf_counter() - started < 2.0


def test_many_chunks_before_the_data_are_refused(tmp_path: Path):
    """IB11: a reader walks at most 1000 chunks before the image data."""
    with pytest.raises(AssetError, match="PNG chunks: more than 1000 chunks before the image"):
        read(tmp_path, png_with(*[chunk(b"tEXt", b"k\0v")] * 1001))


def test_a_real_export_with_its_chunk_read_by_the_other_format_is_refused(tmp_path: Path):
    """IB12: a Tanvas export read as TPad would mean other friction: the error says so."""
    card = build.card(4.0, 4.0, taxtel_mm=2.0, textures=[build.texture(1.3, channel="ev")])
    path = tmp_path / "t.png"
    path.write_bytes(TanvasExporter().write(card).files[0][1])
    with pytest.raises(AssetError, match=f"{FIELD} format: the chunk says format tanvas"):
        TPadImporter().read(path)
    assert TPadImporter().read(path, embedded=False).stats["embedded_card"] is False
    with Image.open(io.BytesIO(path.read_bytes())) as image:
        assert np.asarray(image).max() == 128
    assert save_png(np.zeros((2, 2), dtype=np.uint8), tmp_path / "z.png").exists()
