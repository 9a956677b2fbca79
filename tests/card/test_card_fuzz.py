"""Fuzzing the card reader: nothing but CardError ever escapes, and repeated structure costs
time in proportion to its bytes with a bounded report (spec/README.md section 4)."""

from __future__ import annotations

import contextlib
import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hcard.card_io import card_from_bytes, parse_card, to_bytes, to_json
from hcard.errors import CardError
from hcard.validate import MAX_LISTED_PROBLEMS, errors_of, validate
from tests.helpers.cards import two_texture_card
from tests.helpers.hostile_cards import HOSTILE_CARDS

VALID = to_bytes(two_texture_card())
VALID_JSON = to_json(two_texture_card()).encode()
FUZZ = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def read(data: bytes) -> None:
    with contextlib.suppress(CardError):
        parse_card(data)


@FUZZ
@given(st.binary(max_size=512))
def test_random_bytes(data):
    read(data)


@FUZZ
@given(st.data())
def test_mutated_valid_cards(data):
    source = bytearray(data.draw(st.sampled_from([VALID, VALID_JSON])))
    for _ in range(data.draw(st.integers(1, 6))):
        kind = data.draw(st.sampled_from(["flip", "insert", "delete", "truncate"]))
        at = data.draw(st.integers(0, max(len(source) - 1, 0)))
        if kind == "flip" and source:
            source[at] ^= 1 << data.draw(st.integers(0, 7))
        elif kind == "insert":
            source[at:at] = data.draw(st.binary(min_size=1, max_size=8))
        elif kind == "delete" and source:
            del source[at : at + data.draw(st.integers(1, 8))]
        else:
            source = source[:at]
    read(bytes(source))


@FUZZ
@given(st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.sampled_from(["version", "grid", "textures", "surface", "cols",
                                       "major", "baseline", "components", "x"]),
                      children, max_size=4),
    max_leaves=20,
))
def test_random_json_documents(document):
    import json

    read(json.dumps({"version": {"major": 1}, "grid": document}).encode())
    read(json.dumps(document).encode())


SECONDS_PER_BYTE = 5e-7
"""CPU time a read and validation may take per input byte, beyond :data:`BASE_SECONDS`
(measured ~6e-8 s/byte on the 16 MiB hostile cards: 1 s). CPU time, not wall time: CI runs
these tests again beside the suite at a low priority, where a wall clock measures the
machine's other work."""
BASE_SECONDS = 0.5


@settings(max_examples=12, deadline=None)
@given(st.sampled_from(sorted(HOSTILE_CARDS)), st.integers(1, 1_500_000))
def test_repeated_structure_costs_time_in_proportion_and_a_bounded_report(kind, count):
    """Whatever is repeated and how often: read and validation take time in proportion to the
    bytes, and the report lists at most MAX_LISTED_PROBLEMS problems plus one count per rule."""
    data = HOSTILE_CARDS[kind](count)
    started = time.process_time()
    try:
        card = card_from_bytes(data)
        problems = validate(card)
    finally:
        elapsed = time.process_time() - started
    assert elapsed < BASE_SECONDS + SECONDS_PER_BYTE * len(data), (kind, count, elapsed)
    assert errors_of(problems)
    listed = [p for p in problems if p.path]
    assert len(listed) <= MAX_LISTED_PROBLEMS
    assert len(problems) - len(listed) <= len({p.rule for p in problems})
