"""JSON from strangers, parsed with bounds and checked strictly against the card schema.

:func:`parse_json` is ``json.loads`` with its failures turned into one :class:`JsonInputError`
that says where and why: invalid JSON (line and column), text that is not UTF-8, the
non-standard ``NaN`` and ``Infinity`` literals, a key given twice in one object (``json.loads``
kept the last, so ``{"width_mm": 10, "width_mm": 1000}`` read as 1000 m), nesting deeper than
:data:`MAX_JSON_DEPTH` (5000 nested arrays ended in a RecursionError traceback), and integers
longer than Python converts (a 5000-digit integer ended in a ValueError traceback). A leading
UTF-8 byte-order mark is dropped (:func:`hcard.bounded_read.utf8_text`), for every JSON input
alike.

:func:`check_message_json` walks a JSON object against a protobuf message descriptor before the
protobuf JSON parser sees it, because that parser is lenient where the card format is not
(spec/README.md F3, F7): it takes ``true`` for a double, ``true`` or ``1.5`` for an enum, and
drops an enum name it does not know (``"CHANNEL_EVV"``) when unknown fields are ignored, so the
component then played on its texture's channel instead of being refused by rule C5. It also
refuses one field given under both its names (``widthMm`` and ``width_mm``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any

from google.protobuf.descriptor import Descriptor, FieldDescriptor

from hcard.bounded_read import BYTE_ORDER_MARK, utf8_text
from hcard.errors import InputError

MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays and objects a JSON input may have (a card needs 5)."""

_NUMBER_TEXT = re.compile(r"-?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
"""A number written as a JSON string (the protobuf JSON mapping allows ``"1.5"``): ASCII
digits only, where ``float()`` also takes ``"0.0_2"``, Arabic-Indic and full-width digits."""
_INTEGER_TEXT = re.compile(r"-?[0-9]+")
_SPECIAL_DOUBLES = frozenset({"NaN", "Infinity", "-Infinity"})

_FLOATING = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)
_SIGNED_32, _SIGNED_64 = (-(2**31), 2**31 - 1), (-(2**63), 2**63 - 1)
INTEGER_RANGES = {
    FieldDescriptor.TYPE_INT32: _SIGNED_32, FieldDescriptor.TYPE_SINT32: _SIGNED_32,
    FieldDescriptor.TYPE_SFIXED32: _SIGNED_32,
    FieldDescriptor.TYPE_UINT32: (0, 2**32 - 1), FieldDescriptor.TYPE_FIXED32: (0, 2**32 - 1),
    FieldDescriptor.TYPE_INT64: _SIGNED_64, FieldDescriptor.TYPE_SINT64: _SIGNED_64,
    FieldDescriptor.TYPE_SFIXED64: _SIGNED_64,
    FieldDescriptor.TYPE_UINT64: (0, 2**64 - 1), FieldDescriptor.TYPE_FIXED64: (0, 2**64 - 1),
}
"""The smallest and largest value of each protobuf integer type."""
_INTEGERS = tuple(INTEGER_RANGES)


class JsonInputError(InputError, ValueError):
    """A JSON input that cannot be taken: the message says where (line and column, or the
    field path) and why.

    Attributes:
        reason: why, without the place.
        line, column: where in the text (1-based), when the text itself is at fault.
    """

    def __init__(self, reason: str, line: int | None = None, column: int | None = None) -> None:
        self.reason, self.line, self.column = reason, line, column
        super().__init__(reason if line is None else f"line {line} column {column}: {reason}")


def _refuse_constant(name: str) -> Any:
    raise JsonInputError(f"{name} is not JSON (write the string \"{name}\" where a number "
                         "may be non-finite)")


def _refuse_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object's pairs as a dict; a key given twice is an error naming it (spec/README.md
    F3: ``json.loads`` alone keeps the last value without a word)."""
    obj = dict(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise JsonInputError(f"key {key!r} appears twice in one object")
            seen.add(key)
    return obj


SMALL_TEXT_CHARS = 1 << 16
"""Texts shorter than this have their depth found by walking the value (:func:`json_depth`),
longer ones in numpy (:func:`text_depth`)."""

_EMPTY_OBJECT: dict[str, Any] = {}
"""The one dict every ``{}`` of a :func:`parse_json` call with ``share_empty=True`` becomes."""


def _shared_empty(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    return _EMPTY_OBJECT if not pairs else _refuse_duplicates(pairs)


def parse_json(data: str | bytes, *, max_depth: int = MAX_JSON_DEPTH,
               share_empty: bool = False) -> Any:
    """The value of the JSON ``data`` (text, or UTF-8 bytes with or without a byte-order mark),
    nested at most ``max_depth`` deep.

    ``share_empty``: every empty object is one shared dict, which the caller must not change
    (a 16 MiB card of 5.6 million ``{}`` took 360 MB as as many dicts; the card reader reads
    them and changes nothing).

    Raises:
        JsonInputError: bytes that are not UTF-8, invalid JSON, a key twice in one object, a
            ``NaN``/``Infinity`` literal, nesting deeper than ``max_depth``, or an integer too
            long to convert.
    """
    if isinstance(data, bytes):
        try:
            text = utf8_text(data)
        except UnicodeDecodeError as exc:
            raise JsonInputError(f"not UTF-8 text: {exc.reason} at byte {exc.start}") from None
    else:
        text = data.removeprefix(BYTE_ORDER_MARK)
    hook = _shared_empty if share_empty else _refuse_duplicates
    try:
        value = json.loads(text, parse_constant=_refuse_constant, object_pairs_hook=hook)
    except json.JSONDecodeError as exc:
        raise JsonInputError(exc.msg, exc.lineno, exc.colno) from None
    except RecursionError:
        raise JsonInputError(f"nested deeper than {max_depth} arrays and objects") from None
    except JsonInputError:
        raise
    except ValueError as exc:  # an integer past sys.get_int_max_str_digits()
        raise JsonInputError(str(exc).split(";")[0]) from None
    # a small text's value is walked (numpy is not imported for a profile or a small card)
    depth = json_depth(value) if len(text) < SMALL_TEXT_CHARS else text_depth(text)
    if depth > max_depth:
        raise JsonInputError(f"nested {depth} arrays and objects deep, more than {max_depth}")
    return value


_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
"""A JSON string, escapes included (in valid JSON every ``"`` outside a string starts one)."""


_BRACKET_STEPS = bytes(
    1 if chr(code) in "{[" else 255 if chr(code) in "}]" else 0 for code in range(256))
"""Each byte to its step of the nesting depth as an int8: +1 opens, -1 (255) closes."""
_NOT_BRACKETS = bytes(code for code in range(256) if chr(code) not in "{}[]")


def text_depth(text: str) -> int:
    """How deep arrays and objects nest in the valid JSON ``text`` (0 for a scalar): the
    running count of the brackets outside strings, in numpy. Walking the parsed value instead
    (:func:`json_depth`) took 11.7 s for the 5.6 million objects of a 16 MiB card."""
    import numpy as np  # here, not at import: card commands start without it (0.1-0.2 s)

    skeleton = _STRING.sub("", text).encode("ascii", "replace")
    steps = skeleton.translate(_BRACKET_STEPS, _NOT_BRACKETS)
    if not steps:
        return 0
    return int(np.frombuffer(steps, dtype=np.int8).cumsum(dtype=np.int32).max())


def json_depth(value: Any) -> int:
    """How deep arrays and objects nest in ``value`` (0 for a scalar), found without
    recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children: Any = item.values()
        elif isinstance(item, list):
            children = item
        else:
            continue
        depth += 1
        deepest = max(deepest, depth)
        stack.extend((child, depth) for child in children)
    return deepest


def check_message_json(obj: Any, descriptor: Descriptor, path: str = "",
                       bounds: Mapping[str, int] | None = None) -> None:
    """Check a JSON object's known fields against ``descriptor``'s types (F3, F7, C5).

    Unknown fields are left alone (rule V4). Accepted per field type: a double takes a number
    or a string holding one in ASCII digits, or ``"NaN"``, ``"Infinity"``, ``"-Infinity"``; an
    integer a whole number or a string of ASCII digits; an enum a name it defines or a whole
    number; a string a string; a bool a bool; a message an object; a repeated field an array.
    ``null`` stands for the default of any field. A field given under both its names
    (``widthMm`` and ``width_mm``) is an error.

    ``bounds``: the most elements of a repeated message field (by its full name,
    ``"hcard.v1.Card.textures"``) that are examined; the others are not (spec/README.md
    section 4: past the T1 and T7 counts the excess need not be examined).

    Raises:
        JsonInputError: naming the field path (``textures[0].components[1].channel``) and the
            value's problem.
    """
    if not isinstance(obj, dict):
        raise JsonInputError(f"{path or 'the card'}: expected an object, got {_kind(obj)}")
    named: dict[FieldDescriptor, str] = {}
    for key, value in obj.items():
        field = field_named(descriptor, key)
        if field is None:
            continue
        where = f"{path}.{field.name}" if path else field.name
        if field in named:
            raise JsonInputError(f"{where}: given twice, as {named[field]!r} and {key!r}")
        named[field] = key
        if value is None:
            continue
        if field.is_repeated:
            if not isinstance(value, list):
                raise JsonInputError(f"{where}: expected an array, got {_kind(value)}")
            examined = value
            if bounds is not None and field.full_name in bounds:
                examined = value[:bounds[field.full_name]]
            if field.type in _INTEGERS and set(map(type, examined)) <= {int}:
                continue  # whole numbers all (the common case: millions of texture indices)
            for index, item in enumerate(examined):
                _check_value(item, field, f"{where}[{index}]", bounds)
        else:
            _check_value(value, field, where, bounds)


def field_named(descriptor: Descriptor, key: str) -> FieldDescriptor | None:
    """The field of ``descriptor`` a JSON key names: its proto name or its lowerCamelCase
    JSON name (F3); None for an unknown key."""
    return descriptor.fields_by_name.get(key) or _json_names(descriptor).get(key)


_JSON_NAMES: dict[str, dict[str, FieldDescriptor]] = {}


def _json_names(descriptor: Descriptor) -> dict[str, FieldDescriptor]:
    names = _JSON_NAMES.get(descriptor.full_name)
    if names is None:
        names = _JSON_NAMES[descriptor.full_name] = {f.json_name: f for f in descriptor.fields}
    return names


def _check_value(value: Any, field: FieldDescriptor, where: str,
                 bounds: Mapping[str, int] | None = None) -> None:
    kind = field.type
    if kind == FieldDescriptor.TYPE_MESSAGE:
        check_message_json(value, field.message_type, where, bounds)
    elif kind in _FLOATING:
        if isinstance(value, bool) or not (
            isinstance(value, (int, float))
            or (isinstance(value, str) and (value in _SPECIAL_DOUBLES
                                           or _NUMBER_TEXT.fullmatch(value)))
        ):
            raise JsonInputError(f"{where}: expected a number, got {_kind(value)}")
    elif kind in _INTEGERS:
        whole_number(value, where)
    elif kind == FieldDescriptor.TYPE_ENUM:
        names = field.enum_type.values_by_name
        if isinstance(value, str):
            if value not in names:
                raise JsonInputError(
                    f"{where}: unknown {field.enum_type.name} {value!r} (one of "
                    f"{', '.join(names)}; rule C5)")
        elif isinstance(value, bool) or not isinstance(value, int):
            raise JsonInputError(f"{where}: expected a {field.enum_type.name} name, got "
                                 f"{_kind(value)}")
    elif kind == FieldDescriptor.TYPE_STRING:
        if not isinstance(value, str):
            raise JsonInputError(f"{where}: expected a string, got {_kind(value)}")
    elif kind == FieldDescriptor.TYPE_BOOL and not isinstance(value, bool):
        raise JsonInputError(f"{where}: expected true or false, got {_kind(value)}")


def whole_number(value: Any, where: str) -> int:
    """The integer a JSON value for an integer field stands for: a whole number, or a string
    of ASCII digits (F3).

    Raises:
        JsonInputError: any other value, naming ``where``.
    """
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, str) and _INTEGER_TEXT.fullmatch(value):
        return int(value)
    raise JsonInputError(f"{where}: expected a whole number, got {_kind(value)}")


def _kind(value: Any) -> str:
    """A short description of a JSON value for an error message."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"the string {shown!r}"
    return f"{type(value).__name__} {value!r}"[:60]
