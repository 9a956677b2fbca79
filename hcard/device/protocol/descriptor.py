"""The HID report descriptor of the hcard device, built from HID short items (HID 1.11 6.2.2),
and a parser that turns descriptor bytes back into a readable item-by-item dump.

The descriptor declares one application collection on the vendor usage page 0xFF00 and, for
every report of :data:`~hcard.device.protocol.reports.REPORT_CLASSES`, its report ID, a vendor
usage equal to the ID and a byte array of the report's payload size. The field layout inside
the bytes is defined by the spec (the descriptor does not describe it field by field, as is
usual for vendor-defined devices: no OS driver interprets them).
"""

from __future__ import annotations

from dataclasses import dataclass

from hcard.device.protocol.constants import (
    APPLICATION_USAGE,
    VENDOR_USAGE_PAGE,
    ReportId,
    ReportKind,
)
from hcard.device.protocol.reports import REPORT_CLASSES

MAIN, GLOBAL, LOCAL = 0, 1, 2
"""Item types (bType)."""

DATA_VAR_ABS = 0x02
"""Main item flags: Data, Variable, Absolute (HID 1.11 6.2.2.5)."""
COLLECTION_APPLICATION = 0x01

_MAIN_TAG = {ReportKind.INPUT: 0x8, ReportKind.OUTPUT: 0x9, ReportKind.FEATURE: 0xB}

_ITEM_NAMES = {
    (MAIN, 0x8): "Input",
    (MAIN, 0x9): "Output",
    (MAIN, 0xB): "Feature",
    (MAIN, 0xA): "Collection",
    (MAIN, 0xC): "End Collection",
    (GLOBAL, 0x0): "Usage Page",
    (GLOBAL, 0x1): "Logical Minimum",
    (GLOBAL, 0x2): "Logical Maximum",
    (GLOBAL, 0x3): "Physical Minimum",
    (GLOBAL, 0x4): "Physical Maximum",
    (GLOBAL, 0x5): "Unit Exponent",
    (GLOBAL, 0x6): "Unit",
    (GLOBAL, 0x7): "Report Size",
    (GLOBAL, 0x8): "Report ID",
    (GLOBAL, 0x9): "Report Count",
    (GLOBAL, 0xA): "Push",
    (GLOBAL, 0xB): "Pop",
    (LOCAL, 0x0): "Usage",
    (LOCAL, 0x1): "Usage Minimum",
    (LOCAL, 0x2): "Usage Maximum",
}
_COLLECTION_NAMES = {0: "Physical", 1: "Application", 2: "Logical", 3: "Report"}
_MAIN_FLAG_BITS = (
    ("Data", "Const"),
    ("Array", "Var"),
    ("Abs", "Rel"),
    ("No Wrap", "Wrap"),
    ("Linear", "Non Linear"),
    ("Preferred", "No Preferred"),
    ("No Null", "Null"),
    ("Non Volatile", "Volatile"),
    ("Bit Field", "Buffered Bytes"),
)
_KIND_OF_MAIN_TAG = {tag: kind for kind, tag in _MAIN_TAG.items()}


# ---- building ---------------------------------------------------------------------------------


def short_item(
    tag: int, item_type: int, value: int | None = None, *, signed: bool = False
) -> bytes:
    """One short item: prefix byte then 0, 1, 2 or 4 little-endian data bytes.

    The data size is the smallest that holds ``value`` (as a signed number when ``signed``,
    which HID requires for Logical/Physical Minimum and Maximum).
    """
    if value is None:
        return bytes([(tag << 4) | (item_type << 2)])
    for size, code in ((1, 1), (2, 2), (4, 3)):
        bits = 8 * size
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if low <= value <= high:
            data = value.to_bytes(size, "little", signed=signed)
            return bytes([(tag << 4) | (item_type << 2) | code]) + data
    raise ValueError(f"item value {value} does not fit 4 bytes")


def usage_page(page: int) -> bytes:
    """Global item Usage Page."""
    return short_item(0x0, GLOBAL, page)


def usage(value: int) -> bytes:
    """Local item Usage."""
    return short_item(0x0, LOCAL, value)


def logical_minimum(value: int) -> bytes:
    """Global item Logical Minimum (signed)."""
    return short_item(0x1, GLOBAL, value, signed=True)


def logical_maximum(value: int) -> bytes:
    """Global item Logical Maximum (signed)."""
    return short_item(0x2, GLOBAL, value, signed=True)


def report_size(bits: int) -> bytes:
    """Global item Report Size, bits per field."""
    return short_item(0x7, GLOBAL, bits)


def report_id(value: int) -> bytes:
    """Global item Report ID."""
    return short_item(0x8, GLOBAL, value)


def report_count(count: int) -> bytes:
    """Global item Report Count, number of fields."""
    return short_item(0x9, GLOBAL, count)


def collection(kind: int) -> bytes:
    """Main item Collection."""
    return short_item(0xA, MAIN, kind)


def end_collection() -> bytes:
    """Main item End Collection."""
    return short_item(0xC, MAIN)


def main_item(kind: ReportKind, flags: int = DATA_VAR_ABS) -> bytes:
    """Main item Input, Output or Feature."""
    return short_item(_MAIN_TAG[kind], MAIN, flags)


def build_descriptor() -> bytes:
    """The report descriptor: every report as a byte array of its payload (size - 1 bytes)."""
    items = [
        usage_page(VENDOR_USAGE_PAGE),
        usage(APPLICATION_USAGE),
        collection(COLLECTION_APPLICATION),
        logical_minimum(0),
        logical_maximum(255),
        report_size(8),
    ]
    for cls in REPORT_CLASSES:
        items += [
            report_id(cls.REPORT_ID),
            usage(cls.REPORT_ID),
            report_count(cls.size() - 1),
            main_item(cls.KIND),
        ]
    items.append(end_collection())
    return b"".join(items)


REPORT_DESCRIPTOR: bytes = build_descriptor()
"""The HID report descriptor the device returns for GET_DESCRIPTOR(Report)."""


# ---- parsing and dumping ----------------------------------------------------------------------


@dataclass(frozen=True)
class Item:
    """One parsed short item.

    Attributes:
        offset: position of the prefix byte in the descriptor.
        raw: the item's bytes (prefix and data).
        item_type: MAIN, GLOBAL or LOCAL.
        tag: the item tag.
        data: unsigned value of the data bytes (0 when there are none).
    """

    offset: int
    raw: bytes
    item_type: int
    tag: int
    data: int

    @property
    def name(self) -> str:
        """HID name of the item, e.g. ``Report Count``."""
        unknown = f"Item(type={self.item_type}, tag={self.tag:#x})"
        return _ITEM_NAMES.get((self.item_type, self.tag), unknown)

    @property
    def signed_data(self) -> int:
        """The data bytes as a signed number."""
        size = len(self.raw) - 1
        return int.from_bytes(self.raw[1:], "little", signed=True) if size else 0


def parse_items(descriptor: bytes) -> list[Item]:
    """Split a report descriptor into short items.

    Raises:
        ValueError: a long item (not used by this device) or a truncated item.
    """
    items: list[Item] = []
    pos = 0
    while pos < len(descriptor):
        prefix = descriptor[pos]
        if prefix == 0xFE:
            raise ValueError(f"long item at offset {pos}: not supported")
        size = (0, 1, 2, 4)[prefix & 0x3]
        end = pos + 1 + size
        if end > len(descriptor):
            raise ValueError(f"item at offset {pos} is truncated")
        raw = descriptor[pos:end]
        data = int.from_bytes(raw[1:], "little") if size else 0
        items.append(Item(pos, raw, (prefix >> 2) & 0x3, prefix >> 4, data))
        pos = end
    return items


def report_sizes(descriptor: bytes) -> dict[tuple[ReportKind, int], int]:
    """Size in bytes (report ID included) of every report the descriptor declares."""
    bits: dict[tuple[ReportKind, int], int] = {}
    size = count = rid = 0
    for item in parse_items(descriptor):
        if item.item_type == GLOBAL and item.tag == 0x7:
            size = item.data
        elif item.item_type == GLOBAL and item.tag == 0x8:
            rid = item.data
        elif item.item_type == GLOBAL and item.tag == 0x9:
            count = item.data
        elif item.item_type == MAIN and item.tag in _KIND_OF_MAIN_TAG:
            key = (_KIND_OF_MAIN_TAG[item.tag], rid)
            bits[key] = bits.get(key, 0) + size * count
    return {key: 1 + (total + 7) // 8 for key, total in bits.items()}


def _describe(item: Item, report_name: dict[int, str], state: dict[str, int]) -> str:
    name = item.name
    if item.item_type == GLOBAL and item.tag == 0x0:
        vendor = ", vendor-defined" if item.data >= 0xFF00 else ""
        return f"{name} (0x{item.data:04X}{vendor})"
    if item.item_type == GLOBAL and item.tag in (0x1, 0x2, 0x3, 0x4):
        return f"{name} ({item.signed_data})"
    if item.item_type == GLOBAL and item.tag == 0x8:
        state["id"] = item.data
        return f"{name} (0x{item.data:02X}: {report_name.get(item.data, 'unknown')})"
    if item.item_type == GLOBAL and item.tag == 0x7:
        state["size"] = item.data
        return f"{name} ({item.data})"
    if item.item_type == GLOBAL and item.tag == 0x9:
        state["count"] = item.data
        return f"{name} ({item.data})"
    if item.item_type == LOCAL and item.tag in (0x0, 0x1, 0x2):
        return f"{name} (0x{item.data:02X})"
    if item.item_type == MAIN and item.tag == 0xA:
        return f"{name} ({_COLLECTION_NAMES.get(item.data, f'0x{item.data:02X}')})"
    if item.item_type == MAIN and item.tag in _KIND_OF_MAIN_TAG:
        flags = ",".join(pair[(item.data >> b) & 1] for b, pair in enumerate(_MAIN_FLAG_BITS[:3]))
        payload = state.get("size", 0) * state.get("count", 0) // 8
        rid = state.get("id", 0)
        return (
            f"{name} ({flags})  -> {report_name.get(rid, 'unknown')}: "
            f"{payload} + 1 = {payload + 1} bytes"
        )
    if item.raw[1:]:
        return f"{name} (0x{item.data:X})"
    return name


def dump(descriptor: bytes = REPORT_DESCRIPTOR) -> str:
    """Readable item-by-item dump: offset, bytes, item name and value, indented by collection."""
    names = {int(r): r.name for r in ReportId}
    state: dict[str, int] = {}
    lines = []
    depth = 0
    for item in parse_items(descriptor):
        if item.item_type == MAIN and item.tag == 0xC:
            depth = max(depth - 1, 0)
        hex_bytes = " ".join(f"{b:02X}" for b in item.raw)
        text = _describe(item, names, state)
        lines.append(f"{item.offset:04X}  {hex_bytes:<12}  {'  ' * depth}{text}")
        if item.item_type == MAIN and item.tag == 0xA:
            depth += 1
    return "\n".join(lines) + "\n"


def hex_dump(descriptor: bytes = REPORT_DESCRIPTOR, per_line: int = 16) -> str:
    """The descriptor bytes as hex, ``per_line`` bytes a line, offsets on the left."""
    lines = []
    for start in range(0, len(descriptor), per_line):
        chunk = descriptor[start : start + per_line]
        lines.append(f"{start:04X}  " + " ".join(f"{b:02X}" for b in chunk))
    return "\n".join(lines) + "\n"
