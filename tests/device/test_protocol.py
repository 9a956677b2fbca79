"""The device protocol codec (spec/device-protocol.md): round trips, layouts, ranges, fuzzing,
and agreement between the spec's tables and dumps and the code."""

from __future__ import annotations

import dataclasses
import re
import struct
import zlib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hcard.device.protocol import (
    ECHO_AGE_UNKNOWN,
    MAX_REPORT_BYTES,
    REPORT_CLASSES,
    REPORT_DESCRIPTOR,
    STREAM_FRAMES_PER_REPORT,
    UPLOAD_CHUNK_BYTES,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    Finger,
    Limits,
    ProtocolError,
    Report,
    ReportId,
    ReportKind,
    State,
    Stream,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadStatus,
    crc32,
    decode,
    decode_feature,
    decode_input,
    decode_output,
    dump,
    hex_dump,
    report_class,
    report_ids,
    report_sizes,
    stream_reports,
    upload_reports,
)
from hcard.device.protocol.__main__ import generated_blocks, main, output_for, update_spec
from hcard.device.protocol.constants import CLIP_NAME_BYTES, UPLOAD_DETAIL_BYTES
from hcard.device.protocol.descriptor import parse_items, short_item
from hcard.errors import HcardError

SPEC = Path(__file__).resolve().parents[2] / "spec" / "device-protocol.md"

ASCII = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E))


def _ints(low: int, high: int) -> st.SearchStrategy[int]:
    return st.integers(min_value=low, max_value=high)


def report_strategy(cls: type[Report]) -> st.SearchStrategy[Report]:
    """Every valid value of every field of a report class."""
    fields = {name: _ints(low, high) for name, (low, high) in cls.RANGES.items()}
    if cls is State:
        fields["corner_forces_mn"] = st.tuples(*[_ints(-0x8000, 0x7FFF)] * 4)
    elif cls is Stream:
        return st.integers(1, STREAM_FRAMES_PER_REPORT).flatmap(
            lambda n: st.builds(
                Stream,
                stream_seq=_ints(0, 0xFFFF),
                uv_x1e4=st.tuples(*[_ints(0, 10_000)] * n),
                ev_x1e4=st.tuples(*[_ints(10_000, 40_000)] * n),
            )
        )
    elif cls is Control:
        fields["command"] = st.sampled_from([int(c) for c in Command])
        return st.builds(
            lambda command, argument: Control(  # TAKE_OVER needs a token (1.2, PN6)
                command, argument if command == Command.SET_TOUCH_SOURCE
                else 1 if command == Command.TAKE_OVER else 0
            ),
            fields["command"],
            _ints(0, 1),
        )
    elif cls is UploadData:
        fields["data"] = st.binary(max_size=UPLOAD_CHUNK_BYTES)
    elif cls is UploadEnd:
        fields["action"] = _ints(0, 2)
    elif cls is UploadStatus:
        fields["detail"] = ASCII.filter(lambda s: len(s) <= UPLOAD_DETAIL_BYTES)
    elif cls is ClipReport:
        fields["texture_name"] = ASCII.filter(lambda s: len(s) <= CLIP_NAME_BYTES)
    return st.builds(cls, **fields)


ALL_REPORTS = st.one_of(*[report_strategy(cls) for cls in REPORT_CLASSES])


# ---- round trips ------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", REPORT_CLASSES, ids=lambda c: c.name())
@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_every_report_round_trips(cls: type[Report], data: st.DataObject) -> None:
    report = data.draw(report_strategy(cls))
    wire = report.encode()
    assert len(wire) == cls.size() <= MAX_REPORT_BYTES
    assert wire[0] == cls.REPORT_ID
    assert cls.decode(wire) == report
    assert decode(cls.KIND, wire) == report
    # PT7: padding up to 64 bytes is ignored, whatever it holds
    padded = wire + bytes(range(1, MAX_REPORT_BYTES - len(wire) + 1))
    assert cls.decode(padded) == report


def test_report_table_matches_the_spec() -> None:
    text = SPEC.read_text(encoding="utf-8")
    overview = text[text.index("## 5. Reports overview") : text.index("## 6. Input report")]
    rows = re.findall(r"^\| 0x([0-9A-F]{2}) \| (\w+) \| (\w+) \| (\d+) \|", overview, re.M)
    table = {int(rid, 16): (name, kind, int(size)) for rid, name, kind, size in rows}
    code = {c.REPORT_ID: (c.name(), c.KIND.name.lower(), c.size()) for c in REPORT_CLASSES}
    assert table == code
    assert len(code) == 12


def test_report_sizes_and_ids() -> None:
    assert {c.REPORT_ID for c in REPORT_CLASSES} == {int(r) for r in ReportId}
    assert all(c.size() <= 64 for c in REPORT_CLASSES)
    assert (State.size(), State.SESSION_SIZE, State.LEGACY_SIZE) == (59, 55, 52)  # 1.2, 1.3 append
    assert Stream.size() == UploadData.size() == UploadStatus.size() == 64
    assert report_ids(ReportKind.OUTPUT) == (0x10, 0x11, 0x12)
    assert report_ids(ReportKind.FEATURE) == tuple(range(0x20, 0x28))
    assert report_ids(ReportKind.INPUT) == (0x01,)


# ---- the layout of the spec's field tables --------------------------------------------------

_TYPE_BYTES = {"u8": 1, "u16": 2, "u32": 4, "i16": 2, "i32": 4}


def _type_size(text: str) -> int:
    text = text.strip("`")
    if m := re.fullmatch(r"(\w+)\[(\d+)\]", text):
        unit = 1 if m.group(1) == "char" else _TYPE_BYTES[m.group(1)]
        return unit * int(m.group(2))
    if m := re.fullmatch(r"\(u16, u16\)\[(\d+)\]", text):
        return 4 * int(m.group(1))
    return _TYPE_BYTES[text]


def _spec_layouts() -> dict[int, list[tuple[int, int, str]]]:
    """Report ID -> [(offset, size, field)] from every field table of the spec."""
    text = SPEC.read_text(encoding="utf-8")
    layouts: dict[int, list[tuple[int, int, str]]] = {}
    for table in re.findall(r"\| Offset \| Type \| Field \|.*?\n((?:\|.*\n)+)", text):
        rows = re.findall(r"^\| (\d+) \| ([^|]+?) \| (\w+) \|", table, re.M)
        parsed = [(int(off), _type_size(typ), name) for off, typ, name in rows]
        rid_row = re.search(r"\| 0 \| u8 \| report_id \| - \| 0x([0-9A-F]{2}) \|", table)
        assert rid_row, table
        layouts[int(rid_row.group(1), 16)] = parsed
    return layouts


def test_spec_field_tables_match_the_struct_layouts() -> None:
    layouts = _spec_layouts()
    assert set(layouts) == {c.REPORT_ID for c in REPORT_CLASSES}
    for cls in REPORT_CLASSES:
        rows = layouts[cls.REPORT_ID]
        offset = 0
        for row_offset, size, _name in rows:
            assert row_offset == offset, (cls.name(), rows)
            offset += size
        assert offset == cls.size(), cls.name()
        # the struct agrees byte for byte: every field's offset matches the spec's
        fmt = cls.STRUCT.format.lstrip("<")
        items = re.findall(r"(\d*)([A-Za-z])", fmt)
        struct_offsets, position = [], 0
        for count, code in items:
            n = int(count or 1)
            if code == "s":
                struct_offsets.append(position)
                position += n
                continue
            for _ in range(n):
                struct_offsets.append(position)
                position += struct.calcsize("<" + code)
        assert {r[0] for r in rows} <= set(struct_offsets), cls.name()


def test_spec_field_names_are_the_dataclass_fields() -> None:
    layouts = _spec_layouts()
    renamed = {"count": None, "frames": ("uv_x1e4", "ev_x1e4"), "length": None}
    for cls in REPORT_CLASSES:
        names: list[str] = []
        for _, _, name in layouts[cls.REPORT_ID][1:]:
            mapped = renamed.get(name, name) if cls in (Stream, UploadData) else name
            if mapped is None:
                continue
            names.extend(mapped if isinstance(mapped, tuple) else (mapped,))
        assert names == [f.name for f in dataclasses.fields(cls)], cls.name()


def test_state_layout_golden_bytes() -> None:
    report = State(
        timestamp_us=0x01020304, sequence=0xBEEF, flags=0b101, x_10um=-2, y_10um=5400,
        corner_forces_mn=(100, -1, 300, 400), lateral_force_mn=-250, amplitude_nm=2000,
        voltage_dv=20000, current_10na=25000, target_uv_x1e4=7000, target_ev_x1e4=40000,
        texture=-1, faults=0x0108, dropped_reports=3, rejected_requests=4, stream_queued=2000,
        host_time_echo_us=0xFFFFFFFF, card_generation=7,
    )  # fmt: skip
    wire = report.encode()
    assert wire[:8] == bytes.fromhex("01 04030201 EFBE 05")
    assert wire[8:12] == b"\xfe\xff\xff\xff"  # -2 as i32
    assert wire[12:16] == (5400).to_bytes(4, "little")
    assert wire[16:24] == bytes.fromhex("6400 FFFF 2C01 9001")
    assert wire[36:38] == b"\xff\xff"  # texture -1
    assert wire[38:40] == bytes.fromhex("0801")
    assert wire[46:52] == bytes.fromhex("FFFFFFFF 0700")
    assert report.normal_force_n == pytest.approx(0.799)
    assert report.target_uv == 0.7 and report.target_ev == 4.0
    assert report.voltage_v == pytest.approx(2000.0)
    assert report.current_a == pytest.approx(250e-6)
    assert report.amplitude_m == pytest.approx(2e-6)
    assert report.contact and report.y_mm == pytest.approx(54.0)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(raw=st.binary(min_size=State.STRUCT.size - 1, max_size=State.STRUCT.size - 1))
def test_state_decode_accepts_exactly_what_the_checked_constructor_accepts(raw: bytes) -> None:
    """The decoder checks only the ranges narrower than their wire type; on any bytes it must
    agree with the constructor, which checks every field: same report, or both refuse."""
    data = bytes([ReportId.STATE]) + raw
    values = struct.unpack("<BIHBii4hhHHHHHhHHHHIHHBI", data)[1:]
    try:
        expected: State | None = State(*values[:5], tuple(values[5:9]), *values[9:])
    except ProtocolError:
        expected = None
    if expected is None:
        with pytest.raises(ProtocolError, match="outside"):
            State.decode(data)
    else:
        assert State.decode(data) == expected
        assert State.decode(data).encode() == data


def test_state_decode_names_each_narrow_field_out_of_range() -> None:
    good = State(timestamp_us=1, sequence=2, flags=0, x_10um=0, y_10um=0,
                 corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0, amplitude_nm=0,
                 voltage_dv=0, current_10na=0, target_uv_x1e4=5000, target_ev_x1e4=20000,
                 texture=3, faults=0, dropped_reports=0, rejected_requests=0,
                 stream_queued=0, host_time_echo_us=0, card_generation=0).encode()
    for offset, fmt, value, name in ((8, "<i", 2_000_001, "x_10um"),
                                     (12, "<i", -2_000_001, "y_10um"),
                                     (32, "<H", 10_001, "target_uv_x1e4"),
                                     (34, "<H", 9_999, "target_ev_x1e4"),
                                     (36, "<h", -2, "texture")):
        bad = bytearray(good)
        struct.pack_into(fmt, bad, offset, value)
        with pytest.raises(ProtocolError, match=rf"STATE: {name} = {value} is outside"):
            State.decode(bytes(bad))


def test_finger_from_si_and_layout() -> None:
    report = Finger.from_si(1.5, 12.5, -3.25, 0.8, True)
    assert (report.host_time_us, report.x_10um, report.y_10um, report.fn_mn) == (
        1_500_000, 1250, -325, 800
    )
    assert report.encode() == bytes.fromhex("10 60E31600 E2040000 BBFEFFFF 2003 01")
    assert report.contact and report.fn_n == pytest.approx(0.8)
    # host time wraps modulo 2**32 us
    assert Finger.from_si(4294.967296 + 1e-6, 0, 0, 0, False).host_time_us == 1
    for bad in (
        lambda: Finger.from_si(0, float("nan"), 0, 0, True),
        lambda: Finger.from_si(0, 0, 0, -0.001, True),
        lambda: Finger.from_si(0, 0, 0, 50.001, True),
        lambda: Finger.from_si(0, 20_000.01, 0, 0, True),
        lambda: Finger.from_si(float("inf"), 0, 0, 0, True),
    ):
        with pytest.raises(ProtocolError):
            bad()


# ---- bad input: one test per class of malformation -------------------------------------------


@pytest.mark.parametrize("cls", REPORT_CLASSES, ids=lambda c: c.name())
# whole reports of every field drawn at random are large examples by hypothesis's measure
# (hypothesis 6.80 refused UPLOAD_STATUS's as data_too_large)
@settings(max_examples=20, suppress_health_check=[HealthCheck.data_too_large])
@given(data=st.data())
def test_truncated_oversized_and_misnumbered_reports_are_rejected(
    cls: type[Report], data: st.DataObject
) -> None:
    wire = data.draw(report_strategy(cls)).encode()
    if cls is State:  # a 1.0/1.1 STATE (no session fields, PV4) reads as session 0, token 0
        legacy = cls.decode(wire[:State.LEGACY_SIZE])
        assert (legacy.session_number, legacy.session_token) == (0, 0)
        assert legacy.echo_age_s is None
        full = cls.decode(wire)
        sessions = cls.decode(wire[:State.SESSION_SIZE])  # a 1.2 STATE: no echo age (PI3)
        assert (sessions.session_number, sessions.session_token) == (
            full.session_number, full.session_token)
        assert sessions.echo_age_us == ECHO_AGE_UNKNOWN and sessions.echo_age_s is None
        with pytest.raises(ProtocolError, match="shorter"):
            cls.decode(wire[:State.SESSION_SIZE + 2])  # neither a 1.2 nor a 1.3 STATE
        wire = wire[:State.LEGACY_SIZE]
    with pytest.raises(ProtocolError, match="shorter"):
        cls.decode(wire[:-1])
    with pytest.raises(ProtocolError, match="64-byte"):
        cls.decode(wire + bytes(65 - len(wire)))
    with pytest.raises(ProtocolError, match="report ID"):
        cls.decode(bytes([cls.REPORT_ID ^ 0x80]) + wire[1:])
    with pytest.raises(ProtocolError, match="expected bytes"):
        cls.decode("not bytes")  # type: ignore[arg-type]


def test_unknown_and_wrong_kind_ids_are_rejected() -> None:
    with pytest.raises(ProtocolError, match="no feature report with ID 0x10"):
        decode_feature(Finger(0, 0, 0, 0, 1).encode())
    with pytest.raises(ProtocolError, match="no output report with ID 0x20"):
        decode_output(b"\x20" + bytes(36))
    with pytest.raises(ProtocolError, match="no input report with ID 0x00"):
        decode_input(bytes(52))
    with pytest.raises(ProtocolError, match="no feature report with ID 0xFF"):
        report_class(ReportKind.FEATURE, 0xFF)
    with pytest.raises(ProtocolError, match="unknown report kind"):
        report_class(7, 0x01)
    with pytest.raises(ProtocolError, match="empty report"):
        decode_output(b"")
    assert issubclass(ProtocolError, HcardError)


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        (Finger(0, 0, 0, 0, 1).encode()[:13] + (50_001).to_bytes(2, "little") + b"\x01",
         r"fn_mn = 50001 is outside \[0, 50000\]"),
        (b"\x10" + bytes(4) + (2_000_001).to_bytes(4, "little", signed=True) + bytes(7),
         r"x_10um = 2000001"),
        (b"\x11\x00\x00\x00" + bytes(60), r"frame count 0"),
        (b"\x11\x00\x00\x10" + bytes(60), r"frame count 16"),
        (b"\x11\x00\x00\x01" + (10_001).to_bytes(2, "little") + (10_000).to_bytes(2, "little")
         + bytes(56), r"frame 0: uv 10001"),
        (b"\x11\x00\x00\x02" + bytes([0x10, 0x27, 0x10, 0x27, 0, 0, 0x0F, 0x27]) + bytes(52),
         r"frame 1: ev 9999"),
        (b"\x12\x08\x00", r"unknown command 8"),
        (b"\x12\x07\x00", r"TAKE_OVER needs a session token"),
        (b"\x12\x04\x02", r"unknown touch source 2"),
    ],
)
def test_out_of_range_output_fields_are_rejected(wire: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        decode_output(wire)


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        (b"\x23" + bytes(4) + bytes([59]) + bytes(58), r"length 59 exceeds the chunk size 58"),
        (b"\x24\x04", r"unknown upload action 4"),
        (b"\x25\x03\x05" + bytes(15) + b"caf\xe9" + bytes(42), r"not ASCII"),
        (b"\x25\x03\x05" + bytes(15) + b"a\x07b" + bytes(43), r"printable ASCII"),
        (b"\x26" + bytes(4) + (257).to_bytes(2, "little") + bytes(57), r"clipped_textures = 257"),
        (b"\x26" + bytes(2) + (513).to_bytes(2, "little") + bytes(59), r"item_count = 513"),
        (b"\x26" + bytes(18) + (40_001).to_bytes(2, "little") + bytes(43), r"target_x1e4 = 40001"),
    ],
)
def test_malformed_feature_fields_are_rejected(wire: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        decode_feature(wire)


def test_unknown_enumeration_values_from_the_device_decode() -> None:
    # PV4: a newer minor may add states, results and reasons; a host reads them as unknown
    wire = b"\x25\x09\x0c" + bytes(61)
    report = decode_feature(wire)
    assert isinstance(report, UploadStatus)
    assert (report.state, report.result) == (9, 12)
    clip = ClipReport(1, 1, 1, 1 << 15, 120, 500, 0, 3, 7, 200, 5000, 6000, "new")
    assert decode_feature(clip.encode()) == clip


def test_constructors_check_ranges_and_types() -> None:
    with pytest.raises(ProtocolError, match="must be an integer"):
        Limits(1.5, 0, 0)  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="must be an integer"):
        Limits(True, 0, 0)
    with pytest.raises(ProtocolError, match="outside"):
        Limits(-1, 0, 0)
    with pytest.raises(ProtocolError, match="equal length"):
        Stream(0, (1,), (10_000, 10_000))
    with pytest.raises(ProtocolError, match="exceed the chunk size"):
        UploadData(0, bytes(59))
    with pytest.raises(ProtocolError, match="46"):
        UploadStatus(3, 5, 0, 0, 0, 0, 0, "x" * 47)
    with pytest.raises(ProtocolError, match="tuple of 4"):
        State(0, 0, 0, 0, 0, (0, 0, 0), 0, 0, 0, 0, 0, 10_000, -1, 0, 0, 0, 0, 0, 0)  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="outside i16"):
        State(0, 0, 0, 0, 0, (0, 0, 0, 40_000), 0, 0, 0, 0, 0, 10_000, -1, 0, 0, 0, 0, 0, 0)
    with pytest.raises(ProtocolError, match=">= 0"):
        Limits.from_si(-1e-9, 0, 0)
    assert Limits.from_si(1.0, 1e6, 1.0) == Limits(0xFFFF, 0xFFFF, 0xFFFF)  # saturates
    limits = Limits.from_si(2e-6, 1500.0, 100e-6)
    assert (limits.max_amplitude_nm, limits.max_voltage_dv, limits.max_current_10na) == (
        2000, 15_000, 10_000
    )


# ---- fuzzing: random bytes never raise anything but ProtocolError -----------------------------


def _fuzz_one(kind: ReportKind, data: bytes) -> None:
    try:
        report = decode(kind, data)
    except ProtocolError:
        return
    assert decode(kind, report.encode()) == report
    # reports without ignored bytes re-encode to exactly the bytes received (padding aside);
    # one of an older minor version (STATE of 52 or 55 bytes, COUNTERS of 31: rule PV4)
    # re-encodes to the bytes received followed by the appended fields
    if not isinstance(report, (Stream, UploadData, UploadStatus, ClipReport)):
        size = type(report).size()
        if len(data) < size:
            assert report.encode()[: len(data)] == data
        else:
            assert report.encode() == data[:size]


@settings(max_examples=600)
@given(
    kind=st.sampled_from(list(ReportKind)),
    rid=st.sampled_from([int(r) for r in ReportId] + [0, 0x02, 0x13, 0x28, 0xFF]),
    body=st.binary(max_size=70),
)
def test_fuzz_every_parser_with_random_bytes(kind: ReportKind, rid: int, body: bytes) -> None:
    _fuzz_one(kind, bytes([rid]) + body)


@pytest.mark.parametrize("cls", REPORT_CLASSES, ids=lambda c: c.name())
@settings(max_examples=200)
@given(body=st.binary(min_size=0, max_size=66))
def test_fuzz_each_report_class(cls: type[Report], body: bytes) -> None:
    try:
        report = cls.decode(bytes([cls.REPORT_ID]) + body)
    except ProtocolError as exc:
        assert exc.report == cls.name()
        return
    older = {getattr(cls, name, None) for name in ("LEGACY_SIZE", "SESSION_SIZE")}
    assert len(body) >= cls.size() - 1 or len(body) + 1 in older  # PV4: an older minor's size
    assert cls.decode(report.encode()) == report


# ---- host helpers -----------------------------------------------------------------------------


def test_crc32_check_value_and_upload_reports() -> None:
    assert crc32(b"123456789") == 0xCBF43926
    card = bytes(range(256)) * 3  # 768 bytes: 13 full chunks and one of 14
    reports = upload_reports(card)
    begin = decode_feature(reports[0])
    assert begin == UploadBegin(768, zlib.crc32(card))
    chunks = [decode_feature(r) for r in reports[1:-1]]
    assert len(chunks) == 14
    assert all(isinstance(c, UploadData) for c in chunks)
    assert [c.offset for c in chunks] == list(range(0, 768, UPLOAD_CHUNK_BYTES))  # type: ignore[union-attr]
    assert b"".join(c.data for c in chunks) == card  # type: ignore[union-attr]
    assert len(chunks[-1].data) == 768 - 13 * 58  # type: ignore[union-attr]
    assert decode_feature(reports[-1]) == UploadEnd(1)
    with pytest.raises(ProtocolError, match="empty"):
        upload_reports(b"")


def test_stream_reports_split_round_and_wrap() -> None:
    uv = [i / 30 for i in range(31)]
    ev = [1 + 3 * i / 30 for i in range(31)]
    reports = [decode_output(r) for r in stream_reports(uv, ev, first_seq=0xFFFF)]
    assert [len(r.uv_x1e4) for r in reports] == [15, 15, 1]  # type: ignore[attr-defined]
    assert [r.stream_seq for r in reports] == [0xFFFF, 0, 1]  # type: ignore[attr-defined]
    assert reports[0].uv_x1e4[3] == 1000 and reports[2].ev_x1e4 == (40_000,)  # type: ignore[attr-defined]
    assert reports[1].uv[0] == pytest.approx(0.5, abs=1e-4)  # type: ignore[attr-defined]
    with pytest.raises(ProtocolError, match="uv has 2 frames but ev has 1"):
        stream_reports([0.5, 0.5], [1.0])
    with pytest.raises(ProtocolError, match="uv"):
        stream_reports([1.2], [1.0])
    with pytest.raises(ProtocolError, match="ev"):
        stream_reports([1.0], [0.99])


# ---- descriptor -------------------------------------------------------------------------------


def test_descriptor_declares_every_report_at_its_size() -> None:
    sizes = report_sizes(REPORT_DESCRIPTOR)
    assert sizes == {(c.KIND, c.REPORT_ID): c.size() for c in REPORT_CLASSES}
    assert REPORT_DESCRIPTOR[:3] == bytes.fromhex("0600FF")  # vendor usage page 0xFF00
    assert REPORT_DESCRIPTOR[-1] == 0xC0  # End Collection
    assert len(REPORT_DESCRIPTOR) == 111  # PD1
    items = parse_items(REPORT_DESCRIPTOR)
    assert sum(len(i.raw) for i in items) == len(REPORT_DESCRIPTOR)
    assert [i.name for i in items].count("Report ID") == 12
    assert short_item(0x2, 1, 255, signed=True) == bytes.fromhex("26FF00")
    assert short_item(0x1, 1, -1, signed=True) == bytes.fromhex("15FF")
    assert short_item(0x0, 1, 0x12345) == bytes.fromhex("0745230100")
    with pytest.raises(ValueError, match="long item"):
        parse_items(b"\xfe\x00\x00")
    with pytest.raises(ValueError, match="truncated"):
        parse_items(b"\x26\xff")


def test_spec_descriptor_blocks_equal_the_generated_ones() -> None:
    text = SPEC.read_text(encoding="utf-8")
    blocks = dict(generated_blocks(text))
    assert set(blocks) == {"", "--hex"}
    assert blocks[""] == dump(REPORT_DESCRIPTOR)
    assert blocks["--hex"] == hex_dump(REPORT_DESCRIPTOR)
    assert update_spec(text) == text
    # the hex block is the descriptor itself
    hex_bytes = "".join(line[6:] for line in blocks["--hex"].splitlines()).split()
    assert bytes.fromhex("".join(hex_bytes)) == REPORT_DESCRIPTOR
    # and the readable dump names every report with its size
    for cls in REPORT_CLASSES:
        assert f"-> {cls.name()}: {cls.size() - 1} + 1 = {cls.size()} bytes" in blocks[""]


def test_update_spec_rewrites_a_stale_block() -> None:
    stale = (
        "x\n<!-- BEGIN GENERATED: python -m hcard.device.protocol --hex -->\n```text\nold\n"
        "```\n<!-- END GENERATED -->\n"
    )
    assert update_spec(stale) == stale.replace("old\n", hex_dump(REPORT_DESCRIPTOR))
    with pytest.raises(ValueError, match="no generated output"):
        output_for("--bogus")


def test_main_prints_the_dump(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    assert capsys.readouterr().out == dump(REPORT_DESCRIPTOR)
    assert main(["--hex"]) == 0
    assert capsys.readouterr().out == hex_dump(REPORT_DESCRIPTOR)
    assert main(["--table"]) == 0
    assert "| 0x27 | COUNTERS | feature | 35 | GET |" in capsys.readouterr().out


def test_si_views_of_feature_reports() -> None:
    info = DeviceInfo(1, 0, 1, 0x7D, 60_750, 10_000, 50, 1000, 0, 2500, 0, 25_000, 2 << 20,
                      100, 2000, 15, 8100, 5400)
    assert decode_feature(info.encode()) == info
    limits = Limits(2500, 0, 25_000)
    assert limits.max_amplitude_m == pytest.approx(2.5e-6)
    assert limits.max_current_a == pytest.approx(250e-6)
    assert limits.max_voltage_v == 0.0
    counters = Counters(1, 2, 3, 4, 5, 6, 7, 0x1FF)
    assert decode_feature(counters.encode()).latched_faults == 0x1FF  # type: ignore[attr-defined]


def test_counters_of_an_older_device_read_with_no_late_reports() -> None:
    """Protocol 1.4 appends late_reports (u32, offset 31) to COUNTERS (rule PV4, PI4): a 1.4
    report is 35 bytes; the 31 bytes of a 1.0-1.3 device decode with late_reports 0; a report
    of any other length under 35 bytes is malformed."""
    counters = Counters(1, 2, 3, 4, 5, 6, 7, 0x400, 123_456)
    wire = counters.encode()
    assert len(wire) == Counters.size() == 35
    assert wire[31:] == (123_456).to_bytes(4, "little")
    assert Counters.decode(wire) == counters
    older = Counters.decode(wire[:Counters.LEGACY_SIZE])
    assert older == Counters(1, 2, 3, 4, 5, 6, 7, 0x400, 0)
    with pytest.raises(ProtocolError, match="shorter"):
        Counters.decode(wire[:33])
