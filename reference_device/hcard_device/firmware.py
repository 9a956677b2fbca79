"""The device firmware: host reports in, simulation commands out, STATE reports back
(spec/device-protocol.md).

:class:`Firmware` sits between the USB-HID device and :class:`hcard_device.sim.DeviceSimulation`:

- feature requests (:meth:`Firmware.get_feature`, :meth:`Firmware.set_feature`) answer with a
  report or raise :class:`ProtocolError`, which the USB layer turns into a STALL;
- output reports (:meth:`Firmware.handle_output`) become finger states, streamed frames and
  commands; malformed ones are counted and flagged (fault INVALID_REQUEST), never raised;
- the card upload runs through :class:`~hcard.device.protocol.upload.UploadStore` (staging
  buffer, CRC-32, validation, atomic swap);
- :meth:`Firmware.advance` runs the simulation and produces one STATE report per
  ``frame_rate / 1000`` frames into a bounded queue (the oldest dropped and counted);
- a SET of LIMITS that lowers the amplitude limit under the plate's present amplitude completes
  only once the braked plate has landed on it (rule PS5): the firmware runs those frames (at
  most :attr:`DeviceSimulation.limit_settle_time_s`, their STATE reports included) before it
  returns, as a device holds the control transfer's status stage, and the next
  :meth:`Firmware.advance` calls absorb the lead so device time keeps following the caller's
  clock.

Every accepted host report feeds the simulation's watchdog and keeps the live session alive
(protocol 1.2 sessions, spec section 14: START/STOP/TAKE_OVER carry the host's token, STATE
names the session; :class:`Session`). All public methods are serialised
by :attr:`Firmware.lock` (reentrant), so the USB threads and :meth:`run_realtime` may share one
firmware.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hcard.device.clip_wire import wire_clip_report
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
    REALTIME_LATE_S,
    REPORT_DESCRIPTOR,
    STREAM_FRAMES_PER_REPORT,
    TIME_UNIT_S,
    VOLTAGE_UNIT_V,
    Capability,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    DeviceKind,
    FaultBits,
    Finger,
    Limits,
    ProtocolError,
    Report,
    ReportKind,
    State,
    StateFlags,
    Stream,
    TouchSource,
    UploadAction,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadResult,
    UploadState,
    decode_output,
    report_class,
)
from hcard.device.protocol.constants import DEFAULT_MAX_CARD_BYTES
from hcard.device.protocol.reports import POSITION_RANGE
from hcard.device.protocol.upload import StagedUpload, UploadStore
from hcard.errors import HcardError
from hcard.physics.profile import DeviceProfile
from hcard.quantities import MS_PER_S
from hcard.render import Renderer
from hcard.track import FingerTrack, make_track
from hcard_device.card_check import Checker, CheckFailed, InlineChecker, assemble_card
from hcard_device.sim import TOUCH_DTYPE, DeviceSimulation, SimBlock
from hcard_device.sim.simulation import PreparedCard

DEFAULT_INPUT_QUEUE = 128
"""STATE reports the firmware keeps for the host before dropping the oldest (128 ms)."""
MAX_BLOCK_FRAMES = 1000
"""Largest simulation step of :meth:`Firmware.advance`, frames (0.1 s at 10 kHz)."""
REALTIME_PERIOD_S = 2e-3
"""Wake-up period of :meth:`Firmware.run_realtime`, s. A step costs ~0.2-0.4 ms of CPU
whatever its length (the simulation's per-call work, not its per-frame work): waking every
millisecond held ~40 % of a core idle and up to 70 % while streaming, and the served device fell
behind its clock on a busy 2-core machine; every 2 ms it holds ~20 % idle, and the STATE reports
(one per millisecond of device time) leave in pairs."""
LIMIT_SETTLE_MAX_S = 0.005
"""Longest time a SET of LIMITS may run the device to bring the plate under a lowered limit, s
(rule PS5's bound; the reference devices need at most 0.81 ms and 3.52 ms)."""
ECHOES_AHEAD = 256
"""Host samples placed ahead of the simulated frames whose echo (PI3) waits for its report
(at 1 kHz a client's FINGER reports over :data:`REALTIME_MAX_LAG_S` are 50; a client that
sends more loses the oldest echoes, never a newer one)."""
REALTIME_MAX_LAG_S = 0.05
"""Most simulated time :meth:`Firmware.run_realtime` catches up in one go, s; beyond it the
device falls behind the wall clock rather than stalling the USB threads. Either way the reports
it produces late are flagged REALTIME_LAG and counted (rule PI4, :data:`REALTIME_LATE_S`)."""

_CONTACT, _RUNNING, _CARD_LOADED = (
    int(StateFlags.CONTACT), int(StateFlags.RUNNING), int(StateFlags.CARD_LOADED)
)
_HOST_FINGER, _STREAMING, _UPLOADING, _HOST_PROFILE, _SESSION = (
    int(StateFlags.HOST_FINGER), int(StateFlags.STREAMING), int(StateFlags.UPLOADING),
    int(StateFlags.HOST_PROFILE), int(StateFlags.SESSION),
)
_LATE = int(FaultBits.REALTIME_LAG)
_I16 = (-0x8000, 0x7FFF)
_U16 = 0xFFFF
_U32 = 0xFFFF_FFFF


def _clamp(value: float, low: int, high: int) -> int:
    """Round to the nearest count and saturate at the field range (rule PI2); NaN reads 0."""
    if not math.isfinite(value):
        return high if value > 0 else (low if value < 0 else max(low, min(0, high)))
    return max(low, min(high, round(value)))


_STATE_FIELDS: tuple[tuple[str, float, int, int], ...] = (
    ("timestamp", TIME_UNIT_S, 0, 1 << 62),
    ("contact", 1.0, 0, 1),
    ("x", POSITION_UNIT_MM, *POSITION_RANGE),
    ("y", POSITION_UNIT_MM, *POSITION_RANGE),
    *((f"corner_force_{k}", FORCE_UNIT_N, *_I16) for k in range(4)),
    ("lateral_force", FORCE_UNIT_N, *_I16),
    ("amplitude", AMPLITUDE_UNIT_M, 0, _U16),
    ("voltage", VOLTAGE_UNIT_V, 0, _U16),
    ("current", CURRENT_UNIT_A, 0, _U16),
    ("target_uv", 1 / FRICTION_SCALE, 0, FRICTION_SCALE),
    ("target_ev", 1 / FRICTION_SCALE, FRICTION_SCALE, 4 * FRICTION_SCALE),
    ("texture", 1.0, -1, 255),
)
"""STATE fields read from the frame that closes an interval, in :func:`_state_counts` order:
(name, SI value of one wire count, lowest count, highest count). The time stamp is wrapped to
u32 later; the contact flag is 0/1 and the palette index -1 for a neutral frame."""
_STATE_UNIT = np.array([[unit] for _, unit, _, _ in _STATE_FIELDS])
_STATE_LOW = np.array([[float(low)] for _, _, low, _ in _STATE_FIELDS])
_STATE_HIGH = np.array([[float(high)] for _, _, _, high in _STATE_FIELDS])


def _state_counts(block: SimBlock, ends: slice) -> list[list[int]]:
    """Wire counts of :data:`_STATE_FIELDS` at the frames ``ends`` of ``block`` (the frames
    that close an interval), one list per field: SI values rounded to the nearest count,
    saturated at the field range (rule PI2), NaN as 0. All fields go through one (fields,
    reports) array, so the cost is a handful of numpy calls whatever the number of reports."""
    values = _state_values(block, ends)
    np.divide(values, _STATE_UNIT, out=values)
    values[np.isnan(values)] = 0.0
    np.rint(values, out=values)
    np.maximum(values, _STATE_LOW, out=values)  # infinities saturate too
    np.minimum(values, _STATE_HIGH, out=values)
    return values.astype(np.int64).tolist()


def _state_values(block: SimBlock, ends: slice) -> np.ndarray:
    """The SI values of :data:`_STATE_FIELDS` at the frames ``ends``, (fields, reports)."""
    first = ends.start
    if first + ends.step >= len(block):  # one report (a step of one interval or less)
        # the held touch sample as a plain tuple
        touch = dict(zip(_TOUCH_FIELDS, block.touch.item(first), strict=True))
        return np.array([
            block.t_s.item(first), touch["contact"], touch["x_mm"], touch["y_mm"],
            *block.corner_forces_n[first].tolist(), block.lateral_force_n.item(first),
            block.amplitude_m.item(first), block.voltage_v.item(first),
            block.current_a.item(first), block.target_uv.item(first),
            block.target_ev.item(first), block.texture.item(first),
        ], dtype=np.float64)[:, None]  # fmt: skip
    touch = block.touch
    forces = block.corner_forces_n[ends]
    return np.array((
        block.t_s[ends], touch["contact"][ends], touch["x_mm"][ends], touch["y_mm"][ends],
        forces[:, 0], forces[:, 1], forces[:, 2], forces[:, 3], block.lateral_force_n[ends],
        block.amplitude_m[ends], block.voltage_v[ends], block.current_a[ends],
        block.target_uv[ends], block.target_ev[ends], block.texture[ends],
    ), dtype=np.float64)  # fmt: skip


_TOUCH_FIELDS = TOUCH_DTYPE.names
"""Fields of a held touch sample (:data:`hcard_device.sim.TOUCH_DTYPE`), in order."""

_STATE_PACK = State.STRUCT.pack
_STATE_ID = State.REPORT_ID
"""A STATE report's bytes from its values in wire order (:meth:`State.encode`'s packing): the
firmware packs the values it has already saturated to their ranges (rule PI2) without making a
State, whose range checks cost more than the rest of a report. A host that decodes the report
checks the ranges (:meth:`State.decode`)."""


@dataclass(frozen=True)
class Refusal:
    """Why a COMMIT's staged bytes are refused: the UPLOAD_STATUS result and detail."""

    result: UploadResult
    detail: str


@dataclass(frozen=True)
class Checked:
    """What the checks of a COMMIT found (:meth:`Firmware._check_staged`).

    Attributes:
        data: the staged bytes.
        outcome: the card compiled or the profile to put in force, or why not.
    """

    data: bytes
    outcome: PreparedCard | DeviceProfile | Refusal


class Session:
    """Session ownership of one device (spec section 14, protocol 1.2).

    Attributes:
        number: sessions begun since power-up, wrapping u16 (0: none yet); STATE
            ``session_number`` (rule PN2).
        token: the owner's token while a session is live (0: an anonymous session, begun by
            a 1.0/1.1 host's START); None when no session is live.
        last_host_s: device time of the last host report that was not malformed or refused,
            s: the session ends ``timeout_s`` after it (rule PN7).
        timeout_s: the device's ``watchdog_ms``, s.
        ended: how the last session ended: ``""`` (none ended yet), ``stop``, ``timeout`` or
            ``take-over``.
        owner: the origin (the USB/IP connection) whose START or TAKE_OVER began the live
            session; None when it was begun by a caller that names none (rule PN12).
    """

    def __init__(self, timeout_s: float) -> None:
        self.number = 0
        self.token: int | None = None
        self.owner: object | None = None
        self.last_host_s = 0.0
        self.timeout_s = float(timeout_s)
        self.ended = ""

    @property
    def live(self) -> bool:
        """A session is live (state flag SESSION)."""
        return self.token is not None

    def owned_by_other(self, token: int) -> bool:
        """A live session whose token is not ``token`` (rules PN3, PN4)."""
        return self.token is not None and self.token != token

    def foreign(self, origin: object | None) -> bool:
        """A report from ``origin`` comes from another connection than the one that began
        the live session (rule PN13); never for a caller or a session that names no origin."""
        return (self.token is not None and self.owner is not None and origin is not None
                and origin != self.owner)

    def begin(self, token: int, owner: object | None = None) -> None:
        """A new session for ``token`` begun by ``owner`` (START with no session live, or
        TAKE_OVER: PN1, PN6, PN12)."""
        if self.token is not None:
            self.ended = "take-over"
        self.number = (self.number + 1) & _U16
        self.token = token
        self.owner = owner

    def end(self, how: str) -> None:
        """End the live session (STOP, PN4; timeout, PN7)."""
        if self.token is not None:
            self.token = None
            self.owner = None
            self.ended = how

    def expire(self, now_s: float) -> None:
        """End the live session when no host report arrived for :attr:`timeout_s` (PN7)."""
        if self.token is not None and now_s - self.last_host_s > self.timeout_s:
            self.end("timeout")

    def busy_detail(self) -> str:
        """Why a request was refused, for UPLOAD_STATUS ``detail`` (at most 46 bytes)."""
        return f"session {self.number} of token {self.token} is live"


def _no_finger_track() -> FingerTrack:
    """A track without contact: the internal sensor of a simulation nobody touches."""
    return make_track(np.zeros(1), np.zeros(1), np.zeros(1), 0.0, False, source="no finger")


class Firmware:
    """The firmware of one simulated device.

    Args:
        sim: the device simulation it drives.
        input_queue: STATE reports kept for the host before the oldest are dropped.
        max_card_bytes: largest card UPLOAD_BEGIN accepts, bytes.
        internal_track: the finger the internal touch sensor sees after CONTROL
            SET_TOUCH_SOURCE internal (None: nobody touches).
        checker: checks the bytes of a COMMIT (default: in the calling thread, outside the
            lock; :class:`~hcard_device.card_check.ProcessChecker` in a worker process).
    """

    report_descriptor: bytes = REPORT_DESCRIPTOR
    """The HID report descriptor this device's USB interface declares and returns for
    GET_DESCRIPTOR(Report) (protocol PD1, PD2: the bytes of spec/device-protocol.md 4.1; its
    HID descriptor announces their length). A negative control declares another."""

    def __init__(
        self,
        sim: DeviceSimulation,
        *,
        input_queue: int = DEFAULT_INPUT_QUEUE,
        max_card_bytes: int = DEFAULT_MAX_CARD_BYTES,
        internal_track: FingerTrack | None = None,
        checker: Checker | None = None,
    ) -> None:
        if input_queue < 1:
            raise ValueError(f"input_queue must be >= 1, got {input_queue}")
        self.sim = sim
        self.config = sim.config
        ratio = self.config.frame_rate_hz / INPUT_RATE_HZ
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"frame rate {self.config.frame_rate_hz} Hz is not a whole multiple of the "
                f"{INPUT_RATE_HZ} Hz input report rate"
            )
        self.frames_per_report = round(ratio)
        self.lock = threading.RLock()
        self.upload = UploadStore(max_card_bytes)
        self.internal_track = internal_track
        self.input_capacity = input_queue
        self._queue: deque[bytes] = deque()
        self._latest: bytes = b""
        self._frame_debt = 0.0
        self._interval_frames = 0
        self._interval_faults = 0
        self._pending_faults = 0
        self._watchdog_was_tripped = False
        self._touch_source = TouchSource.INTERNAL
        self._streaming = False
        self._expected_seq: int | None = None
        self._host_time_echo = 0
        self._echo_placed_us: int | None = None  # device time of the echoed sample (PO2)
        # (host time, placement) of samples placed ahead of the frames simulated (_arrival_s):
        # echoed from the first report that reaches their placement
        self._echoes_ahead: deque[tuple[int, int]] = deque(maxlen=ECHOES_AHEAD)
        # run_realtime's clock, its origin and the device time granted so far (_follow_clock)
        self._clock: Callable[[], float] | None = None
        self._clock_origin = 0.0
        self._served_s = 0.0
        # reports whose last frame is before this device time (us) are produced late (PI4);
        # -1: none (set by _follow_clock around a catch-up only)
        self._late_before_us = -1
        self._clip_index = 0
        self._sequence = 0
        self.session = Session(self.config.watchdog_s)
        self.checker: Checker = checker if checker is not None else InlineChecker()
        """Checks the staged bytes of a COMMIT (:mod:`hcard_device.card_check`); the served
        device uses a worker process."""
        self._active_card: PreparedCard | None = None  # the active card, compiled
        # counters (spec 8.4), zeroed by CLEAR_COUNTERS: the simulation's, one set
        self.counts = sim.counts

    # ---- host requests ----------------------------------------------------------------------

    def get_feature(self, report_id: int, origin: object | None = None) -> bytes:
        """GET_REPORT(Feature): the report's bytes, report ID first.

        ``origin``: the connection the request came from (None: unknown). A GET is answered
        whoever asks; from another connection than the live session's owner it does not feed
        the watchdog nor keep the session alive (rule PN13).

        Raises:
            ProtocolError: unknown or non-feature report ID (answer with STALL).
        """
        with self.lock:
            try:
                cls = report_class(ReportKind.FEATURE, report_id)
            except ProtocolError:
                self.counts.rejected_requests += 1
                raise
            if not self._foreign(origin):
                self._host_report()
            return self._feature_report(cls).encode()

    def set_feature(self, data: bytes, origin: object | None = None) -> None:
        """SET_REPORT(Feature) with the report's bytes, report ID first.

        Upload failures are not errors here: they are reported in UPLOAD_STATUS (rule PU6).
        A COMMIT or COMMIT_PROFILE returns once the staged bytes are checked and in force (or
        refused): the check runs without the firmware's lock (rule PU12), so the device keeps
        running meanwhile. ``origin``: the connection the request came from (None: unknown).

        Raises:
            ProtocolError: unknown ID, read-only report, malformed report, or a SET from
                another connection than the live session's owner (rule PN13) (STALL).
        """
        with self.lock:
            try:
                report = self._decode_feature_set(data)
            except ProtocolError:
                self.counts.rejected_requests += 1
                raise
            if self._foreign(origin):
                self.counts.rejected_requests += 1
                self._pending_faults |= FaultBits.SESSION_BUSY
                raise ProtocolError(
                    f"refused: session {self.session.number} belongs to another connection",
                    report=type(report).name())
            self._host_report()
            if isinstance(report, UploadEnd) and report.action in (
                    UploadAction.COMMIT, UploadAction.COMMIT_PROFILE):
                staged = self._stage_commit(report.action)
                if staged is None:
                    self.counts.rejected_requests += 1
                    return
            else:
                if not self._apply_feature(report):
                    self.counts.rejected_requests += 1
                return
        checked = self._check_staged(report.action, staged)  # without the lock (PU12)
        with self.lock:
            if not self._finish_commit(report.action, staged, checked):
                self.counts.rejected_requests += 1
            if not self._foreign(origin):
                self._host_report()

    def handle_output(self, data: bytes, origin: object | None = None) -> None:
        """An output report (interrupt OUT or SET_REPORT(Output)), report ID first.

        Never raises: a malformed or refused report is ignored, counted in
        ``rejected_requests`` and flagged INVALID_REQUEST in the next STATE report (PE2); one
        from another connection than the live session's owner (``origin``; TAKE_OVER
        excepted) is refused and flagged SESSION_BUSY too (rule PN13).
        """
        with self.lock:
            try:
                report = decode_output(data)
            except ProtocolError:
                self._refuse()
                return
            if self._foreign(origin) and not (
                    isinstance(report, Control) and report.command == Command.TAKE_OVER):
                self._refuse()
                self._pending_faults |= FaultBits.SESSION_BUSY
                return
            if not self._apply_output(report, origin):
                self._refuse()
                return
            if not (isinstance(report, Control) and report.command == Command.CLEAR_COUNTERS):
                self.counts.output_reports += 1  # CLEAR_COUNTERS leaves every counter at 0
            self._host_report()

    def _foreign(self, origin: object | None) -> bool:
        """A request from ``origin`` while a session another connection began is live
        (rule PN13)."""
        if origin is None or self.session.owner is None:
            return False
        self.session.expire(self.sim.time_s)
        return self.session.foreign(origin)

    def _host_report(self) -> None:
        """A host report that was not malformed or refused arrived: it feeds the watchdog
        (PS3) and keeps the live session alive (PN7)."""
        self.sim.feed_watchdog()
        self.session.last_host_s = self.sim.time_s

    # ---- time -------------------------------------------------------------------------------

    def advance(self, seconds: float) -> None:
        """Run the simulation for ``seconds`` of device time (whole frames; the remainder is
        carried to the next call) and queue the STATE reports of every completed interval."""
        if not math.isfinite(seconds) or seconds <= 0:
            return
        with self.lock:
            self._frame_debt += seconds * self.config.frame_rate_hz
            frames = math.floor(self._frame_debt + 1e-9)
            if frames <= 0:
                return  # a SET of LIMITS ran ahead (PS5): the clock catches up first
            self._frame_debt = max(self._frame_debt - frames, 0.0)
            while frames > 0:
                n = min(frames, MAX_BLOCK_FRAMES)
                queued_before = self.sim.queued_frames
                self._run_block(self.sim.step(n), queued_before)
                frames -= n
            self.upload.poll(self.sim.time_s)

    def take_input_reports(self, max_count: int | None = None) -> list[bytes]:
        """Remove and return queued STATE reports, oldest first (at most ``max_count``)."""
        with self.lock:
            count = len(self._queue)
            if max_count is not None:
                count = max(0, min(max_count, count))
            return [self._queue.popleft() for _ in range(count)]

    def latest_input_report(self) -> bytes:
        """The most recent STATE report (for GET_REPORT(Input)); produced now when none yet."""
        with self.lock:
            if not self._latest:
                self._latest = self._idle_state().encode()
            return self._latest

    @property
    def queued_input_reports(self) -> int:
        """STATE reports waiting for the host."""
        with self.lock:
            return len(self._queue)

    def run_realtime(
        self,
        stop_event: threading.Event,
        *,
        period_s: float = REALTIME_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
        after_step: Callable[[], object] | None = None,
    ) -> None:
        """Advance the simulation following ``clock`` until ``stop_event`` is set.

        Wakes every ``period_s``, advances by the wall time elapsed and then calls
        ``after_step`` (outside the lock: the server hands the new STATE reports to its
        connections there, on this thread, instead of polling for them on another). When the
        simulation falls more than :data:`REALTIME_MAX_LAG_S` behind, the excess is skipped
        (device time then runs slower than the wall clock instead of building up a backlog).
        Every report
        produced more than :data:`REALTIME_LATE_S` after its last frame was due on ``clock``
        (the catch-up after a late wake-up, and every skip) carries fault REALTIME_LAG and
        counts in COUNTERS ``late_reports`` (rule PI4): a host knows that the run it measured
        was not one of a device in real time."""
        with self.lock:
            self._clock = clock
            self._clock_origin = clock()
            self._served_s = 0.0
        try:
            while not stop_event.is_set():
                with self.lock:
                    self._follow_clock()
                if after_step is not None:
                    after_step()
                stop_event.wait(period_s)
        finally:
            with self.lock:
                self._clock = None

    def _follow_clock(self) -> None:
        """While :meth:`run_realtime` serves: run the simulation up to the device's clock (the
        wall clock's, less what was skipped); called at every wake-up of the loop."""
        if self._clock is None:
            return
        behind = self._clock() - self._clock_origin - self._served_s
        due = behind
        if due > REALTIME_MAX_LAG_S:
            self._clock_origin += due - REALTIME_MAX_LAG_S
            due = REALTIME_MAX_LAG_S
        if due > 0:
            if behind > REALTIME_LATE_S:
                # the report ending ``x`` into this catch-up is ``behind - x`` late (rule PI4)
                self._late_before_us = math.ceil(
                    (self.sim.time_s + behind - REALTIME_LATE_S) / TIME_UNIT_S)
            try:
                self.advance(due)
            finally:
                self._late_before_us = -1
            self._served_s += due

    # ---- features ---------------------------------------------------------------------------

    def _decode_feature_set(self, data: bytes) -> Report:
        if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) == 0:
            raise ProtocolError("empty feature report")
        cls = report_class(ReportKind.FEATURE, data[0])
        if not cls.SET:
            raise ProtocolError("read-only report", report=cls.name())
        report = cls.decode(data)
        if isinstance(report, UploadData) and not report.data:
            raise ProtocolError("length 0: a chunk carries 1..58 bytes", report=cls.name())
        if isinstance(report, UploadEnd) and report.action == UploadAction.NONE:
            raise ProtocolError("action 0: COMMIT is 1, ABORT is 2", report=cls.name())
        if isinstance(report, ClipReport) and report.item_index >= self._clip_item_count():
            raise ProtocolError(
                f"item_index {report.item_index} is beyond the "
                f"{self._clip_item_count()} clipped items",
                report=cls.name(),
            )
        return report

    def _apply_feature(self, report: Report) -> bool:
        """Carry out a decoded SET; False when the request was refused (an upload failure)."""
        now = self.sim.time_s
        if isinstance(report, Limits):
            self.sim.set_limits(
                max_amplitude_m=report.max_amplitude_m,
                max_voltage_v=report.max_voltage_v,
                max_current_a=report.max_current_a,
            )
            self._clip_index = 0
            self._settle_limits()
            return True
        if isinstance(report, ClipReport):
            self._clip_index = report.item_index
            return True
        if isinstance(report, UploadBegin):
            return self.upload.begin(report, now)
        if isinstance(report, UploadData):
            return self.upload.data(report, now)
        assert isinstance(report, UploadEnd) and report.action == UploadAction.ABORT
        return self.upload.abort(now)

    # ---- COMMIT and COMMIT_PROFILE (PU3, PU9, PU12) --------------------------------------------

    def _stage_commit(self, action: int) -> StagedUpload | None:
        """Under the lock: a COMMIT's session check (PN5), length and CRC-32; the staged bytes
        to check, or None when the COMMIT is decided already (failed, or already checking)."""
        now = self.sim.time_s
        self.session.expire(now)
        if self.session.token:  # a session with a token is live: no commit (PN5)
            self._pending_faults |= FaultBits.SESSION_BUSY
            self.upload.busy(self.session.busy_detail())
            return None
        return self.upload.stage_commit(now)

    def _check_staged(self, action: int, staged: StagedUpload) -> Checked:
        """Without the lock: check the CRC-32 and the staged bytes (:attr:`checker`), and
        compile a card for the simulation."""
        data = bytes(staged.buffer)
        if not staged.crc_matches():
            return Checked(data, Refusal(UploadResult.CRC_MISMATCH, ""))
        if action == UploadAction.COMMIT_PROFILE:
            profile = self.checker.check_profile(data)
            if isinstance(profile, CheckFailed):
                return Checked(data, Refusal(UploadResult.INVALID_PROFILE, profile.detail))
            return Checked(data, profile.profile)
        checked = self.checker.check_card(data, self.sim.render_options)
        if isinstance(checked, CheckFailed):
            return Checked(data, Refusal(UploadResult.INVALID_CARD, checked.detail))
        card = assemble_card(checked.pieces)
        return Checked(data, PreparedCard(
            card, Renderer.from_compiled(card, checked.compiled, self.sim.render_options),
            checked.extremes))

    def _finish_commit(self, action: int, staged: StagedUpload, checked: Checked) -> bool:
        """Under the lock: put what was checked in force between two frames, or fail the
        upload; True when it is in force. Nothing happens when the upload was discarded or
        failed while it was checked; a session begun meanwhile makes it BUSY (PN5)."""
        if not self.upload.is_staged(staged):
            return False
        outcome = checked.outcome
        if isinstance(outcome, Refusal):  # CRC first, as PU3 orders the checks
            return self.upload.fail_check(outcome.result, outcome.detail)
        self.session.expire(self.sim.time_s)
        if self.session.token:
            self._pending_faults |= FaultBits.SESSION_BUSY
            return self.upload.fail_check(UploadResult.BUSY, self.session.busy_detail())
        if isinstance(outcome, DeviceProfile):
            try:
                self.sim.set_profile(outcome)
            except HcardError as exc:
                return self.upload.fail_check(UploadResult.INVALID_PROFILE, str(exc))
            self._clip_index = 0
            return self.upload.finish_profile()
        self.sim.load_prepared(outcome)
        self._streaming = False
        self._active_card = outcome
        self._clip_index = 0
        return self.upload.finish_card(staged, outcome.card, checked.data)

    def _settle_limits(self) -> int:
        """Run the device, frame by frame with its STATE reports, until the limits set are in
        force (rule PS5: the plate braked down to a lowered amplitude limit), at most
        :data:`LIMIT_SETTLE_MAX_S`; the frames run are owed to the caller's clock (a negative
        frame debt that :meth:`advance` absorbs). Returns the frames run."""
        rate = self.config.frame_rate_hz
        budget = math.ceil(LIMIT_SETTLE_MAX_S * rate)
        frames = 0
        while self.sim.limits_pending and frames < budget:
            # the frames the braking surely needs in one step, then frame by frame
            n = min(max(math.floor(self.sim.pending_settle_time_s * rate), 1), budget - frames)
            queued_before = self.sim.queued_frames
            self._run_block(self.sim.step(n), queued_before)
            frames += n
        self._frame_debt -= frames
        return frames

    def _feature_report(self, cls: type[Report]) -> Report:
        if cls is DeviceInfo:
            return self.device_info()
        if cls is Limits:
            limits = self.sim.limits
            return Limits.from_si(
                limits.max_amplitude_m, limits.max_voltage_v, limits.max_current_a
            )
        if cls is UploadBegin:
            return self.upload.begin_readback()
        if cls is UploadData:
            return self.upload.data_readback()
        if cls is UploadEnd:
            return UploadEnd(UploadAction.NONE)
        if cls is ClipReport:
            return self._clip_report()
        if cls is Counters:
            return self.counters()
        return self.upload.status()

    def device_info(self) -> DeviceInfo:
        """The DEVICE_INFO report of this device."""
        cfg = self.config
        caps = (
            Capability.HOST_FINGER
            | Capability.DIRECT_STREAMING
            | Capability.CORNER_FORCES
            | Capability.LATERAL_FORCE
            | Capability.PROFILE
        )
        if cfg.has_uv:
            caps |= Capability.UV
        if cfg.has_ev:
            caps |= Capability.EV
        if cfg.touch_rate_hz > 0:  # always, for the simulated devices
            caps |= Capability.INTERNAL_TOUCH
        width, height = cfg.surface_mm
        hw = self.sim.hardware_limits
        return DeviceInfo(
            protocol_major=PROTOCOL_MAJOR,
            protocol_minor=PROTOCOL_MINOR,
            device_kind=int(DeviceKind.COUPLED if cfg.has_ev else DeviceKind.EVITA),
            capabilities=int(caps),
            plate_frequency_hz=_clamp(cfg.limits.plate_frequency, 0, _U32),
            frame_rate_hz=_clamp(cfg.frame_rate_hz, 0, _U16),
            touch_rate_hz=_clamp(cfg.touch_rate_hz, 0, _U16),
            input_rate_hz=INPUT_RATE_HZ,
            ev_carrier_hz=_clamp(cfg.limits.carrier_frequency, 0, _U16) if cfg.has_ev else 0,
            max_amplitude_nm=_clamp(hw.max_amplitude_m / AMPLITUDE_UNIT_M, 0, _U16),
            max_voltage_dv=_clamp(hw.max_voltage_v / VOLTAGE_UNIT_V, 0, _U16),
            max_current_10na=_clamp(hw.max_current_a / CURRENT_UNIT_A, 0, _U16),
            max_card_bytes=self.upload.max_card_bytes,
            watchdog_ms=_clamp(cfg.watchdog_s * MS_PER_S, 0, _U16),
            stream_capacity_frames=_clamp(cfg.stream_queue_frames, 0, _U16),
            stream_frames_per_report=STREAM_FRAMES_PER_REPORT,
            surface_width_10um=_clamp(width / POSITION_UNIT_MM, 0, _U16),
            surface_height_10um=_clamp(height / POSITION_UNIT_MM, 0, _U16),
        )

    def counters(self) -> Counters:
        """The COUNTERS report."""
        return self.counts.report()

    def _clip_item_count(self) -> int:
        return len(self.sim.clip_report.items) if self.upload.active else 0

    def _clip_report(self) -> ClipReport:
        return wire_clip_report(self.sim.clip_report if self.upload.active else None,
                                self.upload.generation, self._clip_index)

    def _arrival_s(self) -> float:
        """The device time of a report arriving now, s: while :meth:`run_realtime` serves, the
        device's clock (ahead of the simulated frames by the time since the loop last ran, at
        most :data:`REALTIME_MAX_LAG_S`, which the loop would skip); else the simulation's.

        A FINGER report is timed there without running the simulation up to it (the frames
        before that time keep the previous finger, :class:`hcard_device.sim.finger.HostFinger`).
        Timed at the simulation's last step instead, a report that came while the simulation
        lagged arrived up to :data:`REALTIME_MAX_LAG_S` early on the device clock; the host
        clock offset (PO2, the smallest arrival - host time ever seen) kept that error for the
        device's life and the device rendered from stale samples (a loaded machine failed A1 on
        a noisy stroke, 0.11-0.18). Running the simulation up to each arrival instead cost a
        step per report (0.2-0.4 ms of CPU whatever its length): a client that sent FINGER
        reports as fast as it could took 90 % of a core on its connection's thread and cut
        another client's STATE stream to 0.56-0.83 of its share.
        """
        if self._clock is None:
            return self.sim.time_s
        behind = self._clock() - self._clock_origin - self._served_s
        carried = self._frame_debt / self.config.frame_rate_hz  # a frame's fraction not run
        return self.sim.time_s + min(max(behind + carried, 0.0), REALTIME_MAX_LAG_S)

    # ---- outputs ----------------------------------------------------------------------------

    def _refuse(self) -> None:
        self.counts.rejected_requests += 1
        self._pending_faults |= FaultBits.INVALID_REQUEST

    def _apply_output(self, report: Report, origin: object | None = None) -> bool:
        """Carry out a decoded output report from ``origin``; False when it is refused
        (PO5)."""
        if isinstance(report, Finger):
            self._touch_source = TouchSource.HOST
            placed_s = self.sim.host_finger(
                self._arrival_s(), report.x_mm, report.y_mm, report.fn_n, report.contact,
                host_time_s=report.host_time_us * TIME_UNIT_S,
            )
            if placed_s is not None:
                self._place_echo(report.host_time_us, round(placed_s / TIME_UNIT_S))
            return True
        if isinstance(report, Stream):
            if self._expected_seq is not None and report.stream_seq != self._expected_seq:
                self.counts.stream_gaps += 1
            self._expected_seq = (report.stream_seq + 1) & _U16
            self.sim.stream_frames(np.asarray(report.uv), np.asarray(report.ev))
            self._streaming = True
            return True
        assert isinstance(report, Control)
        return self._command(report, origin)

    def _command(self, report: Control, origin: object | None = None) -> bool:
        command = report.command
        if command == Command.KEEPALIVE:
            return True
        if command in (Command.START, Command.STOP, Command.TAKE_OVER):
            return self._session_command(command, report.argument, origin)
        if command == Command.CLEAR_COUNTERS:
            self.counts.clear()
            return True
        if command == Command.DEVICE_PROFILE:
            self.session.expire(self.sim.time_s)
            if self.session.token:  # PN5: the profile in force stays during a session
                return self._refuse_busy()
            self.sim.set_profile(None)
            self._clip_index = 0
            return True
        if command == Command.PLAY_CARD:
            if self.upload.active is None or self._active_card is None:
                return False
            self.sim.load_prepared(self._active_card)  # compiled at its COMMIT (PU12)
            self._streaming = False
            return True
        # SET_TOUCH_SOURCE (the simulated devices have both touch sources)
        if report.argument == TouchSource.HOST:
            self._touch_source = TouchSource.HOST
            return True
        self._touch_source = TouchSource.INTERNAL
        self.sim.use_internal_finger(self.internal_track or _no_finger_track())
        return True

    def _session_command(self, command: int, token: int, origin: object | None = None) -> bool:
        """START (PN1, PN3), STOP (PN4) or TAKE_OVER (PN6) with the host's ``token`` from
        ``origin`` (the session begun is attributed to it, PN12); False when refused because
        another token's session is live."""
        session = self.session
        session.expire(self.sim.time_s)
        if command == Command.TAKE_OVER:
            session.begin(token, origin)
            self.sim.start()
            return True
        if session.owned_by_other(token):
            return self._refuse_busy()
        if command == Command.STOP:
            self.sim.stop()
            session.end("stop")
            return True
        if not session.live:
            session.begin(token, origin)
        self.sim.start()
        return True

    def _refuse_busy(self) -> bool:
        """A request refused because another host's session is live: flagged SESSION_BUSY
        (and INVALID_REQUEST, PE2) in the next STATE report by the caller's refusal."""
        self._pending_faults |= FaultBits.SESSION_BUSY
        return False

    # ---- input reports ----------------------------------------------------------------------

    def _run_block(self, block: SimBlock, queued_before: int) -> None:
        """Turn a block of frames into STATE reports at every completed interval.

        ``queued_before``: streamed frames queued before the block; the queue gives one frame
        per frame period while it lasts, which gives its level at every frame of the block."""
        n = len(block)
        if n == 0:
            return
        faults = block.faults
        any_fault = int(np.bitwise_or.reduce(faults))
        if any_fault or self._watchdog_was_tripped:
            self._count_watchdog_trips(faults)
        per = self.frames_per_report
        first_end = per - self._interval_frames - 1  # index of the frame closing the interval
        self._interval_frames = (self._interval_frames + n) % per
        if first_end >= n:
            self._interval_faults |= any_fault
            return
        ends = range(first_end, n, per)
        columns = zip(
            *_state_counts(block, slice(first_end, n, per)),
            [max(queued_before - (end + 1), self.sim.queued_frames) for end in ends],
            self._covered_faults(faults, ends, any_fault),
            strict=True,
        )
        static = self._static_flags()
        clipped = int(FaultBits.CARD_CLIPPED) if self._clip_item_count() and not self._streaming \
            else 0
        session, generation = self.session, self.upload.generation
        late_before = self._late_before_us
        for (time_us, contact, x, y, f0, f1, f2, f3, lateral, amplitude, voltage, current,
             uv, ev, texture, queued, sim_faults) in columns:  # fmt: skip
            session.expire(time_us * TIME_UNIT_S)
            faults = self._faults(sim_faults, clipped)
            echo, echo_age = self._echo_at(time_us)
            if time_us < late_before:  # produced late on the device's real-time clock (PI4)
                faults |= _LATE
                self.counts.late_reports += 1
            self._emit(_STATE_PACK(
                _STATE_ID, time_us & _U32, self._sequence, self._flags(static, contact), x, y,
                f0, f1, f2, f3, lateral, amplitude, voltage, current, uv, ev, texture, faults,
                self.counts.input_dropped & _U16, self.counts.rejected_requests & _U16,
                min(max(queued, 0), _U16), echo, generation, session.number,
                session.token or 0, echo_age,
            ), faults)  # fmt: skip

    def _covered_faults(self, faults: np.ndarray, ends: range, any_fault: int) -> list[int]:
        """The simulation faults of each interval a block completes (``ends``: the frames that
        close them; ``any_fault``: the OR of all the block's faults), the first one with the
        faults of its frames in earlier blocks; keeps those of the frames after the last end
        for the next block."""
        last = ends[-1] + 1
        if not any_fault:  # nothing in this block
            covered = [self._interval_faults, *([0] * (len(ends) - 1))]
            self._interval_faults = 0
            return covered
        if len(ends) == 1:
            covered = [int(np.bitwise_or.reduce(faults[:last])) | self._interval_faults]
        else:
            starts = np.arange(ends[0] + 1 - ends.step, last, ends.step)
            starts[0] = 0
            covered = np.bitwise_or.reduceat(faults[:last], starts).tolist()
            covered[0] |= self._interval_faults
        self._interval_faults = int(np.bitwise_or.reduce(faults[last:]))
        return covered

    def _count_watchdog_trips(self, faults: np.ndarray) -> None:
        """Count the watchdog's trips (frames where WATCHDOG rises) in a block's faults."""
        watchdog_bit = int(FaultBits.WATCHDOG)
        if not self._watchdog_was_tripped and not int(np.bitwise_or.reduce(faults)) & watchdog_bit:
            return  # not tripped before nor during the block
        watchdog = (faults & watchdog_bit) != 0
        previous = np.concatenate(([self._watchdog_was_tripped], watchdog[:-1]))
        self.counts.watchdog_trips += int(np.count_nonzero(watchdog & ~previous))
        self._watchdog_was_tripped = bool(watchdog[-1])

    def _static_flags(self) -> int:
        """STATE flags of the device's present state that no report of a block changes (all
        but CONTACT and SESSION)."""
        flags = 0
        if self.sim.running:
            flags |= _RUNNING
        if self.upload.active is not None:
            flags |= _CARD_LOADED
        if self._touch_source == TouchSource.HOST:
            flags |= _HOST_FINGER
        if self._streaming:
            flags |= _STREAMING
        if self.upload.state == UploadState.RECEIVING:
            flags |= _UPLOADING
        if self.sim.host_profile:
            flags |= _HOST_PROFILE
        return flags

    def _flags(self, static: int, contact: int) -> int:
        """STATE flags: ``static`` (:meth:`_static_flags`) with the frame's contact and the
        session's state."""
        flags = static | (_CONTACT if contact else 0)
        if self.session.live:
            flags |= _SESSION
        return flags

    def _session_fields(self) -> dict[str, int]:
        """STATE ``session_number`` and ``session_token`` (rule PN2)."""
        return {"session_number": self.session.number,
                "session_token": self.session.token or 0}

    def _faults(self, sim_faults: int, clipped: int) -> int:
        """STATE faults: the interval's simulation faults, ``clipped`` (CARD_CLIPPED while a
        clipped card plays) and the firmware's events since the previous report (which are
        consumed)."""
        faults = sim_faults | int(self._pending_faults) | clipped
        self._pending_faults = 0
        return faults & _U16

    def _emit(self, data: bytes, faults: int) -> None:
        """Queue a STATE report (its bytes, and its ``faults``), dropping the oldest when the
        queue is full (rule PT5)."""
        self.counts.latched_faults |= faults
        self._sequence = (self._sequence + 1) & _U16
        self.counts.input_reports += 1
        self._latest = data
        if len(self._queue) >= self.input_capacity:
            self._queue.popleft()
            self.counts.input_dropped += 1
            self._pending_faults |= FaultBits.INPUT_DROPPED
        self._queue.append(data)

    def _idle_state(self) -> State:
        """A STATE report before the first interval completed."""
        echo, echo_age = self._echo_at(round(self.sim.time_s / TIME_UNIT_S))
        return State(
            timestamp_us=round(self.sim.time_s / TIME_UNIT_S) & _U32, sequence=self._sequence,
            flags=0, x_10um=0, y_10um=0, corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0,
            amplitude_nm=0, voltage_dv=0, current_10na=0, target_uv_x1e4=FRICTION_SCALE,
            target_ev_x1e4=FRICTION_SCALE, texture=-1, faults=0, dropped_reports=0,
            rejected_requests=self.counts.rejected_requests & _U16, stream_queued=0,
            host_time_echo_us=echo, card_generation=self.upload.generation,
            echo_age_us=echo_age,
            **self._session_fields(),
        )  # fmt: skip

    def _place_echo(self, host_time_us: int, placed_us: int) -> None:
        """A host sample of ``host_time_us`` was placed at ``placed_us`` (device clock, us):
        echoed (PI3) by the reports from that time on."""
        if placed_us <= round(self.sim.time_s / TIME_UNIT_S):
            self._echoes_ahead.clear()  # placements rise: none ahead precedes this one
            self._host_time_echo, self._echo_placed_us = host_time_us, placed_us
        else:
            self._echoes_ahead.append((host_time_us, placed_us))

    def _echo_at(self, time_us: int) -> tuple[int, int]:
        """STATE host_time_echo_us and echo_age_us of a report whose last frame is at
        ``time_us`` (device clock, us, not wrapped): the latest sample placed by then."""
        ahead = self._echoes_ahead
        while ahead and ahead[0][1] <= time_us:
            self._host_time_echo, self._echo_placed_us = ahead.popleft()
        return self._host_time_echo, self._echo_age(time_us)

    def _echo_age(self, time_us: int) -> int:
        """STATE echo_age_us of a report whose last frame is at ``time_us`` (device clock, us,
        not wrapped): the time since the echoed sample's placement (PI3), saturated (PI2)."""
        if self._echo_placed_us is None:
            return ECHO_AGE_UNKNOWN
        return min(max(time_us - self._echo_placed_us, 0), ECHO_AGE_UNKNOWN - 1)
