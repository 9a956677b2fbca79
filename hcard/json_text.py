"""JSON from strangers, parsed with bounds and checked strictly against the card schema.

:func:`parse_json` is ``json.loads`` with its failures turned into one :class:`JsonInputError`
that says where and why: invalid JSON (line and column), the non-standard ``NaN`` and
``Infinity`` literals, nesting deeper than :data:`MAX_JSON_DEPTH` (5000 nested arrays ended in a
RecursionError traceback), and integers longer than Python converts (a 5000-digit integer ended
in a ValueError traceback).

:func:`check_message_json` walks a JSON object against a protobuf message descriptor before the
protobuf JSON parser sees it, because that parser is lenient where the card format is not
(spec/README.md F3, F7): it takes ``true`` for a double, ``true`` or ``1.5`` for an enum, and
drops an enum name it does not know (``"CHANNEL_EVV"``) when unknown fields are ignored, so the
component then played on its texture's channel instead of being refused by rule C5.
"""

from __future__ import annotations

import json
import re
from typing import Any

from google.protobuf.descriptor import Descriptor, FieldDescriptor

from hcard.errors import InputError

MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays and objects a JSON input may have (a card needs 5)."""

_NUMBER_TEXT = re.compile(r"-?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
"""A number written as a JSON string (the protobuf JSON mapping allows ``"1.5"``): ASCII
digits only, where ``float()`` also takes ``"0.0_2"``, Arabic-Indic and full-width digits."""
_INTEGER_TEXT = re.compile(r"-?[0-9]+")
_SPECIAL_DOUBLES = frozenset({"NaN", "Infinity", "-Infinity"})

_FLOATING = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)
_INTEGERS = (
    FieldDescriptor.TYPE_INT32, FieldDescriptor.TYPE_INT64, FieldDescriptor.TYPE_UINT32,
    FieldDescriptor.TYPE_UINT64, FieldDescriptor.TYPE_SINT32, FieldDescriptor.TYPE_SINT64,
    FieldDescriptor.TYPE_FIXED32, FieldDescriptor.TYPE_FIXED64, FieldDescriptor.TYPE_SFIXED32,
    FieldDescriptor.TYPE_SFIXED64,
)


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


def parse_json(text: str, *, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """The value of the JSON ``text``, nested at most ``max_depth`` deep.

    Raises:
        JsonInputError: invalid JSON, a ``NaN``/``Infinity`` literal, nesting deeper than
            ``max_depth``, or an integer too long to convert.
    """
    try:
        value = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise JsonInputError(exc.msg, exc.lineno, exc.colno) from None
    except RecursionError:
        raise JsonInputError(f"nested deeper than {max_depth} arrays and objects") from None
    except JsonInputError:
        raise
    except ValueError as exc:  # an integer past sys.get_int_max_str_digits()
        raise JsonInputError(str(exc).split(";")[0]) from None
    depth = json_depth(value)
    if depth > max_depth:
        raise JsonInputError(f"nested {depth} arrays and objects deep, more than {max_depth}")
    return value


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


def check_message_json(obj: Any, descriptor: Descriptor, path: str = "") -> None:
    """Check a JSON object's known fields against ``descriptor``'s types (F3, F7, C5).

    Unknown fields are left alone (rule V4). Accepted per field type: a double takes a number
    or a string holding one in ASCII digits, or ``"NaN"``, ``"Infinity"``, ``"-Infinity"``; an
    integer a whole number or a string of ASCII digits; an enum a name it defines or a whole
    number; a string a string; a bool a bool; a message an object; a repeated field an array.
    ``null`` stands for the default of any field.

    Raises:
        JsonInputError: naming the field path (``textures[0].components[1].channel``) and the
            value's problem.
    """
    if not isinstance(obj, dict):
        raise JsonInputError(f"{path or 'the card'}: expected an object, got {_kind(obj)}")
    fields = {}
    for field in descriptor.fields:
        fields[field.name] = field
        fields[field.json_name] = field
    for key, value in obj.items():
        field = fields.get(key)
        if field is None or value is None:
            continue
        where = f"{path}.{field.name}" if path else field.name
        if field.is_repeated:
            if not isinstance(value, list):
                raise JsonInputError(f"{where}: expected an array, got {_kind(value)}")
            for index, item in enumerate(value):
                _check_value(item, field, f"{where}[{index}]")
        else:
            _check_value(value, field, where)


def _check_value(value: Any, field: FieldDescriptor, where: str) -> None:
    kind = field.type
    if kind == FieldDescriptor.TYPE_MESSAGE:
        check_message_json(value, field.message_type, where)
    elif kind in _FLOATING:
        if isinstance(value, bool) or not (
            isinstance(value, (int, float))
            or (isinstance(value, str) and (value in _SPECIAL_DOUBLES
                                           or _NUMBER_TEXT.fullmatch(value)))
        ):
            raise JsonInputError(f"{where}: expected a number, got {_kind(value)}")
    elif kind in _INTEGERS:
        whole = (
            (isinstance(value, int) and not isinstance(value, bool))
            or (isinstance(value, float) and value.is_integer())
            or (isinstance(value, str) and _INTEGER_TEXT.fullmatch(value))
        )
        if not whole:
            raise JsonInputError(f"{where}: expected a whole number, got {_kind(value)}")
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
