"""The report base class and :class:`ProtocolError`.

A report is a frozen dataclass whose fields are the integer wire values (units in the field
names: ``_us`` microseconds, ``_10um`` 0.01 mm, ``_mn`` millinewton, ``_nm`` nanometre, ``_dv``
0.1 V, ``_10na`` 0.01 uA, ``_x1e4`` relative friction times 10 000). Constructing a report
checks every field against its range, so neither ``encode`` nor ``decode`` can produce a report
the spec does not allow.
"""

from __future__ import annotations

import math
import struct
from dataclasses import fields
from typing import Any, ClassVar, TypeVar

from hcard.device.protocol.constants import MAX_REPORT_BYTES, ReportId, ReportKind
from hcard.errors import HcardError

R = TypeVar("R", bound="Report")


class ProtocolError(HcardError):
    """A report is malformed, unknown or not allowed in this direction.

    On the device side a feature request raising this is answered with a STALL; a host driver
    raises it for a report it cannot decode. ``reason`` is the message without the report name.
    """

    def __init__(self, reason: str, *, report: str = "") -> None:
        self.reason = reason
        self.report = report
        super().__init__(f"{report}: {reason}" if report else reason)


class Report:
    """Base of every report dataclass (subclasses are ``@dataclass(frozen=True)``).

    Class attributes set by each subclass:
        REPORT_ID: the report ID byte (first byte on the wire).
        KIND: input, output or feature.
        STRUCT: the little-endian layout of the whole report, ID byte included.
        RANGES: inclusive (low, high) range of each scalar integer field.
        GET, SET: for feature reports, whether GET_REPORT / SET_REPORT is allowed.
    """

    REPORT_ID: ClassVar[int]
    KIND: ClassVar[ReportKind]
    STRUCT: ClassVar[struct.Struct]
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {}
    GET: ClassVar[bool] = False
    SET: ClassVar[bool] = False

    @classmethod
    def size(cls) -> int:
        """Bytes on the wire, report ID included."""
        return cls.STRUCT.size

    @classmethod
    def name(cls) -> str:
        """Report name as in the spec (e.g. ``UPLOAD_DATA``)."""
        return ReportId(cls.REPORT_ID).name

    def __post_init__(self) -> None:
        for field_name, (low, high) in self.RANGES.items():
            value = getattr(self, field_name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ProtocolError(
                    f"{field_name} must be an integer, got {value!r}", report=self.name()
                )
            if not low <= value <= high:
                raise ProtocolError(
                    f"{field_name} = {value} is outside [{low}, {high}]", report=self.name()
                )
        self._check()

    def _check(self) -> None:
        """Checks beyond the scalar ranges (arrays, cross-field rules); raise ProtocolError."""

    def _values(self) -> tuple[Any, ...]:
        """Values to pack after the report ID, in STRUCT order."""
        return tuple(getattr(self, f.name) for f in fields(self))  # type: ignore[arg-type]

    @classmethod
    def _from_values(cls: type[R], values: tuple[Any, ...]) -> R:
        """Build the report from the unpacked values (report ID removed)."""
        return cls(*values)

    def encode(self) -> bytes:
        """The report as sent on the wire: report ID byte then the fields, little endian."""
        return self.STRUCT.pack(self.REPORT_ID, *self._values())

    @classmethod
    def decode(cls: type[R], data: bytes | bytearray | memoryview) -> R:
        """Parse a report, report ID byte included.

        Bytes beyond the report's size (up to 64 in all) are ignored: some host stacks pad
        every report to the longest one of its kind (spec/device-protocol.md rule PT7).

        Raises:
            ProtocolError: wrong type, too short, longer than 64 bytes, wrong report ID, or a
                field out of its range.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise ProtocolError(f"expected bytes, got {type(data).__name__}", report=cls.name())
        data = bytes(data)
        if len(data) > MAX_REPORT_BYTES:
            raise ProtocolError(
                f"{len(data)} bytes exceed the {MAX_REPORT_BYTES}-byte report limit",
                report=cls.name(),
            )
        if len(data) < cls.STRUCT.size:
            raise ProtocolError(
                f"{len(data)} bytes is shorter than the report's {cls.STRUCT.size} bytes",
                report=cls.name(),
            )
        if data[0] != cls.REPORT_ID:
            raise ProtocolError(
                f"report ID 0x{data[0]:02X} is not 0x{cls.REPORT_ID:02X}", report=cls.name()
            )
        values = cls.STRUCT.unpack_from(data, 0)
        return cls._from_values(values[1:])


def narrow_ranges(report: type[Report], indices: dict[str, int]) -> tuple[tuple[int, str, int,
                                                                                 int], ...]:
    """The fields of ``report.RANGES`` whose range is narrower than their wire type, as
    (index in the unpacked values without the report ID, name, low, high): the only checks a
    decoded report needs, since unpacking cannot give a value outside its wire type.
    ``indices`` maps each ranged field to its index in the unpacked values."""
    expanded: list[str] = []
    digits = ""
    for char in report.STRUCT.format.lstrip("<>=!@"):
        if char.isdigit():
            digits += char
            continue
        expanded += [char] * int(digits or 1)
        digits = ""
    wire = expanded[1:]  # without the report ID byte
    narrow = []
    for name, (low, high) in report.RANGES.items():
        index = indices[name]
        wire_low, wire_high = _WIRE_RANGES[wire[index]]
        if low > wire_low or high < wire_high:
            narrow.append((index, name, low, high))
    return tuple(narrow)


# ---- field helpers shared by the report modules ------------------------------------------------

U8 = (0, 0xFF)
U16 = (0, 0xFFFF)
U32 = (0, 0xFFFF_FFFF)
I16 = (-0x8000, 0x7FFF)
I32 = (-0x8000_0000, 0x7FFF_FFFF)
_WIRE_RANGES = {"B": U8, "b": (-0x80, 0x7F), "H": U16, "I": U32, "h": I16, "i": I32}
"""Values each struct integer code of the reports can hold."""
POSITION_RANGE = (-2_000_000, 2_000_000)
"""Positions, 0.01 mm: +-20 m, twice the largest card surface side."""
MAX_FINGER_FORCE_MN = 50_000
"""Largest normal force a FINGER report may carry, mN (50 N; a pressing finger gives < 10 N)."""


def to_counts(value: float, unit: float, low: int, high: int, what: str) -> int:
    """Round an SI value to wire counts; ProtocolError when not finite or out of range."""
    if not math.isfinite(value):
        raise ProtocolError(f"{what} must be finite, got {value}")
    counts = round(value / unit)
    if not low <= counts <= high:
        raise ProtocolError(f"{what} = {value} is outside the wire range")
    return counts


def ascii_field(text: str, size: int, what: str) -> bytes:
    """A NUL-padded ASCII text field; ProtocolError when not printable ASCII or too long."""
    raw = text.encode("ascii", errors="strict") if text.isascii() else None
    if raw is None or not all(0x20 <= b < 0x7F for b in raw):
        raise ProtocolError(f"{what} must be printable ASCII, got {text!r}")
    if len(raw) > size:
        raise ProtocolError(f"{what} has {len(raw)} bytes, more than {size}")
    return raw


def text_from_wire(raw: bytes) -> str:
    """Decode a NUL-padded ASCII field; everything from the first NUL on is padding."""
    text = raw.split(b"\x00", 1)[0]
    try:
        return text.decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError("text field is not ASCII") from None
