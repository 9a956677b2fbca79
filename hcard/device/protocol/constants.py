"""Numbers of the hcard device protocol (spec/device-protocol.md): version, report IDs, wire
units, enumerations and bit flags.

Every value here is normative through the spec; the spec's tables are the definition, this
module is the reference implementation of them.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag

PROTOCOL_MAJOR = 1
"""Major protocol version (incompatible changes). A host MUST refuse another major
(spec/device-protocol.md rule PV2)."""
PROTOCOL_MINOR = 4
"""Minor protocol version (compatible additions; 1.2 adds session ownership, spec section 14;
1.3 the echo age of STATE, rule PI3; 1.4 the real-time lag fault and counter, rule PI4)."""

MAX_REPORT_BYTES = 64
"""Largest report on the wire, bytes, including the report ID byte (one full-speed packet)."""

VENDOR_USAGE_PAGE = 0xFF00
"""Vendor-defined HID usage page of the device's application collection."""
APPLICATION_USAGE = 0x01
"""Usage of the application collection on the vendor page."""

# ---- wire units (one count of the integer field is this much of the SI quantity) ----------
TIME_UNIT_S = 1e-6
"""Time stamps: microseconds, u32, wrapping every 2**32 us (about 71.6 minutes)."""
POSITION_UNIT_MM = 0.01
"""Positions: 0.01 mm (10 um), signed 32 bit."""
FORCE_UNIT_N = 1e-3
"""Forces: millinewton."""
AMPLITUDE_UNIT_M = 1e-9
"""Plate vibration amplitude (peak-to-peak, as the device limits): nanometre."""
VOLTAGE_UNIT_V = 0.1
"""EV voltage (envelope): 0.1 V."""
CURRENT_UNIT_A = 1e-8
"""EV current: 0.01 uA (10 nA)."""
REALTIME_LATE_S = 0.005
"""A STATE report produced more than this after its interval's last frame was due on the
device's real-time clock is flagged REALTIME_LAG and counted (rule PI4), s: five report periods,
half the 10 ms latency bound of the conformance suite (spec/conformance.md D3)."""
ECHO_AGE_UNKNOWN = 0xFFFF_FFFF
"""STATE.echo_age_us when the device cannot say (no sample applied yet, or a 1.0-1.2 device)."""
FRICTION_SCALE = 10_000
"""Relative friction: counts per 1.0 (1e-4 resolution, far below the 8 % JND)."""

UV_MIN, UV_MAX = 0, FRICTION_SCALE
"""Range of a UV target in counts: relative friction [0, 1]."""
EV_MIN, EV_MAX = FRICTION_SCALE, 4 * FRICTION_SCALE
"""Range of an EV target in counts: relative friction [1, 4]."""

STREAM_FRAMES_PER_REPORT = 15
"""Frames carried by one STREAM output report."""
UPLOAD_CHUNK_BYTES = 58
"""Card bytes carried by one UPLOAD_DATA feature report."""
UPLOAD_DETAIL_BYTES = 46
"""Bytes of the failure detail (field path) in UPLOAD_STATUS."""
CLIP_NAME_BYTES = 41
"""Bytes of the texture name in CLIP_REPORT."""

INPUT_RATE_HZ = 1000
"""Input reports per second (one per full-speed frame at bInterval 1 ms)."""
UPLOAD_TIMEOUT_S = 2.0
"""An upload with no upload traffic for this long (device time) fails with TIMEOUT, s."""
DEFAULT_MAX_CARD_BYTES = 2 * 1024 * 1024
"""Largest card the reference device stores: 2 MiB, above the largest valid binary card
(about 1.4 MB, spec/README.md section 4)."""


class ReportKind(IntEnum):
    """HID report types (HID 1.11 section 7.2.1): the high byte of wValue in GET/SET_REPORT."""

    INPUT = 1
    OUTPUT = 2
    FEATURE = 3


class ReportId(IntEnum):
    """Report IDs. IDs are unique across kinds; 0 is never used (HID reserves it)."""

    STATE = 0x01
    FINGER = 0x10
    STREAM = 0x11
    CONTROL = 0x12
    DEVICE_INFO = 0x20
    LIMITS = 0x21
    UPLOAD_BEGIN = 0x22
    UPLOAD_DATA = 0x23
    UPLOAD_END = 0x24
    UPLOAD_STATUS = 0x25
    CLIP_REPORT = 0x26
    COUNTERS = 0x27


class DeviceKind(IntEnum):
    """DEVICE_INFO.device_kind."""

    EVITA = 1
    """E-ViTa (thesis 5.1): glass plate, UV only."""
    COUPLED = 2
    """Coupled UV + EV stimulator (thesis 4.2)."""


class Capability(IntFlag):
    """DEVICE_INFO.capabilities bits."""

    UV = 1 << 0
    """Ultrasonic friction reduction."""
    EV = 1 << 1
    """Electrovibration."""
    HOST_FINGER = 1 << 2
    """Accepts FINGER output reports (touch sensed on the host side)."""
    INTERNAL_TOUCH = 1 << 3
    """Has its own touch sensor (position in STATE while the touch source is internal)."""
    DIRECT_STREAMING = 1 << 4
    """Accepts STREAM output reports."""
    CORNER_FORCES = 1 << 5
    """Four corner force sensors (STATE.corner_forces_mn)."""
    LATERAL_FORCE = 1 << 6
    """Lateral (friction) force sensor (STATE.lateral_force_mn)."""
    PROFILE = 1 << 7
    """Takes a device profile from the host (UPLOAD_END COMMIT_PROFILE, CONTROL DEVICE_PROFILE;
    protocol 1.1)."""


class StateFlags(IntFlag):
    """STATE.flags bits."""

    CONTACT = 1 << 0
    """A finger touches the surface (latest touch sample)."""
    RUNNING = 1 << 1
    """START received and no STOP since: the device renders."""
    CARD_LOADED = 1 << 2
    """A card is active."""
    HOST_FINGER = 1 << 3
    """The touch source is the host (FINGER reports), not the internal sensor."""
    STREAMING = 1 << 4
    """Frames come from the stream queue (direct streaming), not from the card."""
    UPLOADING = 1 << 5
    """A card upload is in progress (UPLOAD_STATUS.state RECEIVING)."""
    HOST_PROFILE = 1 << 6
    """The device renders with a profile the host uploaded, not its own (protocol 1.1)."""
    SESSION = 1 << 7
    """A session is live: STATE.session_token names its owner (protocol 1.2, rule PN2)."""


class FaultBits(IntFlag):
    """STATE.faults and COUNTERS.latched_faults bits."""

    AMPLITUDE_LIMIT = 1 << 0
    """The plate amplitude command was clamped at the amplitude limit."""
    VOLTAGE_LIMIT = 1 << 1
    """The EV voltage command was clamped at the voltage limit."""
    CURRENT_LIMIT = 1 << 2
    """The EV current limiter was active."""
    WATCHDOG = 1 << 3
    """The host went silent past the watchdog time; outputs ramp to zero."""
    CARD_CLIPPED = 1 << 4
    """The active card asks for more than the device can do (see CLIP_REPORT)."""
    STREAM_OVERRUN = 1 << 5
    """Streamed frames were dropped because the stream queue was full."""
    OVER_TEMPERATURE = 1 << 6
    """Over temperature (not produced by the reference device)."""
    INVALID_REQUEST = 1 << 7
    """A malformed or unknown output report was received and ignored."""
    INPUT_DROPPED = 1 << 8
    """Input reports were dropped because the host did not read them in time."""
    SESSION_BUSY = 1 << 9
    """A START, STOP, COMMIT, COMMIT_PROFILE or DEVICE_PROFILE was refused because another
    host's session is live (protocol 1.2, rules PN3-PN5)."""
    REALTIME_LAG = 1 << 10
    """The device produced the report more than :data:`REALTIME_LATE_S` after its interval was
    due on its real-time clock, or skipped device time in the interval: its reports then cover
    device time that ran slower than wall time (protocol 1.4, rule PI4)."""


class Command(IntEnum):
    """CONTROL.command values."""

    KEEPALIVE = 0
    """Does nothing but feed the watchdog."""
    START = 1
    """Start rendering (the active card, or streamed frames)."""
    STOP = 2
    """Stop: outputs ramp to zero."""
    CLEAR_COUNTERS = 3
    """Zero the counters of COUNTERS and STATE and the latched faults."""
    SET_TOUCH_SOURCE = 4
    """argument 0: internal touch sensor; 1: host (FINGER reports)."""
    PLAY_CARD = 5
    """Leave direct streaming and render the active card again (from its initial state)."""
    DEVICE_PROFILE = 6
    """Render with the device's own profile again (protocol 1.1; capability PROFILE)."""
    TAKE_OVER = 7
    """End any live session and start one for the token in the argument (protocol 1.2, PN6)."""


class TouchSource(IntEnum):
    """CONTROL SET_TOUCH_SOURCE argument."""

    INTERNAL = 0
    HOST = 1


class UploadAction(IntEnum):
    """UPLOAD_END.action values (0 is only ever read back, never accepted in a SET)."""

    NONE = 0
    COMMIT = 1
    ABORT = 2
    COMMIT_PROFILE = 3
    """Commit the staged bytes as the device profile, not a card (protocol 1.1)."""


class UploadState(IntEnum):
    """UPLOAD_STATUS.state."""

    IDLE = 0
    """No upload since power-up."""
    RECEIVING = 1
    """BEGIN accepted; receiving DATA."""
    COMMITTED = 2
    """The last upload was committed: its card is active."""
    FAILED = 3
    """The last upload failed (result says why); the previous card stays active."""


class UploadResult(IntEnum):
    """UPLOAD_STATUS.result: why the last upload failed (OK otherwise)."""

    OK = 0
    CRC_MISMATCH = 1
    """The CRC-32 of the received bytes differs from the one announced in BEGIN."""
    SHORT = 2
    """COMMIT before all announced bytes arrived."""
    OUT_OF_ORDER = 3
    """A DATA chunk's offset is not the number of bytes received so far."""
    TOO_LARGE = 4
    """BEGIN announced more than max_card_bytes, or DATA ran past the announced length."""
    INVALID_CARD = 5
    """The bytes are not a valid card (detail: the first problem's field path)."""
    NOT_STARTED = 6
    """DATA or COMMIT without an upload in progress."""
    ABORTED = 7
    """The host sent ABORT."""
    EMPTY = 8
    """BEGIN announced a length of 0."""
    TIMEOUT = 9
    """No upload traffic for UPLOAD_TIMEOUT_S while receiving."""
    INVALID_PROFILE = 10
    """COMMIT_PROFILE: the bytes are not a device profile this device can render with (detail:
    the field and the reason; protocol 1.1)."""
    BUSY = 11
    """COMMIT or COMMIT_PROFILE while a host's session with a token is live: the active card
    and profile stay (protocol 1.2, rule PN5)."""


class ClipReason(IntEnum):
    """CLIP_REPORT.reason: why one texture target cannot be rendered as written."""

    NONE = 0
    """No item (the card renders as written, or no card)."""
    NO_UV = 1
    """The texture asks for friction below 1 and the device has no UV (or its limit is 0)."""
    NO_EV = 2
    """The texture asks for friction above 1 and the device has no EV (or its limit is 0)."""
    AMPLITUDE = 3
    """The UV target needs more plate amplitude than the amplitude limit in force."""
    VOLTAGE = 4
    """The EV target needs more voltage than the voltage (or current) limit in force allows."""
    OTHER = 255
    """A reason this protocol version has no value for."""


class ClipFlags(IntFlag):
    """CLIP_REPORT.flags: the OR of ``1 << reason`` over every clipped item (bit 0 unused)."""

    NO_UV = 1 << ClipReason.NO_UV
    NO_EV = 1 << ClipReason.NO_EV
    AMPLITUDE = 1 << ClipReason.AMPLITUDE
    VOLTAGE = 1 << ClipReason.VOLTAGE
    OTHER = 1 << 15
