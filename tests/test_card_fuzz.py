"""Fuzzing the card reader: nothing but CardError ever escapes (issue 3 item 7)."""

from __future__ import annotations

import contextlib

from cards import two_texture_card
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hcard.card_io import parse_card, to_bytes, to_json
from hcard.errors import CardError

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
