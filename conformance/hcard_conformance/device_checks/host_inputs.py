"""``device.host-driver`` cases of undecodable reports (spec/conformance.md 4.10, rule HD3;
protocol PE4).

The driver reads DEVICE_INFO and :data:`PRIME_S` of STATE reports from the scripted device;
then the device sends one report the driver cannot decode, made from the last good one:

``short-state``
    the STATE report cut to :data:`SHORT_STATE_BYTES` bytes (shorter than the 52 bytes of a
    protocol 1.0 STATE, the shortest any version sends);
``unknown-input``
    the STATE report with the input report ID :data:`UNKNOWN_INPUT_ID`, defined by no version;
``out-of-range-state``
    the STATE report with ``target_uv_x1e4`` :data:`OUT_OF_RANGE_UV` (its range is
    0..10 000);
``short-feature``
    (a feature report) the next GET LIMITS answered with :data:`SHORT_FEATURE_BYTES` of its 7
    bytes; the host asks for LIMITS twice.

The host goes on reading (``read_inputs()``, or the second ``limits()``) for at most
:data:`READ_S`. **HD3**: ``n_miss``, the requirements of PE4 missed, of three, must be 0: the
driver does not crash (it raises nothing but the host library's error,
:class:`~hcard.errors.HcardError`); it reports the report as an error naming the report and
the reason, raised or, when it skips the report, in ``Driver.input_error`` with the report
counted in ``malformed_inputs`` (the report: its name or ID; the reason: the size received,
the unknown ID, the field or its value); and it goes on: a good report the device sent after
the bad one is decoded (a second GET LIMITS answered).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

from hcard.device.base import Driver
from hcard.device.protocol import Limits, ReportId, State
from hcard_conformance.check_names import DEVICE_HOST_DRIVER as CHECK
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.device_checks.host_link import DriverTemplate, ScriptedDevice
from hcard_conformance.device_checks.host_outcomes import Outcome, attempt, names_any
from hcard_conformance.result import CheckResult

PRIME_S = 0.005
"""STATE reports the driver reads before the bad one, s of device time."""
READ_S = 0.02
"""Longest the host reads on after the bad report for a good one, s (20 reports)."""
POLL_S = 0.002
"""Wait of each ``read_inputs()`` call while the host reads on, s."""
SHORT_STATE_BYTES = 30
"""Bytes of the cut STATE report of ``short-state``."""
UNKNOWN_INPUT_ID = 0x7E
"""An input report ID no protocol version defines (STATE is 0x01, the only input report)."""
OUT_OF_RANGE_UV = 12_345
"""``target_uv_x1e4`` of ``out-of-range-state`` (range 0..10 000)."""
TARGET_UV_OFFSET = 32
"""Offset of ``target_uv_x1e4`` in STATE, bytes (spec/device-protocol.md section 6)."""
SHORT_FEATURE_BYTES = 5
"""Bytes of the cut LIMITS answer of ``short-feature``."""
REQUIREMENTS = 3
"""PE4's requirements judged per case: no crash, an error naming report and reason, going on."""
STATE_NAMES = ("STATE", "0x01")
"""How an error names the STATE report: its name or its ID."""


@dataclass(frozen=True)
class BadReport:
    """One case: how the bad report is made from a good STATE report, and what an error
    about it must name (each group: one of its words)."""

    make: Callable[[bytes], bytes]
    names: tuple[tuple[str, ...], ...]


def _out_of_range(good: bytes) -> bytes:
    bad = bytearray(good)
    struct.pack_into("<H", bad, TARGET_UV_OFFSET, OUT_OF_RANGE_UV)
    return bytes(bad)


BAD_INPUTS: dict[str, BadReport] = {
    "short-state": BadReport(lambda good: good[:SHORT_STATE_BYTES],
                             (STATE_NAMES, (str(SHORT_STATE_BYTES),))),
    "unknown-input": BadReport(lambda good: bytes([UNKNOWN_INPUT_ID]) + good[1:],
                               ((f"0x{UNKNOWN_INPUT_ID:02X}", str(UNKNOWN_INPUT_ID)),)),
    "out-of-range-state": BadReport(_out_of_range,
                                    (STATE_NAMES, ("target_uv", str(OUT_OF_RANGE_UV)))),
}
"""The input report cases by name."""
FEATURE_NAMES = (("LIMITS", f"0x{ReportId.LIMITS:02X}"), (str(SHORT_FEATURE_BYTES),))
"""What an error about the cut LIMITS answer must name."""


def _names(message: str, groups: tuple[tuple[str, ...], ...]) -> bool:
    return bool(message) and all(names_any(message, group) for group in groups)


def _after(state: State, sequence: int) -> bool:
    """``state`` was produced after the report numbered ``sequence`` (PT5, wrapping)."""
    return 0 < (state.sequence - sequence) % (1 << 16) < (1 << 15)


def _verdict(case: str, crashes: list[Outcome], reported: str, went_on: bool,
             what_next: str, seen: str) -> CheckResult:
    """The case's result from what the driver did (module docstring, HD3); ``seen``: what it
    did instead when it reported nothing."""
    problems = [f"crashed: {o.text()}" for o in crashes]
    if not reported:
        problems.append("no error naming the report and the reason (raised, or in "
                        f"input_error with the report counted in malformed_inputs): {seen}")
    if not went_on:
        problems.append(f"no {what_next} after it")
    missed = len(crashes[:1]) + (not reported) + (not went_on)
    detail = "; ".join(problems) if problems else f"reported: {reported}; {what_next} after it"
    return CheckResult(CHECK, LEVEL, case, not problems, "n_miss", float(missed), 0.0,
                       f"of {REQUIREMENTS} requirements", detail)


def undecodable_input(template: DriverTemplate, case: str) -> CheckResult:
    """Cases ``short-state``, ``unknown-input``, ``out-of-range-state`` (module docstring)."""
    bad = BAD_INPUTS[case]
    device = ScriptedDevice.open()
    driver = template.connect(device)
    try:
        driver.info()
        if not driver.read_inputs(PRIME_S) or not device.delivered:
            raise RuntimeError(f"the driver decoded no STATE report in {PRIME_S * 1000:.0f} ms "
                               "of a conforming device")
        good = device.delivered[-1][1]
        device.inject(bad.make(good))
        skipped_before = driver.malformed_inputs
        outcomes: list[Outcome] = []
        later: list[State] = []
        deadline = driver.clock() + READ_S
        while driver.clock() < deadline and not later:
            outcome = attempt("read_inputs()", lambda: driver.read_inputs(POLL_S))
            outcomes.append(outcome)
            later += [s for s in outcome.value or () if _after(s, State.decode(good).sequence)]
    finally:
        driver.close()
    return _judge_inputs(case, driver, outcomes, bad, skipped_before, bool(later))


def _judge_inputs(case: str, driver: Driver, outcomes: list[Outcome], bad: BadReport,
                  skipped_before: int, went_on: bool) -> CheckResult:
    raised = [o for o in outcomes if o.error is not None]
    reported = next((o.text() for o in raised
                     if not o.crashed and _names(o.message(driver.uri), bad.names)), "")
    skip_text = " ".join(str(getattr(driver, "input_error", "")).replace(str(driver.uri), "")
                         .split())
    skipped = driver.malformed_inputs - skipped_before
    if not reported and skipped and _names(skip_text, bad.names):
        reported = f"skipped, input_error {skip_text!r}"
    seen = "; ".join([o.text() for o in raised]
                     + [f"{skipped} reports skipped, input_error {skip_text!r}"])
    return _verdict(case, [o for o in raised if o.crashed], reported, went_on,
                    "good STATE report decoded", seen)


def short_feature(template: DriverTemplate) -> CheckResult:
    """Case ``short-feature`` (module docstring)."""
    device = ScriptedDevice.open()
    driver = template.connect(device)
    try:
        driver.info()
        device.answer_short(ReportId.LIMITS, SHORT_FEATURE_BYTES)
        first = attempt("limits()", driver.limits)
        second = attempt("limits()", driver.limits)
    finally:
        driver.close()
    named = first.error is not None and not first.crashed \
        and _names(first.message(driver.uri), FEATURE_NAMES)
    crashes = [o for o in (first, second) if o.crashed]
    went_on = isinstance(second.value, Limits)
    return _verdict("short-feature", crashes, first.text() if named else "", went_on,
                    "LIMITS answered as usual and decoded", first.text())
