"""Check ``device.refusals`` (spec/conformance.md 4.9, rule X1; protocol PT7, PO4, PO5,
PE1-PE3): what a device does with reports it must not carry out.

While the host's finger circles on the surface in a session of its own
(:class:`~.link_session.LinkSession`), the host sends, one case each, bytes a careless or
hostile host might send:

``padded-report``
    a CONTROL KEEPALIVE padded with zeros to 64 bytes: accepted (PT7: a receiver ignores the
    extra bytes), so neither counted nor flagged;
``short-report``
    the same report one byte short: malformed (PT7), so ignored, counted in
    ``rejected_requests`` and flagged INVALID_REQUEST in a STATE report (PE2);
``unknown-output``
    an output report of an ID the protocol does not define: ignored, counted and flagged (PE2);
``unknown-command``
    CONTROL with a command the protocol does not define: malformed (PO5), counted and flagged;
``bad-stream``
    a STREAM report of 0 frames: malformed (PO4), counted and flagged;
``unknown-feature``
    GET_REPORT(Feature) of an ID the protocol does not define: a STALL (PE1), counted, and the
    next request (GET DEVICE_INFO) answered as usual;
``flood``
    :data:`FLOOD_REPORTS` short reports sent as fast as the host can (PS2: a flood of malformed
    reports stops neither the input stream nor the device's answers): every one counted.

Right after the bytes the host sends a FINGER report (on a device with HOST_FINGER). A device
handles a host's reports in order, so a STATE report that echoes that FINGER
(``host_time_echo_us``) was made after the request was handled: the host reads for
:data:`AFTER_S`, and then on until such a report arrives, at most the timing class's latency
and read lag longer (a guest under software emulation reads reports up to seconds late). The
count is judged on the last report read.

In every case the device keeps producing STATE reports and keeps RUNNING the session (PE3):
its report sequence advances by at least :data:`MIN_REPORTS` from the last report before the
request to the last one read (counted by sequence number, PT5, so reports the host failed to
read count as produced), the last with RUNNING. The metric is the difference between the
rejections counted and those required.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

from hcard.device.base import Driver
from hcard.device.errors import DeviceStall
from hcard.device.protocol import (
    Command,
    Control,
    DeviceInfo,
    FaultBits,
    ReportId,
    State,
    StateFlags,
    Stream,
)
from hcard.device.protocol.constants import STREAM_FRAMES_PER_REPORT
from hcard_conformance.check_names import DEVICE_REFUSALS as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, on_one_driver
from hcard_conformance.device_checks.link_session import HOST_PAUSE_MAX_S, LinkSession
from hcard_conformance.realtime import NotKept, attempted_case, device_lag, reasons
from hcard_conformance.result import CannotAssess, CheckResult
from hcard_conformance.timing import REAL_TIME, timing_class

REFUSAL_CASES = ("padded-report", "short-report", "unknown-output", "unknown-command",
                 "bad-stream", "unknown-feature", "flood")
"""The cases of ``device.refusals``, in order."""
BEFORE_S = 0.02
"""Reports read before each case, s (the last one gives the count of rejections so far)."""
AFTER_S = 0.05
"""Reports read after each case at least, s: the rejection counted and flagged, the device
running."""
MIN_REPORTS = 10
"""Fewest STATE reports the device must produce after the request (PE3: it keeps running): a
tenth of what a 1 kHz device sends in :data:`AFTER_S`."""
REPORT_BYTES = 64
"""Longest report of the protocol, bytes (PT3): what a padding host stack sends."""
UNKNOWN_OUTPUT_ID = 0x1F
"""An output report ID no protocol version defines (outputs are 0x10-0x12)."""
UNKNOWN_FEATURE_ID = 0x2F
"""A feature report ID no protocol version defines (features are 0x20-0x27)."""
UNKNOWN_COMMAND = 0xFE
"""A CONTROL command no protocol version defines."""
STREAM_LAYOUT = Stream.STRUCT
"""STREAM on the wire: ID, ``stream_seq``, ``count``, then the frames (PO3)."""
FLOOD_REPORTS = 200
"""Malformed reports of the ``flood`` case: 0.2 s of them at the 1 kHz a full-speed interrupt
pipe carries, sent back to back."""
COUNTER_MODULO = 1 << 16
"""STATE ``rejected_requests`` wraps at 2**16."""


@dataclass(frozen=True)
class Refusal:
    """One case: what the host sends and how many rejections it must cause."""

    send: Callable[[Driver], str]
    """Sends the bytes and says what happened on the host's side ("" when nothing to say)."""
    rejections: int


def _empty_stream() -> bytes:
    """A STREAM report of the protocol's size whose ``count`` is 0 (PO4: malformed)."""
    return STREAM_LAYOUT.pack(ReportId.STREAM, 1, 0, *([0] * (2 * STREAM_FRAMES_PER_REPORT)))


def _keepalive() -> bytes:
    return Control(int(Command.KEEPALIVE)).encode()


def _send(data: bytes, times: int = 1) -> Callable[[Driver], str]:
    def send(driver: Driver) -> str:
        for _ in range(times):
            driver.send_raw(data)
        return ""

    return send


def _unknown_feature(driver: Driver) -> str:
    try:
        driver.get_raw_feature(UNKNOWN_FEATURE_ID, REPORT_BYTES)
    except DeviceStall:
        stalled = True
    else:
        stalled = False
    try:
        answered: DeviceInfo | None = driver.info()
    except DeviceStall:
        answered = None
    return ("" if stalled else "the unknown feature was answered, not STALLed (PE1); ") + \
        ("" if answered is not None else "DEVICE_INFO after it was STALLed (PE1); ")


def refusals() -> dict[str, Refusal]:
    """The cases of the check by name (module docstring)."""
    keepalive = _keepalive()
    return {
        "padded-report": Refusal(_send(keepalive.ljust(REPORT_BYTES, b"\0")), 0),
        "short-report": Refusal(_send(keepalive[:-1]), 1),
        "unknown-output": Refusal(_send(bytes([UNKNOWN_OUTPUT_ID, 0, 0])), 1),
        "unknown-command": Refusal(_send(bytes([ReportId.CONTROL, UNKNOWN_COMMAND, 0])), 1),
        "bad-stream": Refusal(_send(_empty_stream()), 1),
        "unknown-feature": Refusal(_unknown_feature, 1),
        "flood": Refusal(_send(keepalive[:-1], FLOOD_REPORTS), FLOOD_REPORTS),
    }


def all_read(before: State, after: list[State]) -> bool:
    """Whether the host read every STATE report from ``before`` to the last of ``after`` (the
    sequence numbers step by one, PT5): the flag of PE2 rides on one report only."""
    expected = before.sequence
    for state in after:
        expected = (expected + 1) % COUNTER_MODULO
        if state.sequence != expected:
            return False
    return True


def judge(case: str, refusal: Refusal, before: State, after: list[State],
          host_note: str) -> CheckResult:
    """The case's verdict from the last report before it and the reports after it (read until
    one covers the request, module docstring)."""
    counted = (after[-1].rejected_requests - before.rejected_requests) % COUNTER_MODULO \
        if after else 0
    flagged = any(s.faults & FaultBits.INVALID_REQUEST for s in after)
    running = bool(after) and bool(after[-1].flags & StateFlags.RUNNING)
    problems = [host_note.rstrip("; ")] if host_note else []
    notes = []
    if counted != refusal.rejections:
        problems.append(f"{counted} rejections counted, {refusal.rejections} required")
    gapless = all_read(before, after)
    if refusal.rejections and case != "unknown-feature" and not flagged:
        if gapless:
            problems.append("no STATE report flagged INVALID_REQUEST (PE2)")
        else:  # the one report that carries the flag may be among those the host lost
            notes.append("INVALID_REQUEST not judged: the host lost reports after the request")
    if not refusal.rejections and flagged:
        problems.append("a STATE report flagged INVALID_REQUEST for an accepted report")
    produced = (after[-1].sequence - before.sequence) % COUNTER_MODULO if after else 0
    if produced < MIN_REPORTS or not running:
        problems.append(f"{produced} STATE reports produced after it ({len(after)} read), "
                        f"{'RUNNING' if running else 'not RUNNING'} (PE3)")
    detail = "; ".join(problems + notes) if problems else "; ".join([
        f"{counted} rejection(s) counted as required"
        + (", INVALID_REQUEST flagged" if flagged else "")
        + f"; {produced} reports produced after it ({len(after)} read), RUNNING", *notes])
    return CheckResult(CHECK, LEVEL, case, not problems, "rejections_off",
                       float(abs(counted - refusal.rejections)), 0.0, "requests", detail)


def measure_refusals(driver: Driver, wants: Callable[[str], bool] | None = None,
                     lag_s: float = REAL_TIME.report_wait_s,
                     ) -> Iterator[CheckResult]:
    """The cases of ``device.refusals`` on one open driver (module docstring); with ``wants``,
    only the cases it is true of. ``lag_s``: how much longer than :data:`AFTER_S` the host
    reads for a report that covers the request, s."""
    session = LinkSession(driver)
    session.begin()
    try:
        for case, refusal in refusals().items():
            if wants is not None and not wants(case):
                continue

            def attempt(case: str = case, refusal: Refusal = refusal) -> CheckResult:
                before = session.run(BEFORE_S)
                if not before:  # a host whose reads stall (software emulation) reads on
                    before = session.run(lag_s)
                if not before:
                    raise CannotAssess(
                        f"no STATE report in {(BEFORE_S + lag_s) * 1000:.0f} ms")
                session.mark()
                note = refusal.send(driver)
                session.finger.mark()
                session.finger.send()
                after = session.run_until_echoed(AFTER_S, lag_s)
                result = judge(case, refusal, before[-1], after, note)
                if result.passed:
                    return result
                host = (f"the host paused {session.longest_pause_s * 1000:.0f} ms"
                        if session.longest_pause_s > HOST_PAUSE_MAX_S else "")
                why = reasons(host, device_lag(after))
                if why:  # too few reports because the host or the device fell behind
                    raise NotKept(f"{why}; the case failed so: {result.detail}")
                return result

            yield attempted_case(CHECK, LEVEL, case, attempt)
    finally:
        session.restore()


def check_refusals(ctx: Context) -> Iterator[CheckResult]:
    """Malformed, unknown and refused reports are ignored, counted and flagged, and the device
    keeps running (PT7, PO4, PO5, PE1-PE3)."""
    lag_s = timing_class(ctx).report_wait_s
    yield from on_one_driver(ctx, CHECK, REFUSAL_CASES,
                             lambda driver, wants: measure_refusals(driver, wants, lag_s))
