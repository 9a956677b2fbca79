"""The feature reports (spec/device-protocol.md sections 8 and 9)."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, ClassVar

from hcard.device.protocol.base import (
    U8,
    U16,
    U32,
    ProtocolError,
    Report,
    ascii_field,
    text_from_wire,
)
from hcard.device.protocol.constants import (
    AMPLITUDE_UNIT_M,
    CLIP_NAME_BYTES,
    CURRENT_UNIT_A,
    EV_MAX,
    FRICTION_SCALE,
    UPLOAD_CHUNK_BYTES,
    UPLOAD_DETAIL_BYTES,
    VOLTAGE_UNIT_V,
    ReportId,
    ReportKind,
    UploadAction,
)


@dataclass(frozen=True)
class DeviceInfo(Report):
    """What the device is and can do (GET only).

    Attributes:
        protocol_major, protocol_minor: protocol version the device speaks.
        device_kind: :class:`DeviceKind` (unknown values: judge by ``capabilities``).
        capabilities: :class:`Capability` bits.
        plate_frequency_hz: plate resonance, Hz (0: no plate).
        frame_rate_hz: actuator frame rate, Hz.
        touch_rate_hz: internal touch sensor rate, Hz (0: none).
        input_rate_hz: STATE reports per second.
        ev_carrier_hz: EV carrier frequency, Hz (0: no EV).
        max_amplitude_nm, max_voltage_dv, max_current_10na: hardware limits (peak-to-peak nm,
            0.1 V, 0.01 uA); LIMITS can only lower them.
        max_card_bytes: largest card UPLOAD_BEGIN accepts, bytes.
        watchdog_ms: host silence after which outputs ramp to zero, ms.
        stream_capacity_frames: size of the stream queue, frames.
        stream_frames_per_report: frames one STREAM report carries (15).
        surface_width_10um, surface_height_10um: active surface, 0.01 mm.
    """

    REPORT_ID: ClassVar[int] = ReportId.DEVICE_INFO
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BBBBHIHHHHHHHIHHBHH")
    GET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "protocol_major": U8,
        "protocol_minor": U8,
        "device_kind": U8,
        "capabilities": U16,
        "plate_frequency_hz": U32,
        "frame_rate_hz": U16,
        "touch_rate_hz": U16,
        "input_rate_hz": U16,
        "ev_carrier_hz": U16,
        "max_amplitude_nm": U16,
        "max_voltage_dv": U16,
        "max_current_10na": U16,
        "max_card_bytes": U32,
        "watchdog_ms": U16,
        "stream_capacity_frames": U16,
        "stream_frames_per_report": U8,
        "surface_width_10um": U16,
        "surface_height_10um": U16,
    }

    protocol_major: int
    protocol_minor: int
    device_kind: int
    capabilities: int
    plate_frequency_hz: int
    frame_rate_hz: int
    touch_rate_hz: int
    input_rate_hz: int
    ev_carrier_hz: int
    max_amplitude_nm: int
    max_voltage_dv: int
    max_current_10na: int
    max_card_bytes: int
    watchdog_ms: int
    stream_capacity_frames: int
    stream_frames_per_report: int
    surface_width_10um: int
    surface_height_10um: int


@dataclass(frozen=True)
class Limits(Report):
    """Safety limits in force (GET), or lower ones requested by the host (SET).

    A SET value above the hardware limit is clamped to it (never raises the limit past the
    hardware); 0 disables the actuator. Attributes in nm (peak-to-peak), 0.1 V and 0.01 uA.
    """

    REPORT_ID: ClassVar[int] = ReportId.LIMITS
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BHHH")
    GET: ClassVar[bool] = True
    SET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "max_amplitude_nm": U16,
        "max_voltage_dv": U16,
        "max_current_10na": U16,
    }

    max_amplitude_nm: int
    max_voltage_dv: int
    max_current_10na: int

    @classmethod
    def from_si(cls, max_amplitude_m: float, max_voltage_v: float, max_current_a: float) -> Limits:
        """From SI limits (m peak-to-peak, V, A); saturates at the field maximum."""
        def counts(value: float, unit: float, what: str) -> int:
            if not math.isfinite(value) or value < 0:
                raise ProtocolError(f"{what} must be finite and >= 0, got {value}")
            return min(round(value / unit), U16[1])

        return cls(
            counts(max_amplitude_m, AMPLITUDE_UNIT_M, "max_amplitude_m"),
            counts(max_voltage_v, VOLTAGE_UNIT_V, "max_voltage_v"),
            counts(max_current_a, CURRENT_UNIT_A, "max_current_a"),
        )

    @property
    def max_amplitude_m(self) -> float:
        """Amplitude limit, m peak-to-peak."""
        return self.max_amplitude_nm * AMPLITUDE_UNIT_M

    @property
    def max_voltage_v(self) -> float:
        """Voltage limit, V."""
        return self.max_voltage_dv * VOLTAGE_UNIT_V

    @property
    def max_current_a(self) -> float:
        """Current limit, A."""
        return self.max_current_10na * CURRENT_UNIT_A


@dataclass(frozen=True)
class UploadBegin(Report):
    """Start a card upload (SET); GET reads back the upload in progress (zeros when none).

    Attributes:
        total_length: card bytes to come, 1..max_card_bytes (0 only when read back idle).
        crc32: CRC-32 (ISO-HDLC, as zlib.crc32) of those bytes.
    """

    REPORT_ID: ClassVar[int] = ReportId.UPLOAD_BEGIN
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BII")
    GET: ClassVar[bool] = True
    SET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {"total_length": U32, "crc32": U32}

    total_length: int
    crc32: int


@dataclass(frozen=True)
class UploadData(Report):
    """One chunk of card bytes (SET); GET reads back the next expected offset, no data.

    Attributes:
        offset: position of the chunk in the card, bytes; MUST equal the bytes received so far.
        data: 1..58 card bytes (0 only when read back); padded with zeros on the wire.
    """

    REPORT_ID: ClassVar[int] = ReportId.UPLOAD_DATA
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct(f"<BIB{UPLOAD_CHUNK_BYTES}s")
    GET: ClassVar[bool] = True
    SET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {"offset": U32}

    offset: int
    data: bytes

    def _check(self) -> None:
        if not isinstance(self.data, bytes):
            raise ProtocolError("data must be bytes", report=self.name())
        if len(self.data) > UPLOAD_CHUNK_BYTES:
            raise ProtocolError(
                f"{len(self.data)} data bytes exceed the chunk size {UPLOAD_CHUNK_BYTES}",
                report=self.name(),
            )

    def _values(self) -> tuple[Any, ...]:
        return (self.offset, len(self.data), self.data)

    @classmethod
    def _from_values(cls, values: tuple[Any, ...]) -> UploadData:
        offset, length, raw = values
        if length > UPLOAD_CHUNK_BYTES:
            raise ProtocolError(
                f"length {length} exceeds the chunk size {UPLOAD_CHUNK_BYTES}", report=cls.name()
            )
        return cls(offset, raw[:length])


@dataclass(frozen=True)
class UploadEnd(Report):
    """Finish an upload: COMMIT or ABORT (SET); GET reads back NONE.

    Attributes:
        action: :class:`UploadAction`.
    """

    REPORT_ID: ClassVar[int] = ReportId.UPLOAD_END
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BB")
    GET: ClassVar[bool] = True
    SET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {"action": U8}

    action: int

    def _check(self) -> None:
        if self.action not in UploadAction._value2member_map_:
            raise ProtocolError(f"unknown upload action {self.action}", report=self.name())


@dataclass(frozen=True)
class UploadStatus(Report):
    """State of the card upload and of the active card (GET only).

    Attributes:
        state: :class:`UploadState`.
        result: :class:`UploadResult` of the last upload (OK unless state is FAILED).
        detail_flags: bit 0: ``detail`` was truncated to fit.
        received: card bytes received in the current or last upload.
        total_length: length announced by the current or last BEGIN, bytes.
        active_crc32: CRC-32 of the active card's bytes (0: no card).
        card_generation: successful COMMITs since power-up, wrapping (0: no card).
        detail: INVALID_CARD: field path of the first problem (or the start of the reason
            when it has no path); empty otherwise. Printable ASCII, at most 46 bytes.
    """

    REPORT_ID: ClassVar[int] = ReportId.UPLOAD_STATUS
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct(f"<BBBBIIIH{UPLOAD_DETAIL_BYTES}s")
    GET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "state": U8,
        "result": U8,
        "detail_flags": U8,
        "received": U32,
        "total_length": U32,
        "active_crc32": U32,
        "card_generation": U16,
    }

    state: int
    result: int
    detail_flags: int
    received: int
    total_length: int
    active_crc32: int
    card_generation: int
    detail: str = ""

    DETAIL_TRUNCATED: ClassVar[int] = 0x01

    def _check(self) -> None:
        # state and result are not checked against the enumerations: a newer minor version may
        # add values, which a host reads as "unknown" (rule PV4).
        if not isinstance(self.detail, str):
            raise ProtocolError("detail must be a string", report=self.name())
        ascii_field(self.detail, UPLOAD_DETAIL_BYTES, "detail")

    def _values(self) -> tuple[Any, ...]:
        return (
            self.state, self.result, self.detail_flags, self.received, self.total_length,
            self.active_crc32, self.card_generation, self.detail.encode("ascii"),
        )  # fmt: skip

    @classmethod
    def _from_values(cls, values: tuple[Any, ...]) -> UploadStatus:
        # one starred tuple: mypy reads cls(*values[:7], text) as too many arguments
        return cls(*(*values[:7], text_from_wire(values[7])))


@dataclass(frozen=True)
class ClipReport(Report):
    """What the active card asks for beyond the device (GET), one clipped item at a time; a SET
    selects the item (only ``item_index`` of a SET is used).

    Attributes:
        card_generation: the card this report describes (0: no card).
        item_count: clipped items (one per texture and channel); 0: the card renders as written.
        clipped_textures: palette entries with at least one clipped item.
        flags: :class:`ClipFlags`, the OR over all items.
        reference_speed_mm_s: finger speed the targets were checked at, mm/s.
        reference_force_mn: normal force they were checked at, mN.
        item_index: the item described below, 0..item_count-1; 0xFFFF when there is none.
        texture: its palette index, -1 for none.
        channel: 1 UV, 2 EV, 0 none.
        reason: :class:`ClipReason`.
        target_x1e4: the extreme relative friction the texture asks for, x 10 000.
        achievable_x1e4: the closest the device renders, x 10 000.
        texture_name: the texture's name, printable ASCII (others as ``?``), cut to 41 bytes.
    """

    REPORT_ID: ClassVar[int] = ReportId.CLIP_REPORT
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct(f"<BHHHHHHHhBBHH{CLIP_NAME_BYTES}s")
    GET: ClassVar[bool] = True
    SET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "card_generation": U16,
        "item_count": (0, 512),
        "clipped_textures": (0, 256),
        "flags": U16,
        "reference_speed_mm_s": U16,
        "reference_force_mn": U16,
        "item_index": U16,
        "texture": (-1, 255),
        "channel": U8,
        "reason": U8,
        "target_x1e4": (0, EV_MAX),
        "achievable_x1e4": (0, EV_MAX),
    }
    NO_ITEM: ClassVar[int] = 0xFFFF

    card_generation: int
    item_count: int
    clipped_textures: int
    flags: int
    reference_speed_mm_s: int
    reference_force_mn: int
    item_index: int
    texture: int
    channel: int
    reason: int
    target_x1e4: int
    achievable_x1e4: int
    texture_name: str = ""

    @classmethod
    def select(cls, item_index: int) -> ClipReport:
        """The SET that selects which item the next GET describes."""
        return cls(0, 0, 0, 0, 0, 0, item_index, -1, 0, 0, 0, 0)

    def _check(self) -> None:
        if not isinstance(self.texture_name, str):
            raise ProtocolError("texture_name must be a string", report=self.name())
        ascii_field(self.texture_name, CLIP_NAME_BYTES, "texture_name")

    def _values(self) -> tuple[Any, ...]:
        return (
            self.card_generation, self.item_count, self.clipped_textures, self.flags,
            self.reference_speed_mm_s, self.reference_force_mn, self.item_index, self.texture,
            self.channel, self.reason, self.target_x1e4, self.achievable_x1e4,
            self.texture_name.encode("ascii"),
        )  # fmt: skip

    @classmethod
    def _from_values(cls, values: tuple[Any, ...]) -> ClipReport:
        # one starred tuple: mypy reads cls(*values[:12], text) as too many arguments
        return cls(*(*values[:12], text_from_wire(values[12])))

    @property
    def target(self) -> float:
        """Relative friction the item asks for."""
        return self.target_x1e4 / FRICTION_SCALE

    @property
    def achievable(self) -> float:
        """Relative friction the device renders instead."""
        return self.achievable_x1e4 / FRICTION_SCALE


@dataclass(frozen=True)
class Counters(Report):
    """Full-width counters since power-up or CLEAR_COUNTERS (GET only).

    Attributes:
        input_reports: STATE reports produced.
        input_dropped: STATE reports dropped because the queue was full.
        output_reports: output reports accepted.
        rejected_requests: malformed or refused output and feature requests.
        stream_frames_dropped: streamed frames dropped (stream queue full).
        stream_gaps: STREAM reports whose stream_seq was not the previous one plus 1.
        watchdog_trips: times the watchdog expired.
        latched_faults: OR of every :class:`FaultBits` reported since the last clear.
        late_reports: STATE reports produced with fault REALTIME_LAG: the device fell behind
            its real-time clock (protocol 1.4, rule PI4).

    A protocol 1.0-1.3 device sends the first :data:`LEGACY_SIZE` bytes only; :meth:`decode`
    reads the missing ``late_reports`` as 0 (rule PV4: a field appended by a minor version).
    """

    REPORT_ID: ClassVar[int] = ReportId.COUNTERS
    KIND: ClassVar[ReportKind] = ReportKind.FEATURE
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BIIIIIIIHI")
    LEGACY_SIZE: ClassVar[int] = 31
    """Bytes of COUNTERS in protocol 1.0-1.3 (before ``late_reports`` of 1.4)."""
    GET: ClassVar[bool] = True
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "input_reports": U32,
        "input_dropped": U32,
        "output_reports": U32,
        "rejected_requests": U32,
        "stream_frames_dropped": U32,
        "stream_gaps": U32,
        "watchdog_trips": U32,
        "latched_faults": U16,
        "late_reports": U32,
    }

    input_reports: int
    input_dropped: int
    output_reports: int
    rejected_requests: int
    stream_frames_dropped: int
    stream_gaps: int
    watchdog_trips: int
    latched_faults: int
    late_reports: int = 0

    @classmethod
    def decode(cls, data: bytes | bytearray | memoryview) -> Counters:
        """Parse COUNTERS; one of a protocol 1.0-1.3 device (:data:`LEGACY_SIZE` bytes) reads
        with ``late_reports`` 0. Otherwise as :meth:`Report.decode`."""
        if isinstance(data, (bytes, bytearray, memoryview)) and len(data) == cls.LEGACY_SIZE:
            data = bytes(data) + bytes(cls.STRUCT.size - cls.LEGACY_SIZE)
        report = super().decode(data)
        assert isinstance(report, Counters)
        return report
