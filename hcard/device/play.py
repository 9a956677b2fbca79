"""Play a card on a device along a finger track, and record what the device reports.

:func:`play` sets the device profile (the host's, uploaded, or the device's own), uploads the
card, takes the finger state from the host (FINGER reports at the track's sample times: on the
wall clock for real and USB/IP devices, on the simulation's clock for ``sim://``), starts
rendering, collects every STATE report, and stops. :func:`hcard.device.recording.recording`
turns the result into a recording in the measurement format (spec/measurement-format.md, device
columns of rule MF12), which ``hcard calibrate`` reads unchanged; :func:`summary` says what
happened, the rendered friction error against the card's target included
(:func:`hcard.calibration.rendering.rendering_error`).
"""

from __future__ import annotations

import hashlib
import json
from datetime import datetime, timezone
from typing import Any

import numpy as np

from hcard.card_io import to_bytes
from hcard.device.base import Driver
from hcard.device.errors import DeviceError, PlayTooLong, SessionLost
from hcard.device.play_result import HOST_TIME_MODULO, PlayResult
from hcard.device.priority import collection_deferred
from hcard.device.protocol import (
    Capability,
    DeviceInfo,
    StateFlags,
)
from hcard.device.published_profiles import published_profile
from hcard.device.state_log import StateLog
from hcard.quantities import S_PER_US, US_PER_S
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb

TAIL_S = 0.05
"""Reports collected after the last track sample before STOP, s."""
MAX_PLAY_S = 4 * 3600.0
"""Longest track one session plays, s: 14.4 million STATE reports, about 1.2 GB for the
recording's packed reports and summary (spec/measurement-format.md, "Recording a session");
checked before anything is sent, so a track with a 100,000 s gap is refused at once."""
STREAM_STALL_S = 0.5
"""Longest time without any STATE report, on the driver's clock, at the end of a session
before :func:`play` declares the input stream stopped and records nothing, s."""


def _profile_record(driver: Driver, info: DeviceInfo, profile: bytes | None) -> dict[str, Any]:
    """Put the profile in force on the device and describe it for the sidecar.

    ``profile``: the bytes of a profile file (spec/device-profile.md) to upload; None: the
    device's own profile (a device that takes profiles is told to go back to it).
    """
    takes_profiles = bool(info.capabilities & Capability.PROFILE)
    if profile is None:
        if takes_profiles:
            driver.use_device_profile()
        published = published_profile(info)
        content = None if published is None else published.to_dict()
        return {"source": "device", "name": content.get("name") if content else None,
                "sha256": None, "content": content}
    if not takes_profiles:
        raise DeviceError(f"{driver.uri}: the device does not take profiles "
                          "(DEVICE_INFO capability PROFILE is not set)")
    driver.upload_profile(profile)
    try:
        content = json.loads(profile.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        content = None
    name = content.get("name") if isinstance(content, dict) else None
    return {"source": "host", "name": name, "sha256": hashlib.sha256(profile).hexdigest(),
            "content": content if isinstance(content, dict) else None}


def play(driver: Driver, card: pb.Card, track: FingerTrack, *, profile: bytes | None = None,
         tail_s: float = TAIL_S, whole_session: bool = False) -> PlayResult:
    """Set the profile, upload ``card``, drive ``track`` as the host's finger, record, stop.

    ``profile``: the bytes of a device profile file to upload first (None: the device's own
    profile). Finger reports go out at the track's sample times (relative to its first sample),
    on the driver's clock. Between samples the driver collects STATE reports; a KEEPALIVE is
    sent when samples are further apart than half the device's watchdog time.

    Sessions (protocol 1.2, spec section 14): before it changes anything, :func:`play` checks
    that no other host's session is live (rule PN8); START begins its own session. A result is
    returned only for a complete session: when the session is lost (PN9) or the input stream
    stops (:data:`STREAM_STALL_S`), it raises, and the caller records nothing. With
    ``whole_session`` (what ``hcard play`` records) a session the device ended after this
    host's silence (PN7) is lost too: from then on another host's reports were carried out, so
    what followed is not this host's play. Measurements that judge such a run themselves (the
    conformance suite: a run not kept in real time, spec QT3) leave it False.

    Raises:
        PlayTooLong: the track lasts longer than :data:`MAX_PLAY_S` (nothing is sent).
        SessionBusy: another host's session is live; nothing was sent that changes the device.
        SessionLost: the session was lost while playing (the error says how and after how
            much of the track); nothing more was sent to the device.
        DeviceError: the device is missing, refuses the card or the profile, vanishes, or its
            input stream stopped.
    """
    check_play_length(track)
    info = driver.info()
    driver.check_free()
    profile_record = _profile_record(driver, info, profile)
    card_bytes = to_bytes(card)
    upload = driver.upload_card(card_bytes)
    driver.clear_counters()
    if info.capabilities & Capability.HOST_FINGER:
        driver.set_touch_source(host=True)
    keepalive_s = max(info.watchdog_ms / 2000.0, 0.005)
    states = StateLog()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    driver.start()
    start = driver.clock()
    # read back once the session is granted: no other host can change them from then on (a
    # served device refuses it, PN13); before it, one could
    limits_at_start = driver.limits()
    # losses of this session only: idle reports the host did not read while it uploaded the
    # card are not the recording's (they fall before its first report)
    lost_before = driver.reports_lost
    host_us = session_host_times(start, track)
    try:
        with collection_deferred():
            last_report = _drive(driver, track, host_us, start, keepalive_s, tail_s, states)
        if whole_session:
            _check_session_kept(driver, states)
    except SessionLost as exc:
        raise SessionLost(f"{exc}; play stopped after {driver.clock() - start:.3f} s of the "
                          f"{float(track.t[-1] - track.t[0]):.3f} s track with "
                          f"{len(states)} reports: nothing is recorded") from None
    duration = driver.clock() - start
    _check_stream(driver, start + duration - last_report, duration)
    limits = driver.limits()  # in force at the end: a device that cannot tell hosts apart
    driver.stop()             # may have had them changed during the recording
    counters = driver.counters()
    return PlayResult(states, duration, upload, info, counters,
                      driver.reports_lost - lost_before,
                      driver.malformed_inputs, track, card_bytes, card.metadata.title, limits,
                      profile_record, str(driver.uri), started, host_us,
                      None if limits == limits_at_start else limits_at_start)


def _check_session_kept(driver: Driver, states: StateLog) -> None:
    """Raise :class:`SessionLost` when a report shows this driver's session ended by the device
    (its ``session_number`` with flag SESSION cleared: PN7, the host was silent for
    ``watchdog_ms``)."""
    number = driver.session_number
    if number is None or not len(states):
        return
    ended = np.flatnonzero((states.field("session_number") == number)
                           & ((states.field("flags") & int(StateFlags.SESSION)) == 0))
    if ended.size:
        at = states[int(ended[0])].timestamp_us * S_PER_US
        raise SessionLost(f"{driver.uri}: session {number} was ended by the device after "
                          f"watchdog_ms of silence from this host at device time {at:.3f} s "
                          "(spec PN7): another host's reports were carried out from then on "
                          "(spec PN9)")


def check_play_length(track: FingerTrack) -> None:
    """Raise :class:`PlayTooLong` when ``track`` lasts longer than :data:`MAX_PLAY_S`."""
    span_s = float(track.t[-1] - track.t[0])
    if span_s > MAX_PLAY_S:
        raise PlayTooLong(f"the track lasts {span_s:.6g} s; one session plays at most "
                          f"{MAX_PLAY_S:.0f} s ({MAX_PLAY_S / 3600:g} h): play it in parts")


def _drive(driver: Driver, track: FingerTrack, host_us: np.ndarray, start: float,
           keepalive_s: float, tail_s: float, states: StateLog) -> float:
    """Send the track's FINGER reports at their times (relative to ``start`` on the driver's
    clock, s) with KEEPALIVEs in long gaps, appending every STATE report to ``states``;
    returns the driver clock when the last report arrived (``start`` if none), s."""
    t_first = float(track.t[0])
    last_sent = last_report = start

    def collect(until: float) -> None:
        nonlocal last_report
        new = driver.collect_until(until)
        if new:
            states.extend(new)
            last_report = driver.clock()

    for k, (t, x, y, fn, contact) in enumerate(
        zip(track.t, track.x, track.y, track.normal_force, track.contact, strict=True)
    ):
        due = start + (float(t) - t_first)
        while due - last_sent > keepalive_s:
            last_sent += keepalive_s
            collect(last_sent)
            driver.keepalive()
        collect(due)
        driver.send_finger(int(host_us[k]) * S_PER_US, float(x), float(y), float(fn), bool(contact))
        last_sent = due
    collect(driver.clock() + tail_s)
    return last_report


def _check_stream(driver: Driver, silent_s: float, duration_s: float) -> None:
    """Raise DeviceError when no STATE report arrived in the last :data:`STREAM_STALL_S` of
    the session (``silent_s``, s): the recording would be truncated, not complete."""
    if silent_s > STREAM_STALL_S:
        raise DeviceError(
            f"{driver.uri}: the input stream stopped {silent_s:.3f} s before the end of the "
            f"{duration_s:.3f} s session (another host may have taken the device): nothing is "
            "recorded")


def session_host_times(start_s: float, track: FingerTrack) -> np.ndarray:
    """The host times (u32 us) of a session's FINGER reports: ``start_s`` (the driver clock at
    START) plus each sample's time since the track's first, so they keep the track's spacing
    (the device times the finger's moves by them, PO2) and differ from every earlier session
    on a monotonic clock; 0 (which a STATE echo uses for "no sample yet") becomes 1 us."""
    seconds = start_s + (track.t - float(track.t[0]))
    host_us = np.rint(seconds * US_PER_S).astype(np.int64) % HOST_TIME_MODULO
    host_us[host_us == 0] = 1
    return host_us
