"""Reading a file from a stranger with a bound on how much of it is read.

``Path.read_bytes`` trusts ``stat``: a regular file's size is known before reading, but a
character device (``/dev/zero``), a FIFO or a ``/proc`` file reports 0 and is read until memory
runs out (``hcard validate /dev/zero`` ended in MemoryError). :func:`read_bounded` reads at
most one byte past the limit whatever the file is, so the memory a reader spends is bounded by
the limit of its format (spec/README.md section 4, "Limits").
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from hcard.errors import InputError

MAX_TEXT_FILE_BYTES = 512 * 1024 * 1024
"""Largest finger-track or measurement CSV file a reader accepts, bytes (512 MiB: an hour of
a 1 kHz tribometer recording with 12 columns is about 300 MB)."""
MAX_JSON_FILE_BYTES = 16 * 1024 * 1024
"""Largest JSON side file (a device profile, a measurement's conditions sidecar) a reader
accepts, bytes (16 MiB, the card file limit)."""
DEFAULT_MAX_PIXELS = 64_000_000
"""Largest image an encoder decodes by default: 64 megapixels (a guard against decompression
bombs; ``hcard encode --max-pixels`` raises it)."""
DECODE_BYTES_PER_ALLOWED_PIXEL = 4
"""Memory an encoder may spend decoding an image, bytes per pixel of its pixel limit (256 MB
at the default): checked from the header before decoding, with the bytes a pixel of the file's
mode takes (``hcard_builtins.image.loading.decode_bytes``)."""


class InputTooLarge(InputError, ValueError):
    """A file holds more than a reader's limit.

    Attributes:
        limit: the limit, bytes.
        size: the file's size when ``stat`` knows it (a regular file), else None (a device or
            a pipe: more than ``limit`` bytes were offered).
    """

    def __init__(self, limit: int, size: int | None) -> None:
        self.limit = limit
        self.size = size
        if size is not None:
            text = f"{size} bytes exceed the limit of {limit} bytes"
        else:
            text = (f"more than {limit} bytes (not a regular file: a device or a pipe, read "
                    "up to the limit)")
        super().__init__(text)


def read_bounded(path: str | os.PathLike[str], limit: int) -> bytes:
    """The bytes of ``path``, at most ``limit`` of them.

    A regular file larger than ``limit`` is refused before anything is read; any other file
    (a device, a FIFO) is read up to ``limit + 1`` bytes and refused if it offers more.

    Raises:
        InputTooLarge: the file holds more than ``limit`` bytes.
        OSError: the file cannot be opened or read (missing, a directory, no permission).
    """
    with Path(path).open("rb") as file:
        info = os.fstat(file.fileno())
        if stat.S_ISDIR(info.st_mode):
            raise IsADirectoryError(21, "Is a directory", str(path))
        regular = stat.S_ISREG(info.st_mode)
        if regular and info.st_size > limit:
            raise InputTooLarge(limit, info.st_size)
        data = file.read(limit + 1)
    if len(data) > limit:
        raise InputTooLarge(limit, None if not regular else len(data))
    return data


BYTE_ORDER_MARK = "\ufeff"
"""The byte-order mark some editors (Notepad, Excel) put at the start of a UTF-8 file."""


def utf8_text(data: bytes) -> str:
    """The text of a file from a stranger: UTF-8, a leading byte-order mark dropped. The one
    place every reader decodes (cards, tracks, measurements and their sidecars, profiles),
    so a file saved with a BOM reads the same everywhere (spec/README.md F3, TK1, MF1, MF8).

    Raises:
        UnicodeDecodeError: ``data`` is not UTF-8.
    """
    return data.decode("utf-8-sig")


STDIN = "-"
"""The name that stands for standard input (and output) on the command line."""


def read_bounded_stream(stream: BinaryIO, limit: int) -> bytes:
    """At most ``limit`` bytes of ``stream`` (standard input, a pipe).

    Raises:
        InputTooLarge: the stream offers more than ``limit`` bytes.
    """
    data = stream.read(limit + 1)
    if len(data) > limit:
        raise InputTooLarge(limit, None)
    return data
