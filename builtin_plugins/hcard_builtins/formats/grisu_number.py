"""Doubles printed as rapidjson's ``Writer`` prints them, so that an .hjif hcard writes is byte
for byte what the MPEG reference software writes back (spec/interchange/hjif.md IJ30).

rapidjson (the reference's JSON library) finds the digits with Grisu2 (F. Loitsch, "Printing
floating-point numbers quickly and accurately with integers", PLDI 2010): they always read
back as the same double, but are not always the shortest, nor rounded as Python's ``repr``
rounds a tie (the float32 3.55188751220703125 prints as ``3.5518875122070313`` there and
``3.5518875122070312`` in Python). This module follows the algorithm on 64-bit integers:
the value and its rounding boundaries scaled by a cached power of ten, digits generated
while the remainder stays outside the boundaries' interval, the last digit nudged towards
the value. The layout of the digits (``Prettify``) is rapidjson's: ``1.0``, ``0.001234``,
``12340000000.0``, ``1e-7``, ``1.234e30``.

>>> format_double(0.30000001192092896), format_double(1e-07), format_double(100.0)
('0.30000001192092896', '1e-7', '100.0')
"""

from __future__ import annotations

import struct
from fractions import Fraction
from functools import cache

_MASK64 = (1 << 64) - 1
_HIDDEN_BIT = 1 << 52
_SIGNIFICAND_MASK = _HIDDEN_BIT - 1
_EXPONENT_BIAS = 0x3FF + 52


@cache
def _cached_power(index: int) -> tuple[int, int]:
    """10^(-348 + 8 index) as a 64-bit significand (rounded to nearest) and binary exponent:
    the table Grisu2 scales by (87 entries, 10^-348 to 10^340)."""
    value = Fraction(10) ** (-348 + 8 * index)
    e = value.numerator.bit_length() - value.denominator.bit_length() - 64
    while Fraction(2) ** (e + 64) <= value:
        e += 1
    while Fraction(2) ** (e + 63) > value:
        e -= 1
    scaled = value / Fraction(2) ** e
    f = int(scaled)
    if scaled - f >= Fraction(1, 2):
        f += 1
    return f, e


def _multiply(a: tuple[int, int], b: tuple[int, int]) -> tuple[int, int]:
    """The upper 64 bits of the 128-bit product, rounded half up, and the exponent."""
    return (a[0] * b[0] + (1 << 63)) >> 64, a[1] + b[1] + 64


def _normalize(f: int, e: int) -> tuple[int, int]:
    shift = 64 - f.bit_length()
    return f << shift, e - shift


def _boundaries(f: int, e: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The lower and upper rounding boundaries of the double ``f 2^e``, on one exponent."""
    pf, pe = (f << 1) + 1, e - 1
    while not pf & (_HIDDEN_BIT << 1):
        pf, pe = pf << 1, pe - 1
    pf, pe = pf << 10, pe - 10
    mf, me = ((f << 2) - 1, e - 2) if f == _HIDDEN_BIT else ((f << 1) - 1, e - 1)
    return (mf << (me - pe), pe), (pf, pe)


def _grisu_round(digits: list[int], delta: int, rest: int, ten_kappa: int, wp_w: int) -> None:
    """Move the last digit towards the value while the result stays within the interval."""
    while (rest < wp_w and (delta - rest) & _MASK64 >= ten_kappa
           and ((rest + ten_kappa) & _MASK64 < wp_w
                or (wp_w - rest) & _MASK64 > (rest + ten_kappa - wp_w) & _MASK64)):
        digits[-1] -= 1
        rest = (rest + ten_kappa) & _MASK64


def _grisu2(value: float) -> tuple[str, int]:
    """The digits of the positive double ``value`` and K: ``value ~ digits x 10^K``."""
    bits = struct.unpack("<Q", struct.pack("<d", value))[0]
    biased = (bits >> 52) & 0x7FF
    significand = bits & _SIGNIFICAND_MASK
    f, e = (significand + _HIDDEN_BIT, biased - _EXPONENT_BIAS) if biased else (
        significand, 1 - _EXPONENT_BIAS)
    minus, plus = _boundaries(f, e)
    dk = (-61 - plus[1]) * 0.30102999566398114 + 347
    k = int(dk)
    if dk - k > 0.0:
        k += 1
    index = (k >> 3) + 1
    big_k = -(-348 + (index << 3))
    c_mk = _cached_power(index)
    w = _multiply(_normalize(f, e), c_mk)
    wp = _multiply(plus, c_mk)
    wm = _multiply(minus, c_mk)
    wp_f, wm_f = wp[0] - 1, wm[0] + 1
    return _digit_gen(w[0], wp_f, wp[1], wp_f - wm_f, big_k)


def _digit_gen(w_f: int, mp_f: int, mp_e: int, delta: int, big_k: int) -> tuple[str, int]:
    shift = -mp_e
    one = 1 << shift
    wp_w = (mp_f - w_f) & _MASK64
    p1 = mp_f >> shift
    p2 = mp_f & (one - 1)
    kappa = min(len(str(p1)), 9)
    digits: list[int] = []
    while kappa > 0:
        power = 10 ** (kappa - 1)
        d, p1 = divmod(p1, power)
        if d or digits:
            digits.append(d)
        kappa -= 1
        rest = (p1 << shift) + p2
        if rest <= delta:
            _grisu_round(digits, delta, rest, (10**kappa << shift) & _MASK64, wp_w)
            return "".join(map(str, digits)), big_k + kappa
    while True:
        p2 = (p2 * 10) & _MASK64
        delta = (delta * 10) & _MASK64
        d = p2 >> shift
        if d or digits:
            digits.append(d)
        p2 &= one - 1
        kappa -= 1
        if p2 < delta:
            scale = 10 ** -kappa if -kappa < 20 else 0
            _grisu_round(digits, delta, p2, one, (wp_w * scale) & _MASK64)
            return "".join(map(str, digits)), big_k + kappa


def format_double(value: float) -> str:
    """``value`` (finite) as rapidjson's ``Writer::Double`` prints it (``dtoa`` with the
    default 324 decimal places)."""
    if value == 0:
        return "-0.0" if struct.pack("<d", value)[7] & 0x80 else "0.0"
    sign = "-" if value < 0 else ""
    digits, k = _grisu2(abs(value))
    n = len(digits)
    kk = n + k
    if k >= 0 and kk <= 21:
        text = digits + "0" * k + ".0"
    elif 0 < kk <= 21:
        text = digits[:kk] + "." + digits[kk:]
    elif -6 < kk <= 0:
        text = "0." + "0" * -kk + digits
    elif kk < -324:
        text = "0.0"
    elif n == 1:
        text = f"{digits}e{kk - 1}"
    else:
        text = f"{digits[0]}.{digits[1:]}e{kk - 1}"
    return sign + text
