"""A driver for a device that takes actuator frames, not the hcard protocol: the card is
rendered on the host (:mod:`.host_rendering`) and the device plays the commands.

A vendor subclasses :class:`FrameDriver`, names its URI scheme and implements one method,
:meth:`FrameDriver.open_frame_device`, returning a :class:`~hcard.device.frame_device.FrameDevice`;
its ``device-profile`` plugin publishes the physics the host renders with. Everything that
plays, records or judges a device through :class:`~hcard.device.base.Driver` then works
unchanged: the driver answers the feature reports from the host's own state and makes the STATE
reports (1 kHz, spec/device-protocol.md section 7) from the device's measurements.

What stays on the host and what the device must do (spec/conformance.md section 4):

- the card's upload, its validation, sessions and the report sequence are the host's own
  bookkeeping here, not the device's: the conformance checks of the wire protocol
  (``device.upload-integrity``, ``device.report-loss``, ``device.session-ownership``) do not
  apply (:attr:`Driver.renders_on_host`);
- the limits in force clamp the commands on the host, and the device clamps at its hardware
  limits whatever it is sent;
- the host keeps sending frames for :data:`HOST_SILENCE_S` after the application's last output
  (a FINGER, a keepalive, a command, streamed frames); then frames stop, and the device's own
  watchdog ramps its outputs to zero after :attr:`FrameDeviceInfo.watchdog_s`. DEVICE_INFO's
  ``watchdog_ms`` is the sum.
"""

from __future__ import annotations

import abc
import math
import zlib
from collections import deque
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hcard.card_io import card_from_bytes, to_bytes
from hcard.device.base import (
    COMMIT_TIMEOUT_S,
    DEFAULT_TIMEOUT_S,
    Driver,
    UploadOutcome,
    upload_error,
)
from hcard.device.clip_wire import wire_clip_report
from hcard.device.errors import DeviceError
from hcard.device.frame_device import MEASURED_FAULTS, FrameDevice, Measurement
from hcard.device.host_rendering import (
    STREAM_CAPACITY_FRAMES,
    FingerSample,
    FrameBlock,
    HostRendering,
)
from hcard.device.protocol import (
    AMPLITUDE_UNIT_M,
    CURRENT_UNIT_A,
    ECHO_AGE_UNKNOWN,
    FORCE_UNIT_N,
    FRICTION_SCALE,
    INPUT_RATE_HZ,
    POSITION_UNIT_MM,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    STREAM_FRAMES_PER_REPORT,
    VOLTAGE_UNIT_V,
    Capability,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    FaultBits,
    Finger,
    Limits,
    Report,
    State,
    StateFlags,
    TouchSource,
    UploadResult,
    UploadState,
    UploadStatus,
)
from hcard.device.protocol.constants import DEFAULT_MAX_CARD_BYTES
from hcard.device.protocol.reports import POSITION_RANGE
from hcard.device.protocol.upload import detail_text
from hcard.device.published_profiles import published_profile
from hcard.device.uri import DeviceUri
from hcard.errors import HcardError
from hcard.physics.card_clipping import ClipReport as CardClipping
from hcard.physics.card_clipping import clip_report
from hcard.physics.profile import DeviceProfile
from hcard.v1 import card_pb2 as pb
from hcard.validate import card_errors

HOST_SILENCE_S = 0.05
"""The host sends frames for this long after the application's last output report, s."""
CHUNK_S = 0.010
"""Longest block of frames rendered and sent at once, s."""
REPORT_PERIOD_S = 1.0 / INPUT_RATE_HZ
"""STATE report period, s."""
_U16, _U32 = 0xFFFF, 0xFFFF_FFFF
_TIME_WRAP_S = (1 << 32) * 1e-6


def _counts(value: float, unit: float, low: int, high: int) -> int:
    """``value / unit`` rounded and clamped to [low, high] (0 for NaN)."""
    if not math.isfinite(value):
        return 0
    return max(low, min(high, round(value / unit)))


class FrameDriver(Driver):
    """:class:`Driver` of a :class:`FrameDevice`, rendering on the host (module docstring).

    Subclasses set ``name``, ``description``, ``schemes`` (and ``realtime`` True when the
    device runs on the wall clock) and implement :meth:`open_frame_device`.
    """

    renders_on_host: ClassVar[bool] = True
    realtime: ClassVar[bool] = False

    @abc.abstractmethod
    def open_frame_device(self, uri: DeviceUri) -> FrameDevice:
        """Open the frame device ``uri`` names; raise :class:`DeviceError` when unreachable."""

    @classmethod
    def open(cls, uri: DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> Driver:
        """Open the device ``uri`` names and prepare to render for it."""
        return cls(uri, timeout_s=timeout_s)

    def __init__(self, uri: DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.device = self.open_frame_device(uri)
        spec = self.device.info
        self._hardware = Limits.from_si(spec.max_amplitude_m, spec.max_voltage_v,
                                        spec.max_current_a)
        self._limits = self._hardware
        self._rendering = self.host_rendering(self.device_profile(), spec.frame_rate_hz)
        self._clipping: CardClipping | None = None  # of the active card; None: no card
        self._generation = 0
        self._upload_status = UploadStatus(int(UploadState.IDLE), int(UploadResult.OK),
                                           0, 0, 0, 0, 0)
        self._clip_index = 0
        self._running = False
        self._host_finger = False
        self._last_output_s = -math.inf
        self._next_frame = 0          # the next frame the host renders and sends
        self._sent: deque[FrameBlock] = deque()
        self._finger: FingerSample | None = None
        self._pending: deque[State] = deque()
        self._interval_faults = 0
        self._sequence = 0
        self._counts = {"input": 0, "output": 0, "rejected": 0, "trips": 0, "latched": 0}
        self._watchdog_on = False

    def host_rendering(self, profile: DeviceProfile, frame_rate_hz: float) -> HostRendering:
        """What renders the card on the host, frame by frame, with ``profile`` at the device's
        ``frame_rate_hz`` (Hz): a :class:`HostRendering`. A subclass may return a subclass of it
        that renders otherwise (the conformance suite's deliberately faulty device does)."""
        return HostRendering(profile, frame_rate_hz)

    # ------------------------------------------------------------------ what the host knows

    def device_profile(self) -> DeviceProfile:
        """The physics profile the host renders with: the device's published one (a
        ``device-profile`` plugin that recognises its DEVICE_INFO). A subclass may return its
        own instead; the conformance suite still judges through the published one.

        Raises:
            DeviceError: no installed ``device-profile`` plugin recognises the device.
        """
        profile = published_profile(self.info())
        if profile is None:
            raise DeviceError(
                f"{self.uri}: no installed device-profile plugin publishes the physics of the "
                f"{self.device.info.model} (device kind {self.device.info.device_kind}, plate "
                f"{self.device.info.plate_frequency_hz:g} Hz); a frame driver renders with it")
        return profile

    def info(self) -> DeviceInfo:
        """DEVICE_INFO of the device, as the host renders for it."""
        if self._info is None:
            spec = self.device.info
            capabilities = Capability.HOST_FINGER | Capability.DIRECT_STREAMING
            if spec.has_uv:
                capabilities |= Capability.UV
            if spec.has_ev:
                capabilities |= Capability.EV
            if spec.lateral_force:
                capabilities |= Capability.LATERAL_FORCE
            self._info = DeviceInfo(
                PROTOCOL_MAJOR, PROTOCOL_MINOR, spec.device_kind, int(capabilities),
                _counts(spec.plate_frequency_hz, 1.0, 0, _U32),
                _counts(spec.frame_rate_hz, 1.0, 1, _U16), 0, INPUT_RATE_HZ,
                _counts(spec.ev_carrier_hz, 1.0, 0, _U16), self._hardware.max_amplitude_nm,
                self._hardware.max_voltage_dv, self._hardware.max_current_10na,
                DEFAULT_MAX_CARD_BYTES,
                _counts(HOST_SILENCE_S + spec.watchdog_s, 1e-3, 1, _U16),
                STREAM_CAPACITY_FRAMES, STREAM_FRAMES_PER_REPORT,
                _counts(spec.width_mm, POSITION_UNIT_MM, 1, _U16),
                _counts(spec.height_mm, POSITION_UNIT_MM, 1, _U16))
        return self._info

    def sessions_supported(self) -> bool:
        """False: one host renders for the device; there are no sessions to share it."""
        return False

    def clock(self) -> float:
        """The device's clock, s."""
        return self.device.clock()

    def get_report(self, cls: type[Report]) -> Report:
        """The feature report ``cls`` from the host's state."""
        self._check_open()
        if cls is DeviceInfo:
            return self.info()
        if cls is Limits:
            return self._limits
        if cls is UploadStatus:
            return self._upload_status
        if cls is ClipReport:
            return wire_clip_report(self._clipping, self._generation,
                                    self._clip_index)
        if cls is Counters:
            c = self._counts
            return Counters(c["input"], 0, c["output"], c["rejected"],
                            self._rendering.stream_dropped, self._rendering.stream_gaps,
                            c["trips"], c["latched"])
        raise DeviceError(f"{self.uri}: a frame device has no {cls.name()} report")

    def set_report(self, report: Report) -> None:
        """SET LIMITS (clamped to the hardware's, in force from the next frame) or CLIP_REPORT
        (selects the item)."""
        self._check_open()
        self._output()
        if isinstance(report, Limits):
            hw = self._hardware
            self._limits = Limits(min(report.max_amplitude_nm, hw.max_amplitude_nm),
                                  min(report.max_voltage_dv, hw.max_voltage_dv),
                                  min(report.max_current_10na, hw.max_current_10na))
        elif isinstance(report, ClipReport):
            self._clip_index = report.item_index
        else:
            self._counts["rejected"] += 1
            raise DeviceError(f"{self.uri}: a frame device takes no {report.name()} report")

    # ------------------------------------------------------------------ the card

    def upload_card(self, card: pb.Card | bytes, *,
                    commit_timeout_s: float = COMMIT_TIMEOUT_S) -> UploadOutcome:
        """Validate the card and render it from now on; DeviceError (the previous card stays)
        when it is not a valid card."""
        self._check_open()
        self._output()
        data = card if isinstance(card, bytes) else to_bytes(card)
        try:
            message = (card_from_bytes(data, source=str(self.uri)) if isinstance(card, bytes)
                       else card)
            problems = card_errors(message)
            reason, where = ((str(problems[0]), str(problems[0].path)) if problems
                             else ("", ""))
        except HcardError as exc:
            reason, where = str(exc), str(exc)
        if reason:
            self._upload_status = UploadStatus(
                int(UploadState.FAILED), int(UploadResult.INVALID_CARD), 0, len(data), len(data),
                self._upload_status.active_crc32, self._generation, detail_text(where)[0])
            raise DeviceError(f"{self.uri}: {upload_error(self._upload_status)} ({reason})")
        self._rendering.load(message)
        self._generation = self._generation % _U16 + 1
        self._clipping = clip_report(message, self._rendering.profile)
        self._upload_status = UploadStatus(int(UploadState.COMMITTED), int(UploadResult.OK), 0,
                                    len(data), len(data), zlib.crc32(data), self._generation)
        return UploadOutcome(self._upload_status, self.clip_report(), len(data), 0)

    # ------------------------------------------------------------------ output reports

    def send(self, report: Report) -> None:
        """Act on an output report as a device would: CONTROL and FINGER."""
        self._check_open()
        self._output()
        if isinstance(report, Finger):
            self._take_finger(report)
        elif isinstance(report, Control):
            self._control(report)
        else:
            self._counts["rejected"] += 1
            raise DeviceError(f"{self.uri}: a frame device takes no {report.name()} report")

    def stream_frames(self, uv: Sequence[float] | np.ndarray,
                      ev: Sequence[float] | np.ndarray) -> int:
        """Queue streamed target frames (UV in [0, 1], EV in [1, 4]); the number of STREAM
        reports they would take (15 frames each)."""
        self._check_open()
        u, e = np.asarray(uv, dtype=float), np.asarray(ev, dtype=float)
        if u.shape != e.shape or u.ndim != 1:
            raise DeviceError(f"{self.uri}: cannot stream these frames (uv and ev differ in "
                              "shape or are not 1-D)")
        if not (np.all((u >= 0) & (u <= 1)) and np.all((e >= 1) & (e <= 4))):
            raise DeviceError(f"{self.uri}: cannot stream these frames (UV must lie in [0, 1] "
                              "and EV in [1, 4])")
        self._output()
        dropped = self._rendering.stream_dropped
        self._rendering.stream(u, e)
        if self._rendering.stream_dropped > dropped:
            self._interval_faults |= int(FaultBits.STREAM_OVERRUN)
        return -(-u.shape[0] // STREAM_FRAMES_PER_REPORT)

    def _output(self) -> None:
        """An output from the application: the host keeps feeding the device."""
        self._counts["output"] += 1
        self._last_output_s = self.clock()

    def _take_finger(self, report: Finger) -> None:
        now = self.clock()
        t = report.host_time_us * 1e-6  # unwrapped next to the device clock
        t += round((now - t) / _TIME_WRAP_S) * _TIME_WRAP_S
        self._rendering.finger(t, now, report.x_mm, report.y_mm, report.fn_n, report.contact,
                               report.host_time_us)
        self.device.touch(t, report.x_mm, report.y_mm, report.fn_n, report.contact)

    def _control(self, report: Control) -> None:
        command = report.command
        if command == Command.START:
            self._running = True
            self._rendering.restart()
        elif command == Command.STOP:
            self._running = False
            self._rendering.restart()
        elif command == Command.PLAY_CARD:
            self._rendering.restart()
        elif command == Command.SET_TOUCH_SOURCE:
            self._host_finger = report.argument == TouchSource.HOST
        elif command == Command.CLEAR_COUNTERS:
            self._counts.update(input=0, output=0, rejected=0, trips=0, latched=0)
            self._rendering.stream_dropped = self._rendering.stream_gaps = 0
        elif command != Command.KEEPALIVE:
            self._counts["rejected"] += 1
            raise DeviceError(f"{self.uri}: a frame device takes no CONTROL {command}")

    # ------------------------------------------------------------------ input reports

    def read_inputs(self, timeout_s: float | None = None,
                    max_count: int | None = None) -> list[State]:
        """STATE reports: those waiting, else those of the device time that passes within
        ``timeout_s`` (default :attr:`timeout_s`), at most ``max_count``."""
        self._check_open()
        wait = self.timeout_s if timeout_s is None else max(float(timeout_s), 0.0)
        end = self.clock() + wait
        while not self._pending and (now := self.clock()) < end:
            self._advance(min(end, now + REPORT_PERIOD_S))
        count = len(self._pending) if max_count is None else min(max_count, len(self._pending))
        states = [self._pending.popleft() for _ in range(count)]
        self.reports_received += len(states)
        if states:
            self._last_state = states[-1]
        return states

    def _advance(self, until_s: float) -> None:
        """Send the frames due up to device time ``until_s`` (while the host is fed), let the
        device play them, and make the STATE reports of what it measured."""
        rate = self.device.info.frame_rate_hz
        last = math.floor(until_s * rate + 1e-9)
        fed = (math.floor((self._last_output_s + HOST_SILENCE_S) * rate + 1e-9)
               if math.isfinite(self._last_output_s) else -1)
        unplayed = math.ceil(self.clock() * rate - 1e-9)
        self._next_frame = max(self._next_frame, unplayed)  # frames past are past
        limits = (self._limits.max_amplitude_m, self._limits.max_voltage_v)
        chunk = max(1, round(CHUNK_S * rate))
        while self._next_frame <= min(last, fed):
            count = min(chunk, min(last, fed) - self._next_frame + 1)
            block = self._rendering.frames(self._next_frame, count, running=self._running,
                                           limits=limits)
            self.device.play(block.first, block.amplitude_m, block.voltage_v)
            self._sent.append(block)
            self._next_frame += count
        self._report_measured(self.device.measure(until_s))

    def _report_measured(self, measured: Measurement) -> None:
        """STATE reports of the measured frames: report ``j`` covers the frames in
        ``((j - 1) ms, j ms]`` with the values of the last of them (its timestamp), the faults
        of all of them."""
        rate = self.device.info.frame_rate_hz
        for i in range(len(measured)):
            t = float(measured.t_s[i])
            row = self._row(round(t * rate))
            faults = int(measured.faults[i]) & int(MEASURED_FAULTS)
            self._watch(faults)
            self._interval_faults |= faults | (row[1] if row else 0)
            report = math.ceil(t * INPUT_RATE_HZ - 1e-6)
            if math.ceil((t + 1.0 / rate) * INPUT_RATE_HZ - 1e-6) > report:  # its last frame
                self._pending.append(self._state(t, measured, i, row))
                self._interval_faults = 0

    def _watch(self, faults: int) -> None:
        on = bool(faults & FaultBits.WATCHDOG)
        if on and not self._watchdog_on:
            self._counts["trips"] += 1
        self._watchdog_on = on

    def _row(self, frame: int) -> tuple[FrameBlock, int, int] | None:
        """The block sent for ``frame``, its host faults and its offset in the block (None:
        the host sent no frame for it)."""
        while self._sent and self._sent[0].first + len(self._sent[0].uv) <= frame:
            self._sent.popleft()
        if self._sent and self._sent[0].first <= frame:
            block = self._sent[0]
            k = frame - block.first
            return block, int(block.faults[k]), k
        return None

    def _state(self, t: float, measured: Measurement, i: int,
               row: tuple[FrameBlock, int, int] | None) -> State:
        """The STATE report whose last frame is measured row ``i`` at device time ``t``."""
        uv, ev, texture, queued = 1.0, 1.0, -1, self._rendering.queued
        if row is not None:
            block, _, k = row
            uv, ev = float(block.uv[k]), float(block.ev[k])
            texture, queued = int(block.texture[k]), int(block.stream_queued[k])
            self._finger = block.finger[k] or self._finger
        finger = self._finger
        flags = 0
        if finger is not None and finger.contact:
            flags |= StateFlags.CONTACT
        if self._running:
            flags |= StateFlags.RUNNING
        if self._clipping is not None:
            flags |= StateFlags.CARD_LOADED
        if self._host_finger:
            flags |= StateFlags.HOST_FINGER
        if self._rendering.streaming:
            flags |= StateFlags.STREAMING
        faults = self._interval_faults
        self._counts["latched"] |= faults
        self._counts["input"] += 1
        lateral = float(measured.lateral_force_n[i])
        state = State(
            timestamp_us=round(t * 1e6) & _U32,
            sequence=self._sequence,
            flags=int(flags),
            x_10um=_counts(finger.x_mm, POSITION_UNIT_MM, *POSITION_RANGE) if finger else 0,
            y_10um=_counts(finger.y_mm, POSITION_UNIT_MM, *POSITION_RANGE) if finger else 0,
            corner_forces_mn=(0, 0, 0, 0),
            lateral_force_mn=_counts(lateral, FORCE_UNIT_N, -32768, 32767),
            amplitude_nm=_counts(float(measured.amplitude_m[i]), AMPLITUDE_UNIT_M, 0, _U16),
            voltage_dv=_counts(float(measured.voltage_v[i]), VOLTAGE_UNIT_V, 0, _U16),
            current_10na=_counts(float(measured.current_a[i]), CURRENT_UNIT_A, 0, _U16),
            target_uv_x1e4=_counts(uv, 1.0 / FRICTION_SCALE, 0, FRICTION_SCALE),
            target_ev_x1e4=_counts(ev, 1.0 / FRICTION_SCALE, FRICTION_SCALE,
                                   4 * FRICTION_SCALE),
            texture=texture,
            faults=faults,
            dropped_reports=0,
            rejected_requests=self._counts["rejected"] & _U16,
            stream_queued=min(queued, _U16),
            host_time_echo_us=finger.host_time_us if finger else 0,
            card_generation=self._generation,
            echo_age_us=(min(max(round((t - finger.placed_s) * 1e6), 0), ECHO_AGE_UNKNOWN - 1)
                         if finger else ECHO_AGE_UNKNOWN),
        )
        self._sequence = (self._sequence + 1) & _U16
        return state

    # ------------------------------------------------------------------ transport primitives

    def _refuse(self) -> DeviceError:
        return DeviceError(f"{self.uri}: a frame device speaks no hcard protocol reports; the "
                           "frame driver answers them on the host")

    def _write_output(self, report: bytes) -> None:
        raise self._refuse()

    def _set_feature(self, report: bytes) -> None:
        raise self._refuse()

    def _get_feature(self, report_id: int, size: int) -> bytes:
        raise self._refuse()

    def _read_input(self, timeout_s: float) -> bytes | None:
        raise self._refuse()

    def _close(self) -> None:
        self.device.close()
