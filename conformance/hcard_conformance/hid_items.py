"""What a HID report descriptor declares, read item by item (HID 1.11 6.2.2), and the length a
HID descriptor announces (HID 1.11 6.2.1): the suite's own reading for ``device.descriptor``
(device protocol PD1, PD2).

Written apart from :mod:`hcard.device.protocol.descriptor`, which builds the reference device's
descriptor, so that a mistake there is not repeated here: a check that read the bytes with the
code that wrote them would pass whatever they say.

:func:`declarations` walks the short items with the HID parser's state: the global items
(Usage Page, Logical Minimum/Maximum, Report Size, Report ID, Report Count; Push and Pop) stay
in force until changed, the local items (Usage) apply to the next main item only. Each Input,
Output and Feature item becomes a :class:`Field`, each Collection a :class:`Collection`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

MAIN, GLOBAL, LOCAL = 0, 1, 2
"""Item types (bType, HID 1.11 6.2.2.2)."""
INPUT, OUTPUT, FEATURE, COLLECTION, END_COLLECTION = 0x8, 0x9, 0xB, 0xA, 0xC
"""Main item tags (HID 1.11 6.2.2.4)."""
KINDS = {INPUT: "input", OUTPUT: "output", FEATURE: "feature"}
"""The report kind of each data main item."""
LONG_ITEM = 0xFE
"""Prefix of a long item (HID 1.11 6.2.2.3)."""
HID_DESCRIPTOR_TYPE, REPORT_DESCRIPTOR_TYPE = 0x21, 0x22
"""bDescriptorType of the HID descriptor and of the report descriptor (HID 1.11 7.1)."""
_G_PAGE, _G_LMIN, _G_LMAX, _G_SIZE, _G_ID, _G_COUNT, _G_PUSH, _G_POP = 0, 1, 2, 7, 8, 9, 10, 11
_SIGNED = (_G_LMIN, _G_LMAX)


@dataclass(frozen=True)
class Field:
    """One Input, Output or Feature main item and the state it was declared in.

    Attributes:
        offset: position of the main item in the descriptor, bytes.
        kind: ``input``, ``output`` or ``feature``.
        report_id: the Report ID in force (0: none declared yet).
        report_size: bits per field; report_count: fields; size_bits their product.
        logical_min, logical_max: the logical range of a field (signed).
        usages: (usage page, usage ID) of each Usage before it.
        depth: collections open around it.
    """

    offset: int
    kind: str
    report_id: int
    report_size: int
    report_count: int
    logical_min: int
    logical_max: int
    usages: tuple[tuple[int, int], ...]
    depth: int

    @property
    def size_bits(self) -> int:
        """Bits the item adds to its report."""
        return self.report_size * self.report_count


@dataclass(frozen=True)
class Collection:
    """One Collection item: ``kind`` 1 is Application (HID 1.11 6.2.2.6); ``usages`` as
    :class:`Field`'s; ``depth`` the collections already open around it."""

    offset: int
    kind: int
    usages: tuple[tuple[int, int], ...]
    depth: int


@dataclass
class Declarations:
    """What a report descriptor declares: its fields and collections in order, and what could
    not be read (a long or truncated item, a Pop without Push, collections that do not close;
    offsets in bytes)."""

    fields: list[Field] = field(default_factory=list)
    collections: list[Collection] = field(default_factory=list)
    unreadable: list[str] = field(default_factory=list)


def declarations(descriptor: bytes) -> Declarations:
    """Read ``descriptor`` item by item (module docstring)."""
    found = Declarations()
    state = {_G_PAGE: 0, _G_LMIN: 0, _G_LMAX: 0, _G_SIZE: 0, _G_ID: 0, _G_COUNT: 0}
    stack: list[dict[int, int]] = []
    usages: list[tuple[int, int]] = []
    depth = pos = 0
    while pos < len(descriptor):
        prefix = descriptor[pos]
        if prefix == LONG_ITEM:
            found.unreadable.append(f"a long item at offset {pos}")
            break
        size = (0, 1, 2, 4)[prefix & 0x3]
        if pos + 1 + size > len(descriptor):
            found.unreadable.append(f"the item at offset {pos} is cut short")
            break
        raw = descriptor[pos + 1:pos + 1 + size]
        tag, kind = prefix >> 4, (prefix >> 2) & 0x3
        value = int.from_bytes(raw, "little", signed=kind == GLOBAL and tag in _SIGNED)
        if kind == GLOBAL and tag == _G_PUSH:
            stack.append(dict(state))
        elif kind == GLOBAL and tag == _G_POP:
            if stack:
                state = stack.pop()
            else:
                found.unreadable.append(f"a Pop without Push at offset {pos}")
        elif kind == GLOBAL:
            state[tag] = value
        elif kind == LOCAL and tag == 0:  # Usage; four bytes carry their own page
            usages.append((value >> 16, value & 0xFFFF) if size == 4
                          else (state[_G_PAGE], value))
        elif kind == MAIN and tag in KINDS:
            found.fields.append(Field(pos, KINDS[tag], state[_G_ID], state[_G_SIZE],
                                      state[_G_COUNT], state[_G_LMIN], state[_G_LMAX],
                                      tuple(usages), depth))
        elif kind == MAIN and tag == COLLECTION:
            found.collections.append(Collection(pos, value, tuple(usages), depth))
            depth += 1
        elif kind == MAIN and tag == END_COLLECTION:
            if depth == 0:
                found.unreadable.append(f"an End Collection without Collection at offset {pos}")
            depth = max(depth - 1, 0)
        if kind == MAIN:
            usages = []
        pos += 1 + size
    if depth:
        found.unreadable.append(f"{depth} collection(s) never closed")
    return found


def report_sizes(found: Declarations) -> dict[tuple[str, int], int]:
    """(kind, report ID) -> the report's size in bytes, its ID byte included (HID 1.11 5.6:
    a report's fields in declaration order, padded to whole bytes)."""
    bits: dict[tuple[str, int], int] = {}
    for item in found.fields:
        key = (item.kind, item.report_id)
        bits[key] = bits.get(key, 0) + item.size_bits
    return {key: 1 + (total + 7) // 8 for key, total in bits.items()}


def announced_report_length(hid_descriptor: bytes) -> int | None:
    """The report descriptor's length a HID descriptor announces, bytes (the
    ``wDescriptorLength`` of its first class descriptor of type 0x22, HID 1.11 6.2.1); None when
    the bytes are no HID descriptor or name no report descriptor."""
    if len(hid_descriptor) < 6 or hid_descriptor[1] != HID_DESCRIPTOR_TYPE:
        return None
    count = hid_descriptor[5]
    for index in range(count):
        at = 6 + 3 * index
        if at + 3 > len(hid_descriptor):
            return None
        kind, length = struct.unpack_from("<BH", hid_descriptor, at)
        if kind == REPORT_DESCRIPTOR_TYPE:
            return int(length)
    return None
