"""Reading and writing haptic cards: binary protobuf (``.hcard``) and the JSON mapping.

The binary form is the plain serialised ``hcard.v1.Card`` message, readable by any protobuf
tool. The JSON form is the protobuf JSON mapping with the proto field names. ``load`` detects
the form from the content, not the file name. Every failure raises :class:`CardError` (or its
subclass :class:`CardValidationError`) naming the file, the field and the reason.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Literal

import hcard.limits as limits
from hcard.atomic import write_atomically
from hcard.bounded_read import STDIN, InputTooLarge, read_bounded, read_bounded_stream
from hcard.errors import CardError
from hcard.file_errors import read_reason, write_reason
from hcard.json_card import card_from_json_value
from hcard.json_text import JsonInputError, parse_json
from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid

CardFormat = Literal["binary", "json"]
MEDIA_TYPE = "application/vnd.hcard+protobuf"
JSON_MEDIA_TYPE = "application/vnd.hcard+json"
FILE_EXTENSION = ".hcard"


def format_for_path(path: str | os.PathLike[str]) -> CardFormat:
    """The format a file name asks for: ``.json`` (including ``.hcard.json``) is JSON."""
    return "json" if str(path).lower().endswith(".json") else "binary"


def looks_like_json(data: bytes) -> bool:
    """True when ``data`` starts (after white space and a UTF-8 BOM) with ``{``.

    A binary card never does: ``{`` would be the deprecated start-group tag of field 15.
    """
    return data.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"{")


def card_from_bytes(data: bytes, *, source: str | os.PathLike[str] | None = None) -> pb.Card:
    """Parse a card from binary or JSON bytes (detected from the content). Does not validate."""
    if not data:
        raise CardError("empty input: no card bytes", source=source)
    if len(data) > limits.MAX_CARD_BYTES:
        raise CardError(
            f"{len(data)} bytes exceed the card size limit of {limits.MAX_CARD_BYTES}",
            source=source,
        )
    if looks_like_json(data):
        return _card_from_json_bytes(data, source)
    card = pb.Card()
    try:
        card.ParseFromString(data)
    except Exception as exc:
        raise CardError(f"corrupt or truncated card bytes ({exc})", source=source) from None
    return card


def _card_from_json_bytes(data: bytes, source: str | os.PathLike[str] | None) -> pb.Card:
    """A JSON card, read in time and memory bounded by the limits (:mod:`hcard.json_card`)."""
    try:
        value = parse_json(data, share_empty=True)
    except JsonInputError as exc:
        raise CardError(f"not valid JSON ({exc})", source=source) from None
    try:
        return card_from_json_value(value)
    except JsonInputError as exc:
        raise CardError(f"JSON does not match the card schema ({exc})", source=source) from None


def check_version(card: pb.Card, *, source: str | os.PathLike[str] | None = None) -> None:
    """Reject a card whose major version this reader does not implement (spec rule V1)."""
    if not card.HasField("version"):
        raise CardError(
            "missing format version (not an hcard card?)", source=source, path="version"
        )
    major = card.version.major
    if major != limits.FORMAT_MAJOR:
        raise CardError(
            f"unsupported major version {major}.{card.version.minor}: this reader implements "
            f"major version {limits.FORMAT_MAJOR}",
            source=source,
            path="version.major",
        )


def parse_card(
    data: bytes, *, source: str | os.PathLike[str] | None = None, check: bool = True
) -> pb.Card:
    """Parse card bytes, check the version and (when ``check``) validate; raise on failure."""
    card = card_from_bytes(data, source=source)
    check_version(card, source=source)
    return require_valid(card, source=source) if check else card


def read_card_file(path: str | os.PathLike[str]) -> bytes:
    """The bytes of a card file (``-``: standard input); :class:`CardError` when missing,
    unreadable or too large."""
    if str(path) == STDIN:
        try:
            return read_bounded_stream(sys.stdin.buffer, limits.MAX_CARD_BYTES)
        except InputTooLarge as exc:
            raise CardError(f"{exc} (the card size limit, rule F6)", source="<stdin>") from None
    file = Path(path)
    try:
        return read_bounded(file, limits.MAX_CARD_BYTES)
    except InputTooLarge as exc:
        raise CardError(f"{exc} (the card size limit, rule F6)", source=file) from None
    except OSError as exc:
        raise CardError(read_reason(exc, "a card file"), source=file) from None


def load(path: str | os.PathLike[str], *, check: bool = True) -> pb.Card:
    """Read a card file (binary or JSON), check its version and validate it.

    Raises:
        CardError: the file is missing, unreadable, too large, corrupt, of an unknown major
            version, or (with ``check``) invalid, in which case it is a
            :class:`CardValidationError` listing every problem.
    """
    return parse_card(read_card_file(path), source=path, check=check)


def to_bytes(card: pb.Card) -> bytes:
    """Binary serialisation (deterministic: the same card always gives the same bytes)."""
    return card.SerializeToString(deterministic=True)


def to_json(card: pb.Card) -> str:
    """JSON mapping with proto field names, every field written, enums by name."""
    from google.protobuf import json_format  # imported here: binary cards never need it

    return (
        json_format.MessageToJson(
            card,
            preserving_proto_field_name=True,
            always_print_fields_with_no_presence=True,
            indent=2,
        )
        + "\n"
    )


def dumps(card: pb.Card, fmt: CardFormat = "binary") -> bytes:
    """Serialise ``card`` in the given format."""
    return to_json(card).encode("utf-8") if fmt == "json" else to_bytes(card)


def checked_bytes(card: pb.Card, path: str | os.PathLike[str], *, fmt: CardFormat | None = None,
                  check: bool = True) -> bytes:
    """The bytes :func:`save` writes to ``path`` (the format from its name unless given),
    the card validated first when ``check``: for a caller that writes them with other files.

    Raises:
        CardValidationError: ``check`` and the card is invalid.
    """
    if check:
        require_valid(card, source=path)
    return dumps(card, fmt or format_for_path(path))


def save(
    card: pb.Card,
    path: str | os.PathLike[str],
    *,
    fmt: CardFormat | None = None,
    check: bool = True,
) -> None:
    """Write ``card`` to ``path`` atomically; the format follows the file name unless given.

    With ``check`` the card is validated first and an invalid card is not written. On any
    failure the previous file at ``path`` is left intact.
    """
    data = checked_bytes(card, path, fmt=fmt, check=check)
    try:
        write_atomically(path, data)
    except OSError as exc:
        raise CardError(write_reason(exc), source=path) from None
