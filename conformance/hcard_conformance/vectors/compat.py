"""Compatibility vectors (README V3, V4, F4): valid files that a reader of format 1.0 meets in
the world, each carrying the content of one vector card.

``unknown-fields.hcard`` (V3)
    the card as a writer of a later minor (1.9) would write it: fields this version does not
    define at four depths of the message, one of them before every known field (F1: any field
    order). A reader reads it as the card; re-written as binary, it keeps every one of those
    fields, and the minor version stays 9.
``unknown-fields.json`` (V4)
    the card's JSON with keys this version does not define, at four depths, holding an object,
    an array, a number, ``true`` and ``null``: read as the card, without error.
``binary-named.json``, ``json-named.hcard`` (F4, F5)
    the binary form under a JSON name and the JSON form under a binary one: read from the
    content, as the card.

Every unknown field is listed (a :class:`~hcard_conformance.wire_fields.WireField`) so that a
check can look for it in re-written bytes without trusting the reader that wrote them.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hcard import card_io
from hcard.v1 import card_pb2 as pb
from hcard_conformance.vectors.cards import vector_cards
from hcard_conformance.wire_fields import (
    WIRE_FIXED32,
    WIRE_FIXED64,
    WIRE_LEN,
    WIRE_VARINT,
    WireField,
    varint,
)

COMPAT_CARD = "checkerboard"
"""The vector card whose content every compatibility vector carries (two textures, each with
components: unknown fields can sit at every depth)."""
LATER_MINOR = 9
"""The minor version of the writer that added the unknown fields."""

def _length_delimited(data: bytes) -> bytes:
    return varint(len(data)) + data


LEADING_FIELD = WireField("", 900, WIRE_VARINT, varint(300))
"""Written before every known field of the card (F1: readers accept any field order)."""
UNKNOWN_FIELDS: tuple[WireField, ...] = (
    LEADING_FIELD,
    WireField("", 901, WIRE_LEN, _length_delimited(b"\x08\x01\x12\x04v1.9")),
    WireField("metadata", 902, WIRE_LEN, _length_delimited(b"written by hcard 1.9")),
    WireField("textures[1]", 903, WIRE_FIXED64, bytes.fromhex("000000000000d03f")),  # 0.25
    WireField("textures[1].components[0]", 904, WIRE_FIXED32, bytes.fromhex("0000803f")),
)
"""The unknown fields of ``unknown-fields.hcard``, in the order they are written."""

UNKNOWN_JSON_KEYS: tuple[tuple[str, str, object], ...] = (
    ("", "surface_finish", {"kind": "matte", "gloss_gu": 12}),
    ("", "extensions", [1, "two", {"three": 3}]),
    ("metadata", "created_with_minor", 9),
    ("textures[1]", "roughnessHint", True),
    ("textures[1].components[0]", "envelope", None),
)
"""(object path, key, value) of the unknown keys of ``unknown-fields.json``."""


@dataclass(frozen=True)
class CompatVector:
    """One compatibility vector: a file a reader must read as the card ``card`` (with minor
    version ``minor``), under rule ``rule``."""

    name: str
    extension: str
    data: bytes
    card: str
    minor: int
    rule: str
    description: str
    unknown: tuple[WireField, ...] = ()

    @property
    def file_name(self) -> str:
        """The file's name in ``compat/``."""
        return f"{self.name}{self.extension}"


def _at(root: Any, path: str, child: Callable[[Any, str], Any]) -> Any:
    """What ``path`` (``"textures[1].components[0]"``; ``""``: ``root``) names in ``root``,
    each name looked up by ``child(node, name)`` (a message's attribute, an object's key)."""
    node = root
    for part in path.split(".") if path else []:
        name, _, index = part.partition("[")
        node = child(node, name)
        if index:
            node = node[int(index.rstrip("]"))]
    return node


def later_minor_card() -> pb.Card:
    """The compatibility card as a 1.9 writer sees it, without the unknown fields."""
    card = pb.Card()
    card.CopyFrom(next(vc.card for vc in vector_cards() if vc.name == COMPAT_CARD))
    card.version.minor = LATER_MINOR
    return card


def unknown_fields_binary() -> bytes:
    """``unknown-fields.hcard``: :data:`LEADING_FIELD`, then the card with the other unknown
    fields at the end of the messages that hold them (protobuf merges a message's fields
    wherever they appear)."""
    card = later_minor_card()
    for unknown in UNKNOWN_FIELDS:
        if unknown is not LEADING_FIELD:
            _at(card, unknown.path, getattr).MergeFromString(unknown.encoded())
    return LEADING_FIELD.encoded() + card.SerializeToString(deterministic=True)


def unknown_fields_json() -> bytes:
    """``unknown-fields.json``: the reference JSON of :func:`later_minor_card` with
    :data:`UNKNOWN_JSON_KEYS` added."""
    obj = json.loads(card_io.to_json(later_minor_card()))
    for path, key, value in UNKNOWN_JSON_KEYS:
        _at(obj, path, dict.__getitem__)[key] = value
    return (json.dumps(obj, indent=2) + "\n").encode("utf-8")


def compat_vectors() -> list[CompatVector]:
    """Every compatibility vector (module docstring)."""
    card = next(vc.card for vc in vector_cards() if vc.name == COMPAT_CARD)
    return [
        CompatVector("unknown-fields", ".hcard", unknown_fields_binary(), COMPAT_CARD,
                     LATER_MINOR, "V3",
                     "a 1.9 writer's card: five fields 1.0 does not define, at four depths, "
                     "one before every known field; re-written, every one is kept",
                     UNKNOWN_FIELDS),
        CompatVector("unknown-fields", ".json", unknown_fields_json(), COMPAT_CARD,
                     LATER_MINOR, "V4",
                     "a 1.9 writer's JSON: five keys 1.0 does not define, at four depths; "
                     "read without error"),
        CompatVector("binary-named", ".json", card_io.to_bytes(card), COMPAT_CARD,
                     card.version.minor, "F4",
                     "the binary form under a .json name: read from the content (F5)"),
        CompatVector("json-named", ".hcard", card_io.to_json(card).encode("utf-8"),
                     COMPAT_CARD, card.version.minor, "F4",
                     "the JSON form under a .hcard name: read from the content (F5)"),
    ]
