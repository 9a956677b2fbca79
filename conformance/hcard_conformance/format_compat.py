"""Check ``format.compat`` (spec/conformance.md Q4b; README V3, V4, F2, F4): the reader and
writer on files other writers make.

Cases, one per compatibility vector of the manifest (``NAME.FORM``) and one for the writer:

``unknown-fields.binary`` (V3)
    a later minor's binary card reads and validates as its card; written back as binary it
    keeps every field the manifest lists as unknown, found in the written bytes by
    :mod:`~hcard_conformance.wire_fields` (not by the reader's runtime), and its minor
    version. Metric: unknown fields lost, plus one for a lowered minor, plus one when the
    known content differs from the card's.
``unknown-fields.json`` (V4)
    a later minor's JSON card with unknown keys reads and validates as its card.
``binary-named.json``, ``json-named.hcard`` (F4)
    each form under the other's file name reads as the card, the form found from the content.
``json-writer`` (F2)
    the JSON the writer gives for every vector card, read with the standard ``json`` module:
    only proto field names (no lowerCamelCase), enums by name, every double equal bit for bit
    to the card's (shortest round-trip or 17 digits), a field left out only at its zero value,
    no key twice. Metric: such faults over all cards.

For the reading cases the metric is 0 when the file reads as its card, else the number of
faults found (a rejection counts one).
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Iterator
from typing import Any

from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.message import Message

from hcard.card_io import dumps, parse_card, read_card_file, to_bytes
from hcard.errors import CardError
from hcard.v1 import card_pb2 as pb
from hcard_conformance.check_names import FORMAT_COMPAT as CHECK
from hcard_conformance.context import Context
from hcard_conformance.result import CheckResult
from hcard_conformance.vectors.manifest import CompatEntry
from hcard_conformance.wire_fields import WireError, WireField, unknown_fields

LEVEL = "format"
JSON_WRITER_CASE = "json-writer"
FLOATING = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)
JSON_FLOAT_WORDS = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}
"""The strings the protobuf JSON mapping writes for non-finite doubles."""


def compat_cases(ctx: Context) -> list[str]:
    """Cases of ``format.compat`` (registry declaration): every compatibility vector, then
    :data:`JSON_WRITER_CASE`."""
    return [entry.case for entry in ctx.manifest.compat] + [JSON_WRITER_CASE]


def _expected_card(ctx: Context, entry: CompatEntry) -> pb.Card:
    card = ctx.manifest.card(entry.card).load_card()
    card.version.minor = entry.minor
    return card


def _listed_unknown(entry: CompatEntry) -> list[WireField]:
    return [WireField.from_json(row) for row in entry.unknown]


def _read_problems(ctx: Context, entry: CompatEntry) -> tuple[list[str], str]:
    """(faults, what was done) for one compatibility vector."""
    data = read_card_file(entry.file)
    try:
        card = parse_card(data, source=entry.file)
    except CardError as exc:
        return [f"rejected: {exc}"], ""
    except Exception as exc:  # a reader that crashes on a valid file fails the case (Q4)
        return [f"the reader raised {type(exc).__name__}: {exc}"], ""
    expected = _expected_card(ctx, entry)
    problems = []
    if entry.unknown:  # V3: write it back, look for every listed field in the bytes
        written = to_bytes(card)
        try:
            kept = unknown_fields(written, pb.Card.DESCRIPTOR)
        except WireError as exc:
            return [f"the re-written bytes are not a protobuf message ({exc})"], ""
        lost = [u for u in _listed_unknown(entry) if u not in kept]
        problems += [f"re-written without unknown field {u.number} of "
                     f"{u.path or 'the card'} (V3)" for u in lost]
        again = pb.Card.FromString(written)
        if again.version.minor < entry.minor:
            problems.append(f"re-written as minor {again.version.minor}, read as {entry.minor}"
                            " (V3: not lowered)")
        again.DiscardUnknownFields()
        card = again
        done = f"re-written: {len(_listed_unknown(entry)) - len(lost)} of " \
               f"{len(entry.unknown)} unknown fields kept, minor {again.version.minor}"
    else:
        done = f"read as card {entry.card!r}, version 1.{entry.minor}"
    if to_bytes(card) != to_bytes(expected):
        problems.append(f"its known fields differ from card {entry.card!r}")
    return problems, done


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


def _number(value: Any) -> float | None:
    """A JSON value written for a double, as a float (None: not a number)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str) and value in JSON_FLOAT_WORDS:
        return JSON_FLOAT_WORDS[value]
    return None


def _scalar_problem(field: FieldDescriptor, written: Any, value: Any, where: str) -> str:
    """Why ``written`` is not how F2 writes the scalar ``value`` of ``field`` ("" if it is)."""
    if field.type == FieldDescriptor.TYPE_ENUM:
        names = field.enum_type.values_by_number
        if not isinstance(written, str):
            return f"{where}: enum written as {written!r}, not by name"
        if value not in names or names[value].name != written:
            return f"{where}: enum {written!r}, the card holds {value}"
        return ""
    if field.type in FLOATING:
        number = _number(written)
        if number is None:
            return f"{where}: {written!r} is not a number"
        same = (math.isnan(number) and math.isnan(value)) or _bits(number) == _bits(value)
        return "" if same else f"{where}: {written!r} reads back as {number!r}, the card " \
            f"holds {value!r} (not a round-trip representation)"
    if field.type == FieldDescriptor.TYPE_STRING:
        return "" if written == value else f"{where}: {written!r}, the card holds {value!r}"
    if isinstance(written, bool) != (field.type == FieldDescriptor.TYPE_BOOL):
        return f"{where}: {written!r} for a {field.type} field"
    try:
        same = int(written) == int(value)
    except (TypeError, ValueError):
        same = False
    return "" if same else f"{where}: {written!r}, the card holds {value!r}"


def _is_zero(message: Message, field: FieldDescriptor) -> bool:
    """Whether ``field`` of ``message`` holds its zero value (F2 lets a writer leave it out);
    -0.0 is not zero (its bits differ)."""
    if field.is_repeated:
        return len(getattr(message, field.name)) == 0
    if field.type == FieldDescriptor.TYPE_MESSAGE:
        return not message.HasField(field.name)
    value = getattr(message, field.name)
    if isinstance(value, float):
        return value == 0 and math.copysign(1.0, value) > 0
    return not value


def json_writer_problems(obj: Any, message: Message, where: str = "") -> list[str]:
    """F2 faults of the JSON value ``obj`` written for ``message``."""
    descriptor: Descriptor = message.DESCRIPTOR
    if not isinstance(obj, dict):
        return [f"{where or 'the card'}: a {type(obj).__name__} where a message belongs"]
    problems = []
    for key, written in obj.items():
        field = descriptor.fields_by_name.get(key)
        at = f"{where}.{key}" if where else key
        if field is None:
            problems.append(f"{at}: not a proto field name"
                            + (" (a lowerCamelCase JSON name)"
                               if any(f.json_name == key for f in descriptor.fields) else ""))
            continue
        value = getattr(message, field.name)
        if field.is_repeated:
            if not isinstance(written, list) or len(written) != len(value):
                problems.append(f"{at}: {len(value)} values expected")
                continue
            for i, (w, v) in enumerate(zip(written, value, strict=True)):
                if field.type == FieldDescriptor.TYPE_MESSAGE:
                    problems += json_writer_problems(w, v, f"{at}[{i}]")
                elif problem := _scalar_problem(field, w, v, f"{at}[{i}]"):
                    problems.append(problem)
        elif field.type == FieldDescriptor.TYPE_MESSAGE:
            problems += json_writer_problems(written, value, at)
        elif problem := _scalar_problem(field, written, value, at):
            problems.append(problem)
    problems += [f"{where + '.' if where else ''}{f.name}: left out, but not zero"
                 for f in descriptor.fields
                 if f.name not in obj and not _is_zero(message, f)]
    return problems


def _no_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    keys = [k for k, _ in pairs]
    twice = sorted({k for k in keys if keys.count(k) > 1})
    if twice:
        raise ValueError(f"key {twice[0]!r} written twice in one object")
    return dict(pairs)


def _writer_problems(ctx: Context) -> tuple[list[str], int]:
    """(F2 faults, cards written) of the JSON writer over every vector card."""
    problems = []
    for entry in ctx.manifest.cards:
        card = entry.load_card()
        text = dumps(card, "json")
        try:
            obj = json.loads(text, object_pairs_hook=_no_repeated_keys)
        except ValueError as exc:
            problems.append(f"{entry.name}: not JSON ({exc})")
            continue
        problems += [f"{entry.name}: {p}" for p in json_writer_problems(obj, card)]
    return problems, len(ctx.manifest.cards)


def check_compat(ctx: Context) -> Iterator[CheckResult]:
    """Q4b (module docstring): metric = faults found per case."""
    for entry in ctx.manifest.compat:
        if not ctx.wants(CHECK, entry.case):
            continue
        problems, done = _read_problems(ctx, entry)
        detail = "; ".join(problems[:4]) if problems else f"{entry.rule}: {done}"
        yield CheckResult(CHECK, LEVEL, entry.case, not problems, "Q4b",
                          float(len(problems)), 0.0, "faults", detail)
    if ctx.wants(CHECK, JSON_WRITER_CASE):
        problems, cards = _writer_problems(ctx)
        detail = "; ".join(problems[:4]) if problems else \
            f"F2: {cards} cards written with proto field names, enums by name, exact doubles"
        yield CheckResult(CHECK, LEVEL, JSON_WRITER_CASE, not problems, "Q4b",
                          float(len(problems)), 0.0, "faults", detail)
