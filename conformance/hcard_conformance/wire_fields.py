"""The fields of a protobuf message read straight from its bytes, without a protobuf runtime:
what ``format.compat`` uses to find the fields a reader kept (README V3) without trusting the
reader's own runtime to report them.

Wire format: a message is a sequence of (tag, payload); the tag is the varint
``number << 3 | wire_type``; VARINT payloads are varints, I64 8 bytes, LEN a varint length and
that many bytes, I32 4 bytes (protobuf encoding guide). Groups (wire types 3, 4) are not used
by the card schema and are an error here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from google.protobuf.descriptor import Descriptor, FieldDescriptor

from hcard.errors import HcardError

WIRE_VARINT, WIRE_FIXED64, WIRE_LEN, WIRE_FIXED32 = 0, 1, 2, 5


class WireError(HcardError, ValueError):
    """Bytes that are not a well-formed protobuf message."""


@dataclass(frozen=True)
class WireField:
    """One field occurrence: ``path`` of the message holding it (``""``: the top message,
    ``"textures[1]"``), its number, wire type and payload (the bytes after the tag)."""

    path: str
    number: int
    wire_type: int
    payload: bytes

    def encoded(self) -> bytes:
        """Tag and payload, as the field appears in its message."""
        return varint(self.number << 3 | self.wire_type) + self.payload

    def as_json(self) -> dict[str, Any]:
        """The field as the vectors' manifest lists it (``compat[].unknown``)."""
        return {"path": self.path, "number": self.number, "wire_type": self.wire_type,
                "payload_hex": self.payload.hex()}

    @classmethod
    def from_json(cls, row: dict[str, Any]) -> WireField:
        """The field a manifest row (:meth:`as_json`) lists."""
        return cls(str(row["path"]), int(row["number"]), int(row["wire_type"]),
                   bytes.fromhex(row["payload_hex"]))


def varint(value: int) -> bytes:
    """``value`` (>= 0) as a protobuf varint: 7 bits a byte, least significant first."""
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _varint(data: bytes, at: int) -> tuple[int, int]:
    """(value, next offset) of the varint at ``at``."""
    value = shift = 0
    while True:
        if at >= len(data) or shift > 63:
            raise WireError(f"truncated or overlong varint at byte {at}")
        byte = data[at]
        value |= (byte & 0x7F) << shift
        at += 1
        shift += 7
        if not byte & 0x80:
            return value, at


def _fields(data: bytes) -> list[tuple[int, int, bytes, bytes]]:
    """(number, wire type, payload, value) of every field of one message's bytes; ``value``
    is a LEN field's content (else the payload)."""
    out = []
    at = 0
    while at < len(data):
        tag, after_tag = _varint(data, at)
        number, wire_type = tag >> 3, tag & 7
        if wire_type == WIRE_VARINT:
            _, end = _varint(data, after_tag)
            payload = value = data[after_tag:end]
        elif wire_type in (WIRE_FIXED64, WIRE_FIXED32):
            end = after_tag + (8 if wire_type == WIRE_FIXED64 else 4)
            payload = value = data[after_tag:end]
        elif wire_type == WIRE_LEN:
            length, start = _varint(data, after_tag)
            end = start + length
            payload, value = data[after_tag:end], data[start:end]
        else:
            raise WireError(f"wire type {wire_type} of field {number} at byte {at}")
        if end > len(data) or number == 0:
            raise WireError(f"field {number} at byte {at} runs past the end")
        out.append((number, wire_type, payload, value))
        at = end
    return out


def unknown_fields(data: bytes, descriptor: Descriptor, path: str = "") -> list[WireField]:
    """Every field of the message ``data`` (of type ``descriptor``) and of its sub-messages
    that the descriptor does not define, in the order they appear."""
    found: list[WireField] = []
    counts: dict[int, int] = {}
    for number, wire_type, payload, value in _fields(data):
        field = descriptor.fields_by_number.get(number)
        if field is None:
            found.append(WireField(path, number, wire_type, payload))
            continue
        if field.type != FieldDescriptor.TYPE_MESSAGE or wire_type != WIRE_LEN:
            continue
        where = f"{path}.{field.name}" if path else field.name
        if field.is_repeated:
            index = counts.get(number, 0)
            counts[number] = index + 1
            where += f"[{index}]"
        found += unknown_fields(value, field.message_type, where)
    return found
