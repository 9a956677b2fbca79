"""Numbers and strings printed as the MPEG reference software prints them (rapidjson's
``Writer``; spec/interchange/hjif.md IJ16). The expected texts are what the reference wrote
back for files holding these values (its round trips of the test exports, and of hand-written
files with ``0.3``, ``1.5708``), not Python's ``repr``."""

from __future__ import annotations

import random
import struct

import pytest

from hcard_builtins.formats.grisu_number import format_double
from hcard_builtins.formats.hjif_model import float32, format_string, sine_phase

WRITTEN_BY_THE_REFERENCE = [
    (float32(0.3), "0.30000001192092896"),
    (float32(0.1), "0.10000000149011612"),
    (float32(1.5708), "1.5707999467849731"),
    (float32(0.8), "0.800000011920929"),
    # a tie of the float32's exact decimal expansion 3.55188751220703125: Python's repr
    # rounds it to even (...312), Grisu2 up (...313)
    (3.55188751220703125, "3.5518875122070313"),
    # not Python's shortest (0.2549281716346741)
    (0.25492817163467407, "0.25492817163467407"),
    (1.0, "1.0"), (0.0, "0.0"), (-0.0, "-0.0"), (100.0, "100.0"), (0.5, "0.5"),
]


@pytest.mark.parametrize(("value", "text"), WRITTEN_BY_THE_REFERENCE)
def test_doubles_as_the_reference_writes_them(value: float, text: str) -> None:
    assert format_double(value) == text


@pytest.mark.parametrize(("value", "text"), [
    (1e-7, "1e-7"), (1.5e-7, "1.5e-7"), (0.000001, "0.000001"), (0.001234, "0.001234"),
    (12340000000.0, "12340000000.0"), (1e21, "1e21"), (1.234e33, "1.234e33"),
    (5e-324, "5e-324"), (-0.25, "-0.25")])
def test_the_layout_of_the_digits(value: float, text: str) -> None:
    """rapidjson's Prettify: a decimal point up to 21 digits, exponents without '+' or
    padding (Python writes 1e-07 and 1e+21)."""
    assert format_double(value) == text


def test_every_double_reads_back_exactly() -> None:
    rng = random.Random(29)
    for _ in range(20000):
        value = struct.unpack("<d", struct.pack("<Q", rng.getrandbits(64)))[0]
        if value == value and abs(value) != float("inf"):
            assert float(format_double(value)) == value


def test_strings_as_rapidjson_escapes_them() -> None:
    assert format_string('a"b\\c/d\n\t\x01é\u2028') == '"a\\"b\\\\c/d\\n\\t\\u0001é\u2028"'


def test_a_phase_above_the_schema_maximum_is_written_as_zero() -> None:
    assert float32(6.28318) > 6.28318  # why: the float32 nearest 6.28318 is above it
    assert sine_phase(6.28318) == 0.0
    assert sine_phase(-0.5) == float32(2 * 3.141592653589793 - 0.5)
    assert sine_phase(6.2831) == float32(6.2831)
