"""Check ``device.descriptor`` (spec/conformance.md 4.10, rules H1-H3; protocol PD1, PD2): the
HID report descriptor the device returns, and the length its HID descriptor announces.

The host reads DEVICE_INFO (PV2), then the report descriptor (GET_DESCRIPTOR(Report), all of
it: :meth:`Driver.report_descriptor`) and the HID descriptor of the device's HID interface
(:meth:`Driver.hid_descriptor`), and judges three cases:

``exact-bytes`` (PD1, H1)
    the descriptor is byte for byte the table of spec/device-protocol.md 4.1
    (:data:`~hcard.device.protocol.REPORT_DESCRIPTOR`, from which that table is generated and
    held equal to it by the project's tests). Metric: the bytes that differ, a byte missing or
    extra counting as one.
``announced-length`` (PD1, H2)
    the HID descriptor announces the descriptor's length, 111 bytes (HID 1.11 6.2.1,
    ``wDescriptorLength`` of its report descriptor). Metric: how far the announced length is
    from it, bytes.
``declares-reports`` (PD2, H3)
    read with the suite's own item reader (:mod:`hcard_conformance.hid_items`, not the code
    that builds the reference device's descriptor): one Application collection on usage page
    0xFF00, usage 0x01, and inside it every report of the protocol declared once, as a byte
    array (Report Size 8, Logical Minimum 0, Logical Maximum 255) with a vendor usage equal to
    its report ID, at the size of its layout in :data:`~hcard.device.protocol.REPORT_CLASSES`
    (Report Count = size - 1), and no other report. Metric: the faults found.

Section 4.1 gives the bytes of protocol 1.4. A device of another minor version declares other
reports or sizes of right (PV4): ``exact-bytes`` is then not assessed, ``announced-length``
holds the announced length to the length read, and ``declares-reports`` judges the form of
every report declared but not the sizes. A driver whose transport cannot read a descriptor
(:class:`~hcard.device.errors.DescriptorUnavailable`: hidapi has no call for the HID
descriptor) leaves the cases that need it not assessed, saying why. Not applicable to a device
rendered on the host, whose HID protocol is its own (section 4, as the other wire-protocol
checks).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

from hcard.device.base import Driver
from hcard.device.errors import DescriptorUnavailable, DeviceStall
from hcard.device.protocol import PROTOCOL_MAJOR, PROTOCOL_MINOR, REPORT_DESCRIPTOR, ReportId
from hcard.device.protocol.reports import REPORT_CLASSES
from hcard_conformance.check_names import DEVICE_DESCRIPTOR as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, judged, on_one_driver
from hcard_conformance.hid_items import (
    Declarations,
    announced_report_length,
    declarations,
    report_sizes,
)
from hcard_conformance.result import CheckResult, unassessed

DESCRIPTOR_CASES = ("exact-bytes", "announced-length", "declares-reports")
"""The cases of ``device.descriptor``, in order."""
VENDOR_USAGE_PAGE = 0xFF00
"""The usage page of the Application collection and of every report's usage (PD2)."""
APPLICATION_USAGE = 0x01
"""The usage of the Application collection (PD2)."""
APPLICATION = 0x01
"""Collection type Application (HID 1.11 6.2.2.6)."""
BYTE_ARRAY = (8, 0, 255)
"""Report Size (bits), Logical Minimum and Logical Maximum of a byte array (PD2)."""
SHOWN_FAULTS = 4
"""Faults the detail of ``declares-reports`` spells out; the rest are counted."""


def protocol_sizes() -> dict[tuple[str, int], int]:
    """(kind, report ID) -> size in bytes, ID included, of every report of this protocol
    version: from the report layouts, not from any descriptor."""
    return {(cls.KIND.name.lower(), cls.REPORT_ID): cls.size() for cls in REPORT_CLASSES}


def _report(kind: str, report_id: int) -> str:
    try:
        name = f" ({ReportId(report_id).name})"
    except ValueError:
        name = ""
    return f"{kind} report 0x{report_id:02X}{name}"


def _usages(usages: tuple[tuple[int, int], ...]) -> str:
    return ", ".join(f"0x{page:04X}:0x{usage:02X}" for page, usage in usages) or "none"


def differing_bytes(got: bytes, expected: bytes) -> tuple[int, int | None]:
    """(bytes that differ, offset of the first) between ``got`` and ``expected``: a byte one
    has and the other lacks counts as differing; the offset is None when they are equal."""
    differ = [i for i, (a, b) in enumerate(zip(got, expected, strict=False)) if a != b]
    shorter = min(len(got), len(expected))
    count = len(differ) + abs(len(got) - len(expected))
    first = differ[0] if differ else (shorter if len(got) != len(expected) else None)
    return count, first


def judge_exact_bytes(got: bytes, expected: bytes = REPORT_DESCRIPTOR,
                      note: str = "") -> CheckResult:
    """``exact-bytes`` (H1): the descriptor read against section 4.1's bytes."""
    count, first = differing_bytes(got, expected)
    if first is None:
        detail = f"{len(got)} bytes, equal to spec/device-protocol.md 4.1 (PD1)"
    else:
        here = f"0x{got[first]:02X}" if first < len(got) else "nothing"
        there = f"0x{expected[first]:02X}" if first < len(expected) else "nothing"
        detail = (f"{note}{count} byte(s) differ from spec/device-protocol.md 4.1 (PD1), the "
                  f"first at offset 0x{first:04X}: {here} where 4.1 has {there}; {len(got)} "
                  f"bytes read, 4.1 has {len(expected)}")
    return judged(CHECK, "exact-bytes", "bytes_differing", float(count), 0.0, "bytes", detail)


def judge_announced_length(announced: int | None, expected: int, read: int | None,
                           what: str) -> CheckResult:
    """``announced-length`` (H2): the length the HID descriptor announces against
    ``expected`` (``what`` says where that number comes from); ``read``: the length of the
    descriptor read (None: not read)."""
    read_text = "" if read is None else f"; {read} bytes read"
    if announced is None:
        return judged(CHECK, "announced-length", "length_off", float("nan"), 0.0, "bytes",
                      "no HID descriptor naming a report descriptor after the HID interface "
                      f"(HID 1.11 6.2.1; PD1){read_text}")
    return judged(CHECK, "announced-length", "length_off", float(abs(announced - expected)),
                  0.0, "bytes", f"the HID descriptor announces {announced} bytes; {what} is "
                  f"{expected} (PD1){read_text}")


def declaration_faults(found: Declarations,
                       sizes: dict[tuple[str, int], int] | None) -> list[str]:
    """What in ``found`` is not as PD2 asks; ``sizes`` (:func:`protocol_sizes`): every report
    to be declared at its size and no other (None: sizes not judged)."""
    faults = list(found.unreadable)
    collections = found.collections
    if len(collections) != 1 or collections[0].kind != APPLICATION:
        kinds = ", ".join(f"0x{c.kind:02X}" for c in collections) or "none"
        faults.append(f"{len(collections)} collection(s) (types {kinds}), one Application "
                      "collection asked")
    elif collections[0].usages != ((VENDOR_USAGE_PAGE, APPLICATION_USAGE),):
        faults.append(f"the Application collection's usage is "
                      f"{_usages(collections[0].usages)}, 0xFF00:0x01 asked")
    items: dict[tuple[str, int], int] = {}
    for item in found.fields:
        name = _report(item.kind, item.report_id)
        key = (item.kind, item.report_id)
        items[key] = items.get(key, 0) + 1
        if item.report_id == 0:
            faults.append(f"an {item.kind} item before any Report ID (offset {item.offset})")
        if item.depth == 0:
            faults.append(f"{name} declared outside the Application collection")
        if (item.report_size, item.logical_min, item.logical_max) != BYTE_ARRAY:
            faults.append(f"{name}: Report Size {item.report_size}, Logical Minimum "
                          f"{item.logical_min}, Logical Maximum {item.logical_max}; a byte "
                          "array has 8, 0, 255")
        if item.usages != ((VENDOR_USAGE_PAGE, item.report_id),):
            faults.append(f"{name}: usage {_usages(item.usages)}, "
                          f"0xFF00:0x{item.report_id:02X} (its report ID) asked")
    faults += [f"{_report(*key)} declared in {n} main items, one asked"
               for key, n in items.items() if n > 1]
    if sizes is not None:
        declared = report_sizes(found)
        for key, size in sizes.items():
            got = declared.get(key)
            if got is None:
                faults.append(f"{_report(*key)} not declared (the protocol's is {size} bytes)")
            elif got != size:
                faults.append(f"{_report(*key)} declared {got} bytes, the protocol's is "
                              f"{size} (Report Count {size - 1})")
        faults += [f"{_report(*key)} declared, which the protocol does not define"
                   for key in declared if key not in sizes]
    return faults


def judge_declarations(descriptor: bytes, sizes: dict[tuple[str, int], int] | None,
                       note: str = "", unsized: str = "") -> CheckResult:
    """``declares-reports`` (H3): :func:`declaration_faults` of ``descriptor`` counted;
    ``unsized``: why the sizes are not judged (``sizes`` None)."""
    found = declarations(descriptor)
    faults = declaration_faults(found, sizes)
    if faults:
        shown = "; ".join(faults[:SHOWN_FAULTS])
        more = f"; and {len(faults) - SHOWN_FAULTS} more" if len(faults) > SHOWN_FAULTS else ""
        detail = f"{note}{len(faults)} fault(s) against PD2: {shown}{more}"
    else:
        how = "at the protocol's sizes" if sizes is not None else f"(sizes not judged: {unsized})"
        detail = (f"one Application collection on 0xFF00:0x01; {len(report_sizes(found))} "
                  f"reports declared as byte arrays with their IDs as usages {how} (PD2)")
    return judged(CHECK, "declares-reports", "declaration_faults", float(len(faults)), 0.0,
                  "faults", detail)


@dataclass(frozen=True)
class Read:
    """A descriptor as the driver read it: ``data`` (b"" when the device STALLed the request,
    a failure of PD1, said in ``note``; None when the transport cannot read it, ``why``)."""

    data: bytes | None
    note: str = ""
    why: str = ""


def read_descriptor(read: Callable[[], bytes], what: str) -> Read:
    """Call ``read`` (:meth:`Driver.report_descriptor` or :meth:`Driver.hid_descriptor`)."""
    try:
        return Read(read())
    except DescriptorUnavailable as exc:
        return Read(None, why=str(exc))
    except DeviceStall as exc:
        return Read(b"", note=f"the device STALLed GET_DESCRIPTOR({what}) ({exc}); ")


def announced_length_case(driver: Driver, report: Read, other: str) -> CheckResult:
    """``announced-length`` on ``driver``: against 111 bytes on a device of this protocol
    version (``other`` empty), else against the length of the descriptor read (``report``)."""
    hid = read_descriptor(driver.hid_descriptor, "HID")
    if hid.data is None:
        return unassessed(CHECK, LEVEL, "announced-length", hid.why)
    if hid.note:
        return judged(CHECK, "announced-length", "length_off", float("nan"), 0.0, "bytes",
                      f"{hid.note}no length announced (PD1)")
    announced = announced_report_length(hid.data)
    read = None if report.data is None else len(report.data)
    if not other:
        return judge_announced_length(announced, len(REPORT_DESCRIPTOR), read,
                                      "the length of section 4.1")
    if read is None:
        return unassessed(CHECK, LEVEL, "announced-length", f"{other}, and {report.why}")
    return judge_announced_length(announced, read, read, "the length of the descriptor read")


def measure_descriptor(driver: Driver, wants: Callable[[str], bool] | None = None,
                       ) -> Iterator[CheckResult]:
    """The cases of ``device.descriptor`` on one open driver (module docstring); with
    ``wants``, only the cases it is true of."""
    cases = [case for case in DESCRIPTOR_CASES if wants is None or wants(case)]
    info = driver.info()
    version = (info.protocol_major, info.protocol_minor)
    other = ("" if version == (PROTOCOL_MAJOR, PROTOCOL_MINOR) else
             f"the device speaks protocol {version[0]}.{version[1]}; section 4.1 gives the "
             f"descriptor of {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}")
    report = read_descriptor(driver.report_descriptor, "Report")
    for case in cases:
        if case == "announced-length":
            yield announced_length_case(driver, report, other)
        elif report.data is None:
            yield unassessed(CHECK, LEVEL, case, report.why)
        elif case == "exact-bytes":
            yield (unassessed(CHECK, LEVEL, case, other) if other
                   else judge_exact_bytes(report.data, note=report.note))
        else:
            yield judge_declarations(report.data, None if other else protocol_sizes(),
                                     report.note, other)


def check_descriptor(ctx: Context) -> Iterator[CheckResult]:
    """The report descriptor is section 4.1's, announced at its length, and declares every
    report as PD2 asks (PD1, PD2)."""
    yield from on_one_driver(ctx, CHECK, DESCRIPTOR_CASES, measure_descriptor)
