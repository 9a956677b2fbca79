"""The input report STATE (spec/device-protocol.md section 6)."""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import Any, ClassVar

from hcard.device.protocol.base import (
    I16,
    POSITION_RANGE,
    U8,
    U16,
    U32,
    ProtocolError,
    Report,
    narrow_ranges,
)
from hcard.device.protocol.constants import (
    AMPLITUDE_UNIT_M,
    CURRENT_UNIT_A,
    ECHO_AGE_UNKNOWN,
    EV_MAX,
    EV_MIN,
    FORCE_UNIT_N,
    FRICTION_SCALE,
    POSITION_UNIT_MM,
    TIME_UNIT_S,
    UV_MAX,
    UV_MIN,
    VOLTAGE_UNIT_V,
    ReportId,
    ReportKind,
    StateFlags,
)


@dataclass(frozen=True)
class State(Report):
    """Device state, sent on the interrupt IN endpoint at the input rate (1 kHz).

    Values are those of the last frame of the report's interval; ``faults`` is the OR over the
    interval's frames plus firmware events since the previous report.

    Attributes:
        timestamp_us: device time of the last frame covered, us, wrapping u32.
        sequence: report counter, wrapping u16; a gap means reports were dropped.
        flags: :class:`StateFlags`.
        x_10um, y_10um: finger position (latest touch sample), 0.01 mm, surface coordinates.
        corner_forces_mn: the four corner force sensors, mN, in the order top-left (0, 0),
            top-right (+x), bottom-left (+y), bottom-right.
        lateral_force_mn: lateral (friction) force along the finger's motion, mN.
        amplitude_nm: measured plate vibration amplitude (peak-to-peak), nm.
        voltage_dv: measured EV voltage envelope, 0.1 V.
        current_10na: measured EV current, 0.01 uA.
        target_uv_x1e4, target_ev_x1e4: target relative friction being rendered, x 10 000.
        texture: active palette index, -1 for none.
        faults: :class:`FaultBits`.
        dropped_reports: input reports dropped (queue full), wrapping u16.
        rejected_requests: malformed or refused host requests, wrapping u16.
        stream_queued: frames waiting in the stream queue.
        host_time_echo_us: host_time_us of the last FINGER report applied (0: none yet).
        card_generation: incremented by every successful COMMIT, wrapping u16 (0: no card).
        session_number: the session the report belongs to, +1 per session begun since
            power-up, wrapping u16 (0: none yet; protocol 1.2, rule PN2).
        session_token: the token of the live session's owner, 1..255; 0 when no session is
            live or the live one is anonymous (a 1.0/1.1 host's START; rule PN2).
        echo_age_us: device time from the placement of the echoed finger sample on the device
            clock (rule PO2) to the last frame covered, us; :data:`ECHO_AGE_UNKNOWN` when no
            sample was applied yet (protocol 1.3, rule PI3). The sample's host time plus this
            age is the report's time on the host's clock, exactly, whatever the transport did.

    A protocol 1.0/1.1 device sends the first :data:`LEGACY_SIZE` bytes only, a 1.2 device
    :data:`SESSION_SIZE`; :meth:`decode` reads the missing session fields as 0 and the missing
    echo age as unknown (rule PV4: fields appended by a minor version).
    """

    REPORT_ID: ClassVar[int] = ReportId.STATE
    KIND: ClassVar[ReportKind] = ReportKind.INPUT
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BIHBii4hhHHHHHhHHHHIHHBI")
    LEGACY_SIZE: ClassVar[int] = 52
    """Bytes of STATE in protocol 1.0 and 1.1 (before the session fields of 1.2)."""
    SESSION_SIZE: ClassVar[int] = 55
    """Bytes of STATE in protocol 1.2 (before the echo age of 1.3)."""
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "timestamp_us": U32,
        "sequence": U16,
        "flags": U8,
        "x_10um": POSITION_RANGE,
        "y_10um": POSITION_RANGE,
        "lateral_force_mn": I16,
        "amplitude_nm": U16,
        "voltage_dv": U16,
        "current_10na": U16,
        "target_uv_x1e4": (UV_MIN, UV_MAX),
        "target_ev_x1e4": (EV_MIN, EV_MAX),
        "texture": (-1, 255),
        "faults": U16,
        "dropped_reports": U16,
        "rejected_requests": U16,
        "stream_queued": U16,
        "host_time_echo_us": U32,
        "card_generation": U16,
        "session_number": U16,
        "session_token": U8,
        "echo_age_us": U32,
    }

    timestamp_us: int
    sequence: int
    flags: int
    x_10um: int
    y_10um: int
    corner_forces_mn: tuple[int, int, int, int]
    lateral_force_mn: int
    amplitude_nm: int
    voltage_dv: int
    current_10na: int
    target_uv_x1e4: int
    target_ev_x1e4: int
    texture: int
    faults: int
    dropped_reports: int
    rejected_requests: int
    stream_queued: int
    host_time_echo_us: int
    card_generation: int
    session_number: int = 0
    session_token: int = 0
    echo_age_us: int = ECHO_AGE_UNKNOWN

    def _check(self) -> None:
        forces = self.corner_forces_mn
        if not isinstance(forces, tuple) or len(forces) != 4:
            raise ProtocolError("corner_forces_mn must be a tuple of 4", report=self.name())
        for force in forces:
            if isinstance(force, bool) or not isinstance(force, int):
                raise ProtocolError("corner_forces_mn must be integers", report=self.name())
            if not I16[0] <= force <= I16[1]:
                raise ProtocolError(f"corner force {force} mN is outside i16", report=self.name())

    def _values(self) -> tuple[Any, ...]:
        return (
            self.timestamp_us, self.sequence, self.flags, self.x_10um, self.y_10um,
            *self.corner_forces_mn, self.lateral_force_mn, self.amplitude_nm, self.voltage_dv,
            self.current_10na, self.target_uv_x1e4, self.target_ev_x1e4, self.texture,
            self.faults, self.dropped_reports, self.rejected_requests, self.stream_queued,
            self.host_time_echo_us, self.card_generation, self.session_number,
            self.session_token, self.echo_age_us,
        )  # fmt: skip

    @classmethod
    def decode(cls, data: bytes | bytearray | memoryview) -> State:
        """Parse a STATE report. One of a protocol 1.0/1.1 device (:data:`LEGACY_SIZE` bytes, no
        session fields) reads as session 0, token 0; one of a 1.0-1.2 device (up to
        :data:`SESSION_SIZE` bytes) with the echo age unknown. Otherwise as
        :meth:`Report.decode`."""
        if isinstance(data, (bytes, bytearray, memoryview)) and \
                len(data) in (cls.LEGACY_SIZE, cls.SESSION_SIZE):
            data = bytes(data) + bytes(cls.SESSION_SIZE - len(data))
            data += ECHO_AGE_UNKNOWN.to_bytes(4, "little")
        return super().decode(data)

    @classmethod
    def _from_values(cls, values: tuple[Any, ...]) -> State:
        """The decoded report. Unpacked values already fit their wire types, so only the
        ranges narrower than the type are checked (positions, targets, texture) and the
        constructor's per-field type checks are skipped: a host reads ~1000 of these a second,
        and under software emulation the full checks made it fall behind the stream."""
        for index, name, low, high in _DECODE_CHECKS:
            if not low <= values[index] <= high:
                raise ProtocolError(f"{name} = {values[index]} is outside [{low}, {high}]",
                                    report=cls.name())
        state = object.__new__(cls)
        state.__dict__.update(zip(_FIELD_NAMES, _arguments(values), strict=True))
        return state

    # SI views
    @property
    def echo_age_s(self) -> float | None:
        """Device time from the placement of the echoed finger sample to this report, s; None
        when the device does not say (rule PI3)."""
        if self.echo_age_us == ECHO_AGE_UNKNOWN:
            return None
        return self.echo_age_us * TIME_UNIT_S

    @property
    def session_live(self) -> bool:
        """A session is live (state flag SESSION, protocol 1.2)."""
        return bool(self.flags & StateFlags.SESSION)

    @property
    def contact(self) -> bool:
        """A finger touches the surface."""
        return bool(self.flags & StateFlags.CONTACT)

    @property
    def x_mm(self) -> float:
        """Finger x, mm."""
        return self.x_10um * POSITION_UNIT_MM

    @property
    def y_mm(self) -> float:
        """Finger y, mm."""
        return self.y_10um * POSITION_UNIT_MM

    @property
    def corner_forces_n(self) -> tuple[float, float, float, float]:
        """Corner forces, N."""
        a, b, c, d = (f * FORCE_UNIT_N for f in self.corner_forces_mn)
        return (a, b, c, d)

    @property
    def normal_force_n(self) -> float:
        """Total normal force (sum of the corners), N."""
        return sum(self.corner_forces_mn) * FORCE_UNIT_N

    @property
    def lateral_force_n(self) -> float:
        """Lateral force, N."""
        return self.lateral_force_mn * FORCE_UNIT_N

    @property
    def amplitude_m(self) -> float:
        """Measured plate amplitude, m."""
        return self.amplitude_nm * AMPLITUDE_UNIT_M

    @property
    def voltage_v(self) -> float:
        """Measured EV voltage, V."""
        return self.voltage_dv * VOLTAGE_UNIT_V

    @property
    def current_a(self) -> float:
        """Measured EV current, A."""
        return self.current_10na * CURRENT_UNIT_A

    @property
    def target_uv(self) -> float:
        """UV target, relative friction."""
        return self.target_uv_x1e4 / FRICTION_SCALE

    @property
    def target_ev(self) -> float:
        """EV target, relative friction."""
        return self.target_ev_x1e4 / FRICTION_SCALE

    @property
    def timestamp_s(self) -> float:
        """Device time stamp (wrapping), s."""
        return self.timestamp_us * TIME_UNIT_S


def _arguments(values: tuple[Any, ...]) -> tuple[Any, ...]:
    """The constructor's arguments from STATE's unpacked values (report ID removed): the four
    corner forces (values 5-8) make one tuple field."""
    return (*values[:5], tuple(values[5:9]), *values[9:])


_FIELD_NAMES = tuple(f.name for f in fields(State))
_VALUE_COUNT = len(State.STRUCT.unpack(bytes(State.STRUCT.size))) - 1
_DECODE_CHECKS = narrow_ranges(State, {
    name: index
    for name, index in zip(_FIELD_NAMES, _arguments(tuple(range(_VALUE_COUNT))), strict=True)
    if isinstance(index, int)})
"""(index, name, low, high) of the STATE fields whose range is narrower than their wire type."""
