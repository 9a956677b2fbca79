"""The output reports FINGER, STREAM and CONTROL (spec/device-protocol.md section 7)."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, ClassVar

from hcard.device.protocol.base import (
    MAX_FINGER_FORCE_MN,
    POSITION_RANGE,
    U8,
    U16,
    U32,
    ProtocolError,
    Report,
    to_counts,
)
from hcard.device.protocol.constants import (
    EV_MAX,
    EV_MIN,
    FORCE_UNIT_N,
    FRICTION_SCALE,
    POSITION_UNIT_MM,
    STREAM_FRAMES_PER_REPORT,
    TIME_UNIT_S,
    UV_MAX,
    UV_MIN,
    Command,
    ReportId,
    ReportKind,
    TouchSource,
)


@dataclass(frozen=True)
class Finger(Report):
    """Finger state from the host, for devices whose touch sensor is on the host side.

    Attributes:
        host_time_us: host time of the touch sample, us, wrapping u32 (echoed in STATE).
        x_10um, y_10um: finger position, 0.01 mm, surface coordinates, within +-20 m.
        fn_mn: normal force, mN, 0..50 000.
        flags: bit 0 contact; bits 1-7 reserved (send 0, ignored).
    """

    REPORT_ID: ClassVar[int] = ReportId.FINGER
    KIND: ClassVar[ReportKind] = ReportKind.OUTPUT
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BIiiHB")
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {
        "host_time_us": U32,
        "x_10um": POSITION_RANGE,
        "y_10um": POSITION_RANGE,
        "fn_mn": (0, MAX_FINGER_FORCE_MN),
        "flags": U8,
    }

    host_time_us: int
    x_10um: int
    y_10um: int
    fn_mn: int
    flags: int

    @classmethod
    def from_si(cls, t_s: float, x_mm: float, y_mm: float, fn_n: float, contact: bool) -> Finger:
        """From host time (s, taken modulo 2**32 us), position (mm) and normal force (N)."""
        if not math.isfinite(t_s):
            raise ProtocolError(f"host time must be finite, got {t_s}", report=cls.name())
        return cls(
            host_time_us=round(t_s / TIME_UNIT_S) % (1 << 32),
            x_10um=to_counts(x_mm, POSITION_UNIT_MM, *POSITION_RANGE, "x_mm"),
            y_10um=to_counts(y_mm, POSITION_UNIT_MM, *POSITION_RANGE, "y_mm"),
            fn_mn=to_counts(fn_n, FORCE_UNIT_N, 0, MAX_FINGER_FORCE_MN, "fn_n"),
            flags=1 if contact else 0,
        )

    @property
    def contact(self) -> bool:
        """The finger touches the surface."""
        return bool(self.flags & 1)

    @property
    def x_mm(self) -> float:
        """Finger x, mm."""
        return self.x_10um * POSITION_UNIT_MM

    @property
    def y_mm(self) -> float:
        """Finger y, mm."""
        return self.y_10um * POSITION_UNIT_MM

    @property
    def fn_n(self) -> float:
        """Normal force, N."""
        return self.fn_mn * FORCE_UNIT_N


@dataclass(frozen=True)
class Stream(Report):
    """Direct frame streaming: 1 to 15 frames of (UV, EV) target relative friction.

    Attributes:
        stream_seq: host counter, wrapping u16; a gap tells the device a report was lost.
        uv_x1e4: UV targets, relative friction x 10 000, each in [0, 10 000] (0..1).
        ev_x1e4: EV targets, relative friction x 10 000, each in [10 000, 40 000] (1..4);
            as many as ``uv_x1e4``. On the wire the unused frame slots are 0 and ignored.
    """

    REPORT_ID: ClassVar[int] = ReportId.STREAM
    KIND: ClassVar[ReportKind] = ReportKind.OUTPUT
    STRUCT: ClassVar[struct.Struct] = struct.Struct(f"<BHB{2 * STREAM_FRAMES_PER_REPORT}H")
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {"stream_seq": U16}

    stream_seq: int
    uv_x1e4: tuple[int, ...]
    ev_x1e4: tuple[int, ...]

    def _check(self) -> None:
        uv, ev = self.uv_x1e4, self.ev_x1e4
        if not isinstance(uv, tuple) or not isinstance(ev, tuple) or len(uv) != len(ev):
            raise ProtocolError("uv and ev must be tuples of equal length", report=self.name())
        if not 1 <= len(uv) <= STREAM_FRAMES_PER_REPORT:
            raise ProtocolError(
                f"frame count {len(uv)} is outside [1, {STREAM_FRAMES_PER_REPORT}]",
                report=self.name(),
            )
        for i, (u, e) in enumerate(zip(uv, ev, strict=True)):
            if isinstance(u, bool) or not isinstance(u, int) or not UV_MIN <= u <= UV_MAX:
                raise ProtocolError(
                    f"frame {i}: uv {u!r} is outside [{UV_MIN}, {UV_MAX}]", report=self.name()
                )
            if isinstance(e, bool) or not isinstance(e, int) or not EV_MIN <= e <= EV_MAX:
                raise ProtocolError(
                    f"frame {i}: ev {e!r} is outside [{EV_MIN}, {EV_MAX}]", report=self.name()
                )

    def _values(self) -> tuple[Any, ...]:
        pad = (0, 0) * (STREAM_FRAMES_PER_REPORT - len(self.uv_x1e4))
        pairs = [v for pair in zip(self.uv_x1e4, self.ev_x1e4, strict=True) for v in pair]
        return (self.stream_seq, len(self.uv_x1e4), *pairs, *pad)

    @classmethod
    def _from_values(cls, values: tuple[Any, ...]) -> Stream:
        seq, count, slots = values[0], values[1], values[2:]
        if not 1 <= count <= STREAM_FRAMES_PER_REPORT:
            raise ProtocolError(
                f"frame count {count} is outside [1, {STREAM_FRAMES_PER_REPORT}]",
                report=cls.name(),
            )
        return cls(seq, tuple(slots[0 : 2 * count : 2]), tuple(slots[1 : 2 * count : 2]))

    @classmethod
    def from_friction(cls, stream_seq: int, uv: Any, ev: Any) -> Stream:
        """From relative friction sequences (UV in [0, 1], EV in [1, 4]), rounded to 1e-4."""
        step = 1 / FRICTION_SCALE
        uv_counts = tuple(to_counts(float(u), step, UV_MIN, UV_MAX, "uv") for u in uv)
        ev_counts = tuple(to_counts(float(e), step, EV_MIN, EV_MAX, "ev") for e in ev)
        return cls(stream_seq % (1 << 16), uv_counts, ev_counts)

    @property
    def uv(self) -> tuple[float, ...]:
        """UV targets, relative friction."""
        return tuple(u / FRICTION_SCALE for u in self.uv_x1e4)

    @property
    def ev(self) -> tuple[float, ...]:
        """EV targets, relative friction."""
        return tuple(e / FRICTION_SCALE for e in self.ev_x1e4)


@dataclass(frozen=True)
class Control(Report):
    """A command to the device.

    Attributes:
        command: a :class:`Command` value.
        argument: SET_TOUCH_SOURCE: a :class:`TouchSource`; START and STOP: the host's
            session token, 0 for none (protocol 1.2, rules PN1, PN4); TAKE_OVER: the token,
            1..255 (PN6); every other command: reserved, 0.
    """

    REPORT_ID: ClassVar[int] = ReportId.CONTROL
    KIND: ClassVar[ReportKind] = ReportKind.OUTPUT
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BBB")
    RANGES: ClassVar[dict[str, tuple[int, int]]] = {"command": U8, "argument": U8}

    command: int
    argument: int = 0

    def _check(self) -> None:
        if self.command not in Command._value2member_map_:
            raise ProtocolError(f"unknown command {self.command}", report=self.name())
        if (
            self.command == Command.SET_TOUCH_SOURCE
            and self.argument not in TouchSource._value2member_map_
        ):
            raise ProtocolError(f"unknown touch source {self.argument}", report=self.name())
        if self.command == Command.TAKE_OVER and self.argument == 0:
            raise ProtocolError("TAKE_OVER needs a session token 1..255", report=self.name())
