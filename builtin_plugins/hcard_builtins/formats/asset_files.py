"""Reading another tool's asset file: at most a stated number of bytes, and every failure one
:class:`~hcard.errors.AssetError` line naming the file (spec/interchange.md IX6)."""

from __future__ import annotations

from pathlib import Path

from hcard.bounded_read import InputTooLarge, read_bounded
from hcard.errors import AssetError
from hcard.file_errors import read_reason


def read_asset(source: Path, limit: int, what: str) -> bytes:
    """The bytes of ``source``, ``what`` it is in words (``"a .haps file"``); AssetError when it
    is missing, unreadable or larger than ``limit`` bytes (read no further than that)."""
    try:
        return read_bounded(source, limit)
    except InputTooLarge as exc:
        raise AssetError(str(exc), source=source) from None
    except OSError as exc:
        raise AssetError(read_reason(exc, what), source=source) from None
