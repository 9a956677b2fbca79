"""Format level (spec/conformance.md Q2-Q4): the card reader and writer on the vectors.

* ``format.parse`` (Q2): every vector card, binary and JSON, parses and validates with no error;
* ``format.round_trip`` (Q3): ``binary(parse(json file))`` equals the binary file byte for byte,
  ``binary(parse(binary file))`` too, and ``json(parse(binary file))`` equals the JSON file
  after both are re-serialised by the reader's own writer;
* ``format.reject`` (Q4): every invalid vector is rejected with a :class:`CardError` whose
  reason contains the documented fragment and whose field path is the documented one.

Each check declares its cases from the manifest before it runs (``parse_cases``,
``round_trip_cases``, ``reject_cases``, named by the registry) and measures only the cases a
run wants (:meth:`Context.wants`).

These exercise the host-side reader (``hcard.card_io``) that every driver uploads through; the
level is the same whichever driver is named. A device's own acceptance of cards is judged at
the device level.
"""

from __future__ import annotations

from collections.abc import Iterator

from hcard.card_io import card_from_bytes, dumps, parse_card, read_card_file, to_bytes
from hcard.errors import CardError
from hcard.validate import card_errors
from hcard_conformance.check_names import FORMAT_PARSE, FORMAT_REJECT, FORMAT_ROUND_TRIP
from hcard_conformance.context import Context
from hcard_conformance.result import CheckResult

LEVEL = "format"
FORMS = ("binary", "json")
"""The two files of every vector card, in the order ``format.parse`` reads them."""


def parse_cases(ctx: Context) -> list[str]:
    """Cases of ``format.parse`` (registry declaration): ``CARD.binary`` and ``CARD.json`` of
    every vector card."""
    return [f"{entry.name}.{form}" for entry in ctx.manifest.cards for form in FORMS]


def round_trip_cases(ctx: Context) -> list[str]:
    """Cases of ``format.round_trip`` (registry declaration): every vector card."""
    return [entry.name for entry in ctx.manifest.cards]


def reject_cases(ctx: Context) -> list[str]:
    """Cases of ``format.reject`` (registry declaration): every invalid vector."""
    return [entry.name for entry in ctx.manifest.invalid]


def _first_difference(a: bytes, b: bytes) -> str:
    """Where two byte strings first differ, in words."""
    if a == b:
        return "identical"
    n = next((i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x != y), min(len(a),
                                                                                    len(b)))
    return f"first difference at byte {n} ({len(a)} vs {len(b)} bytes)"


def check_parse(ctx: Context) -> Iterator[CheckResult]:
    """Q2: parse and validate both files of every card; metric = validation errors found."""
    for entry in ctx.manifest.cards:
        for form, path in zip(FORMS, (entry.binary, entry.json), strict=True):
            if not ctx.wants(FORMAT_PARSE, f"{entry.name}.{form}"):
                continue
            try:
                card = parse_card(read_card_file(path), source=path, check=False)
                problems = card_errors(card)
            except CardError as exc:
                yield CheckResult(FORMAT_PARSE, LEVEL, f"{entry.name}.{form}", False, "Q2",
                                  1.0, 0.0, "errors", f"rejected: {exc}")
                continue
            detail = ("parses and validates" if not problems
                      else "; ".join(str(p) for p in problems[:3]))
            yield CheckResult(FORMAT_PARSE, LEVEL, f"{entry.name}.{form}", not problems,
                              "Q2", float(len(problems)), 0.0, "errors", detail)


def check_round_trip(ctx: Context) -> Iterator[CheckResult]:
    """Q3: metric = number of round trips (of three) whose bytes differ."""
    for entry in ctx.manifest.cards:
        if not ctx.wants(FORMAT_ROUND_TRIP, entry.name):
            continue
        binary = read_card_file(entry.binary)
        json_bytes = read_card_file(entry.json)
        from_binary = card_from_bytes(binary, source=entry.binary)
        from_json = card_from_bytes(json_bytes, source=entry.json)
        trips = {
            "binary->binary": (to_bytes(from_binary), binary),
            "json->binary": (to_bytes(from_json), binary),
            "binary->json": (dumps(from_binary, "json"), dumps(from_json, "json")),
        }
        bad = [f"{name}: {_first_difference(got, want)}"
               for name, (got, want) in trips.items() if got != want]
        yield CheckResult(FORMAT_ROUND_TRIP, LEVEL, entry.name, not bad, "Q3",
                          float(len(bad)), 0.0, "mismatches",
                          "; ".join(bad) or f"{len(binary)} bytes, 3 round trips bit exact")


def check_reject(ctx: Context) -> Iterator[CheckResult]:
    """Q4: metric = 0 when rejected as documented, 1 otherwise."""
    for entry in ctx.manifest.invalid:
        if not ctx.wants(FORMAT_REJECT, entry.name):
            continue
        try:
            parse_card(read_card_file(entry.file), source=entry.file)
        except CardError as exc:
            reason_ok = entry.error in exc.reason or entry.error in str(exc)
            field_ok = exc.field_path == entry.field
            passed = reason_ok and field_ok
            detail = f"rejected: {exc}"
            if not reason_ok:
                detail += f" (expected the error to contain {entry.error!r})"
            if not field_ok:
                detail += f" (field {exc.field_path!r}, expected {entry.field!r})"
            yield CheckResult(FORMAT_REJECT, LEVEL, entry.name, passed, "Q4",
                              0.0 if passed else 1.0, 0.0, "", detail)
            continue
        except Exception as exc:  # a reader crash is a failure, not a rejection
            yield CheckResult(FORMAT_REJECT, LEVEL, entry.name, False, "Q4", 1.0, 0.0, "",
                              f"reader raised {type(exc).__name__} instead of CardError: {exc}")
            continue
        yield CheckResult(FORMAT_REJECT, LEVEL, entry.name, False, "Q4", 1.0, 0.0, "",
                          f"accepted; expected rejection: {entry.error} ({entry.rule})")
