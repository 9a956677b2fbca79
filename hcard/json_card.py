"""A JSON card to its message in time and memory bounded by the card's limits.

The protobuf JSON parser (``json_format.ParseDict``) is written in Python: a 16 MiB JSON card of
5.6 million empty components ``{}`` took 41-52 s and 843 MB to read (the binary card of the same
structure: under 1.5 s), far past the bounds of spec/README.md section 4. Here the value of the
JSON (:func:`hcard.json_text.parse_json`, every ``{}`` one shared dict) becomes the message with
work bounded by the limits, not by the file:

- textures past :data:`~hcard.limits.MAX_TEXTURES` and components past
  :data:`~hcard.limits.MAX_COMPONENTS_PER_TEXTURE` are neither checked nor converted: each is
  an empty placeholder message, added in one binary merge, so the card has as many as the file
  and validation reports the count (T1, T7) as for a binary card, whose excess it does not
  examine either (section 4: "the excess elements need not be examined"). Such a card is
  invalid, so no placeholder is ever rendered;
- a repeated integer (``grid.texture_index``, up to 8.4 million in 16 MiB) is checked and added
  in one C call when it holds plain integers;
- every other field goes through ``json_format.ParseDict``, one message at a time, so numbers
  written as strings, enums by name or number and the rest of the protobuf JSON mapping read as
  the protobuf library reads them.
"""

from __future__ import annotations

from typing import Any

from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.message import Message

from hcard import limits
from hcard.json_text import (
    INTEGER_RANGES,
    JsonInputError,
    check_message_json,
    field_named,
    whole_number,
)
from hcard.v1 import card_pb2 as pb

EXAMINED = {
    pb.Card.DESCRIPTOR.fields_by_name["textures"].full_name: limits.MAX_TEXTURES,
    pb.Texture.DESCRIPTOR.fields_by_name["components"].full_name:
        limits.MAX_COMPONENTS_PER_TEXTURE,
}
"""The most elements of each repeated message field that are checked and converted; the rest
become placeholders (module docstring)."""


def card_from_json_value(value: Any) -> pb.Card:
    """The card a parsed JSON value (:func:`hcard.json_text.parse_json`) describes.

    Raises:
        JsonInputError: the value is not an object, or a field has a value of the wrong type
            or out of its range (the message names the field path).
    """
    if not isinstance(value, dict):
        raise JsonInputError("a JSON card must be an object")
    check_message_json(value, pb.Card.DESCRIPTOR, bounds=EXAMINED)
    card = pb.Card()
    _fill(card, value, "")
    return card


def _fill(message: Message, obj: dict[str, Any], path: str) -> None:
    """Set the fields ``obj`` names on ``message`` (``obj`` checked by
    :func:`check_message_json`)."""
    from google.protobuf import json_format  # 30-60 ms to import; binary cards never need it

    descriptor: Descriptor = message.DESCRIPTOR
    plain: dict[str, Any] = {}
    for key, value in obj.items():
        field = field_named(descriptor, key)
        if field is None or value is None:
            continue  # unknown fields are those of a newer minor version (rule V4)
        where = f"{path}.{field.name}" if path else field.name
        if field.type == FieldDescriptor.TYPE_MESSAGE:
            if field.is_repeated:
                _fill_repeated_messages(message, field, value, where)
            else:
                _fill(getattr(message, field.name), value, where)
        elif field.is_repeated and field.type in INTEGER_RANGES:
            getattr(message, field.name).extend(_whole_numbers(value, field, where))
        else:
            plain[key] = value
    if plain:
        try:
            json_format.ParseDict(plain, message)
        except json_format.ParseError as exc:
            raise JsonInputError(f"{path or 'the card'}: {exc}") from None


def _fill_repeated_messages(message: Message, field: FieldDescriptor, items: list[Any],
                            where: str) -> None:
    """The elements of a repeated message field: the first :data:`EXAMINED` converted, the
    others empty placeholders."""
    container = getattr(message, field.name)
    shown = EXAMINED.get(field.full_name, len(items))
    for index, item in enumerate(items[:shown]):
        _fill(container.add(), item, f"{where}[{index}]")
    excess = len(items) - shown
    if excess > 0:
        message.MergeFromString(_empty_elements(field.number, excess))


def _empty_elements(number: int, count: int) -> bytes:
    """``count`` empty elements of the repeated message field ``number`` in the binary
    encoding: its tag (wire type 2, length-delimited) and a length of 0, each."""
    tag, value = bytearray(), number << 3 | 2
    while True:
        byte, value = value & 0x7F, value >> 7
        tag.append(byte | (0x80 if value else 0))
        if not value:
            break
    return (bytes(tag) + b"\x00") * count


def _whole_numbers(items: list[Any], field: FieldDescriptor, where: str) -> list[int]:
    """The elements of a repeated integer field as ints in the field's range."""
    if set(map(type, items)) <= {int}:
        numbers = items
    else:
        numbers = [whole_number(item, f"{where}[{index}]") for index, item in enumerate(items)]
    if not numbers:
        return numbers
    low, high = INTEGER_RANGES[field.type]
    if min(numbers) < low or max(numbers) > high:
        index = next(i for i, n in enumerate(numbers) if not low <= n <= high)
        raise JsonInputError(f"{where}[{index}]: {numbers[index]} is out of range "
                             f"({low}..{high})")
    return numbers
