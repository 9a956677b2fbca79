"""``device.host-driver`` cases of version handling (spec/conformance.md 4.10, rules HD1 and HD2;
protocol PV2, PV3).

``refuses-major``
    DEVICE_INFO says protocol :data:`OTHER_MAJOR`.:data:`OTHER_MAJOR_MINOR`. On a fresh driver
    the host first uploads a card (no DEVICE_INFO asked for by the host: the driver must read it
    itself, before any other request), then plays a stroke
    (:func:`hcard.device.play.play`), starts, sends a FINGER report and lowers a limit.
    **HD1**: the requests sent other than GET DEVICE_INFO, ``n_sent``, must be 0, and every one
    of the five operations must raise an error naming the device's version (``2.3``) and the
    major the driver implements (``1``, ``1.x`` or ``1.4``).
``newer-minor``
    DEVICE_INFO says protocol 1.:data:`NEWER_MINOR` and every STATE report carries
    :data:`APPENDED_BYTES` bytes more (fields a later minor appends, PV4, which a host ignores,
    PT7). The host reads DEVICE_INFO and plays a stroke. **HD2**: ``n_refused``, the operations
    that raised plus the STATE reports the driver did not decode, must be 0, and the play
    must return at least :data:`MIN_REPORTS` reports.
"""

from __future__ import annotations

from hcard.device.play import play
from hcard.device.protocol import PROTOCOL_MAJOR, DeviceInfo, ReportId
from hcard_conformance.check_names import DEVICE_HOST_DRIVER as CHECK
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.device_checks.host_link import DriverTemplate, ScriptedDevice
from hcard_conformance.device_checks.host_outcomes import (
    MIN_REPORTS,
    PLAY_S,
    Outcome,
    attempt,
    names_major,
    names_number,
    stroke_card,
    stroke_track,
)
from hcard_conformance.result import CheckResult

OTHER_MAJOR = PROTOCOL_MAJOR + 1
"""The major version DEVICE_INFO says in ``refuses-major`` (one no driver of this standard
implements)."""
OTHER_MAJOR_MINOR = 3
"""Its minor version (3, so that the error names ``2.3``, a pair no other number of the
message makes)."""
NEWER_MINOR = 99
"""The minor version DEVICE_INFO says in ``newer-minor`` (far beyond any published minor)."""
APPENDED_BYTES = 4
"""Bytes appended to every STATE report in ``newer-minor`` (a u32 field of a later minor)."""
APPENDED_VALUE = 0xA5
"""Value of each appended byte (not 0: a later minor's field holds data)."""
LIMIT_M = 1e-6
"""Amplitude limit ``refuses-major`` asks for, m peak-to-peak."""


def refuses_major(template: DriverTemplate) -> CheckResult:
    """Case ``refuses-major`` (module docstring)."""
    device = ScriptedDevice.open()
    info = device.info()
    device.version = (OTHER_MAJOR, OTHER_MAJOR_MINOR)
    driver = template.connect(device)
    try:
        card, track = stroke_card(info), stroke_track(info)
        x, y = float(track.x[0]), float(track.y[0])
        outcomes = [
            attempt("upload_card()", lambda: driver.upload_card(card)),
            attempt("play", lambda: play(driver, card, track)),
            attempt("start()", driver.start),
            attempt("send_finger()", lambda: driver.send_finger(0.0, x, y, 0.5, True)),
            attempt("set_limits()", lambda: driver.set_limits(max_amplitude_m=LIMIT_M)),
        ]
    finally:
        driver.close()
    sent = [r for r in device.requests
            if not (r.kind == "get" and r.data[:1] == bytes([ReportId.DEVICE_INFO]))]
    version = f"{OTHER_MAJOR}.{OTHER_MAJOR_MINOR}"

    def refused(outcome: Outcome) -> bool:
        message = outcome.message(driver.uri)
        return outcome.error is not None and names_number(message, version) \
            and names_major(message.replace(version, ""), PROTOCOL_MAJOR)

    problems = [o.text() for o in outcomes if not refused(o)]
    if sent:
        problems.insert(0, f"{len(sent)} requests sent to a device of protocol {version}: "
                        + ", ".join(r.text() for r in sent[:5]))
    detail = "; ".join(problems) if problems else (
        f"each of {len(outcomes)} operations refused the device of protocol {version} naming "
        f"both versions ({outcomes[0].text()}); nothing but GET DEVICE_INFO sent")
    return CheckResult(CHECK, LEVEL, "refuses-major", not problems, "n_sent", float(len(sent)),
                       0.0, "requests", detail)


def newer_minor(template: DriverTemplate) -> CheckResult:
    """Case ``newer-minor`` (module docstring)."""
    device = ScriptedDevice.open()
    info = device.info()
    device.version = (PROTOCOL_MAJOR, NEWER_MINOR)
    device.appended = bytes([APPENDED_VALUE]) * APPENDED_BYTES
    driver = template.connect(device)
    try:
        read = attempt("info()", driver.info)
        played = attempt("play", lambda: play(driver, stroke_card(info), stroke_track(info)))
    finally:
        driver.close()
    outcomes = [read, played]
    undecoded = driver.malformed_inputs
    refused = sum(o.error is not None for o in outcomes) + undecoded
    problems = [o.text() for o in outcomes if o.error is not None]
    if isinstance(read.value, DeviceInfo) and read.value.protocol_minor != NEWER_MINOR:
        problems.append(f"info() said minor {read.value.protocol_minor}, the device {NEWER_MINOR}")
    if undecoded:
        problems.append(f"{undecoded} STATE reports of {APPENDED_BYTES} appended bytes not "
                        f"decoded ({driver.input_error})")
    states = getattr(played.value, "states", None)
    count = len(states) if states is not None else 0
    if played.error is None and count < MIN_REPORTS:
        problems.append(f"the play returned {count} STATE reports, fewer than {MIN_REPORTS}")
    detail = "; ".join(problems) if problems else (
        f"protocol 1.{NEWER_MINOR} accepted: info() and a {PLAY_S:g} s play returned, "
        f"{count} STATE reports of {APPENDED_BYTES} appended bytes decoded")
    return CheckResult(CHECK, LEVEL, "newer-minor", not problems, "n_refused", float(refused),
                       0.0, "operations and reports", detail)
