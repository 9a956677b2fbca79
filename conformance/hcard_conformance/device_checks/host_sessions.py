"""``device.host-driver`` cases of another host's session (spec/conformance.md 4.10, rule HD4;
protocol PN8, with PN6 and PN7).

Before the driver under test connects, another host begins and ends
:data:`EARLIER_SESSIONS` sessions on the scripted device with token :data:`OTHER_TOKEN` and
begins one more (``session_number`` :data:`EARLIER_SESSIONS` + 1: numbers no other part of a
message makes):

``busy-device``
    The other host feeds its session (a KEEPALIVE every 20 ms). The host plays a stroke
    (:func:`hcard.device.play.play`: DEVICE_INFO, look, upload, START), then calls
    ``start()``. **HD4**: ``n_sent``, the requests that change the device plus every request
    (a GET included) sent after the driver read the first report showing the session and
    before it gave its verdict, must be 0; for each operation that silence must last at least
    ``watchdog_ms`` of device time, and the operation must raise an error naming the session's
    ``session_number`` and ``session_token``.
``abandoned-session``
    The other host sends nothing more (it crashed): the device ends the session after
    ``watchdog_ms`` (PN7). The host plays a stroke. **HD4**: ``n_sent``, the requests that
    change the device sent before the driver read a report showing the session ended, must
    be 0, and the play must return at least :data:`MIN_REPORTS` reports.
``takes-over``
    The other host feeds its session. The host reads DEVICE_INFO, takes the device over
    (``take_over()``, PN6: what a host does "when asked to"), stops its session and plays a
    stroke (PN5: the owner too uploads a card outside a session). **HD4**: the sessions the
    driver was granted (a report showing a live session other than the other
    host's after ``take_over()``, and the play returning at least :data:`MIN_REPORTS`
    reports) are counted: ``n_denied``, 1 when none was, must be 0.
"""

from __future__ import annotations

from hcard.device.base import Driver
from hcard.device.play import play
from hcard.device.protocol import DeviceInfo, ReportId, State
from hcard.quantities import MS_PER_S, S_PER_MS
from hcard_conformance.check_names import DEVICE_HOST_DRIVER as CHECK
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.device_checks.host_link import (
    DriverTemplate,
    OtherHost,
    Request,
    ScriptedDevice,
)
from hcard_conformance.device_checks.host_outcomes import (
    MIN_REPORTS,
    Outcome,
    attempt,
    names_number,
    stroke_card,
    stroke_track,
)
from hcard_conformance.result import CheckResult

OTHER_TOKEN = 201
"""The other host's session token."""
EARLIER_SESSIONS = 6
"""Sessions the other host begins and ends before the one it keeps (so that it is session 7)."""


def _beside_other_host(template: DriverTemplate, *, fed: bool,
                       ) -> tuple[ScriptedDevice, DeviceInfo, OtherHost, Driver]:
    """A scripted device on which another host holds session 7 (token :data:`OTHER_TOKEN`),
    fed or gone silent, its DEVICE_INFO, that host, and the implementation's driver on it."""
    device = ScriptedDevice.open()
    info = device.info()
    device.begin_other_session(OTHER_TOKEN, EARLIER_SESSIONS, fed=fed)
    other = device.other
    assert other is not None
    return device, info, other, template.connect(device)


def _states(device: ScriptedDevice, first: int) -> list[tuple[float, State]]:
    """The STATE reports handed to the driver from index ``first`` on, with their times."""
    found = []
    for t_s, data in device.delivered[first:]:
        if data[:1] == bytes([ReportId.STATE]):
            try:
                found.append((t_s, State.decode(data)))
            except Exception:  # an altered report is the case's, not a session's
                continue
    return found


def _shows(state: State, other: OtherHost) -> bool:
    """``state`` shows the other host's session live."""
    return state.session_live and state.session_number == other.number


def _busy(device: ScriptedDevice, other: OtherHost, outcome: Outcome, first_request: int,
          first_report: int, done_s: float, watchdog_s: float,
          uri: object) -> tuple[list[Request], list[str]]:
    """What one operation of ``busy-device`` sent that it must not have, and its problems."""
    requests = device.requests[first_request:]
    seen = next((t for t, s in _states(device, first_report) if _shows(s, other)), None)
    forbidden = [r for r in requests if r.changes_device or (seen is not None and r.t_s >= seen)]
    problems = []
    if seen is None:
        problems.append(f"{outcome.what}: read no STATE report before "
                        + ("changing the device" if requests else "its verdict"))
    else:
        silent_until = next((r.t_s for r in requests if r.t_s >= seen), done_s)
        silent_s = silent_until - seen
        if silent_s < watchdog_s:
            problems.append(f"{outcome.what}: silent {silent_s * MS_PER_S:.0f} ms after it saw "
                            f"session {other.number}, less than watchdog_ms "
                            f"{watchdog_s * MS_PER_S:.0f}")
    message = outcome.message(uri)
    if not (outcome.error is not None and names_number(message, other.number)
            and names_number(message, other.token)):
        problems.append(f"no error naming session {other.number} and token {other.token}: "
                        f"{outcome.text()}")
    return forbidden, problems


def busy_device(template: DriverTemplate) -> CheckResult:
    """Case ``busy-device`` (module docstring)."""
    device, info, other, driver = _beside_other_host(template, fed=True)
    sent: list[Request] = []
    problems: list[str] = []
    outcomes = []
    try:
        for what, operation in (("play", lambda: play(driver, stroke_card(info),
                                                       stroke_track(info))),
                                ("start()", driver.start)):
            first_request, first_report = len(device.requests), len(device.delivered)
            outcome = attempt(what, operation)
            outcomes.append(outcome)
            forbidden, wrong = _busy(device, other, outcome, first_request, first_report,
                                     device.clock(), info.watchdog_ms * S_PER_MS, driver.uri)
            sent += forbidden
            problems += wrong
    finally:
        driver.close()
    if sent:
        problems.insert(0, f"{len(sent)} requests sent while session {other.number} of "
                        f"another host was live: " + ", ".join(r.text() for r in sent[:5]))
    detail = "; ".join(problems) if problems else (
        f"each operation silent for watchdog_ms or more, then: {outcomes[0].text()}")
    return CheckResult(CHECK, LEVEL, "busy-device", not problems, "n_sent", float(len(sent)),
                       0.0, "requests", detail)


def abandoned_session(template: DriverTemplate) -> CheckResult:
    """Case ``abandoned-session`` (module docstring)."""
    device, info, other, driver = _beside_other_host(template, fed=False)
    try:
        played = attempt("play", lambda: play(driver, stroke_card(info), stroke_track(info)))
    finally:
        driver.close()
    ended = next((t for t, s in _states(device, 0) if not _shows(s, other)), None)
    early = [r for r in device.requests if r.changes_device and (ended is None or r.t_s < ended)]
    problems = []
    if early:
        problems.append(f"{len(early)} requests changing the device sent while session "
                        f"{other.number} of a silent host was live: "
                        + ", ".join(r.text() for r in early[:5]))
    states = getattr(played.value, "states", None)
    count = len(states) if states is not None else 0
    if count < MIN_REPORTS:
        problems.append(f"the play did not go on once the session ended ({played.text()}; "
                        f"{count} STATE reports)")
    if ended is None and not problems:
        problems.append(f"the driver read no report showing session {other.number} ended")
    detail = "; ".join(problems) if problems or ended is None else (
        f"waited until session {other.number} ended at {ended * MS_PER_S:.0f} ms "
        f"(watchdog_ms {info.watchdog_ms}), then played: {count} STATE reports")
    return CheckResult(CHECK, LEVEL, "abandoned-session", not problems, "n_sent",
                       float(len(early)), 0.0, "requests", detail)


def takes_over(template: DriverTemplate) -> CheckResult:
    """Case ``takes-over`` (module docstring)."""
    device, info, other, driver = _beside_other_host(template, fed=True)
    try:
        outcomes = [attempt("info()", driver.info)]
        first_report = len(device.delivered)
        outcomes.append(attempt("take_over()", driver.take_over))
        outcomes.append(attempt("stop()", driver.stop))  # PN5: a card is uploaded outside it
        outcomes.append(attempt("play", lambda: play(driver, stroke_card(info),
                                                     stroke_track(info))))
    finally:
        driver.close()
    own = [s for _, s in _states(device, first_report) if s.session_live
           and s.session_number != other.number and s.session_token != other.token]
    states = getattr(outcomes[-1].value, "states", None)
    count = len(states) if states is not None else 0
    problems = [o.text() for o in outcomes if o.error is not None]
    if not own:
        problems.append(f"no report showed a session of the driver's after take_over() "
                        f"(session {other.number}, token {other.token} was live)")
    if not problems and count < MIN_REPORTS:
        problems.append(f"the play returned {count} STATE reports, fewer than {MIN_REPORTS}")
    denied = 1.0 if problems else 0.0
    detail = "; ".join(problems) if problems else (
        f"session {own[0].session_number} granted over session {other.number}; "
        f"played {count} STATE reports in it")
    return CheckResult(CHECK, LEVEL, "takes-over", not problems, "n_denied", denied, 0.0,
                       "sessions", detail)
