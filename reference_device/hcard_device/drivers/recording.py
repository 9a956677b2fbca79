"""A play session as a recording in the measurement format (spec/measurement-format.md).

One row per STATE report (spec/device-protocol.md section 6), the columns of rule M3 in SI
units (``t_s`` device time from the first report, ``x_m``, ``y_m``, ``speed_m_s``, ``fn_n``,
``fl_n``, ``amplitude_m``, ``voltage_v``, ``contact``) and the device columns of rule M12
(``sequence``, corner forces, ``current_a``, ``target_uv``, ``target_ev``, ``texture``,
``faults``, ``flags``, ``echo_s``), with the sidecar keys of rule M9 for what the device and the
host know: device class, protocol, plate and carrier frequencies, limits in force, the card
(SHA-256, generation), the profile rendering it and the session's report counts.

The finger's speed is not in a STATE report; it is the speed the host drove: each report echoes
the host time of the last FINGER report the device applied (``echo``), which names the track
sample in force, and the speed is that of the last two track samples, as the device's own finger
state derives it (``hcard_device.sim.finger.HostFinger``), signed by the direction along x. The
``stroke`` column is the echoed sample's stroke of the track (:func:`track_strokes`).
"""

from __future__ import annotations

import hashlib
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from hcard.calibration.measurement import Measurement
from hcard.calibration.splits import stroke_numbers
from hcard.track import FingerTrack
from hcard_device.protocol import Capability, DeviceInfo, DeviceKind, State

if TYPE_CHECKING:
    from hcard_device.drivers.play import PlayResult

MM = 1e-3
"""Metres per millimetre."""
HOST_TIME_MODULO = 1 << 32
"""FINGER.host_time_us wraps at 2**32 us."""


def unwrapped_times(states: list[State]) -> np.ndarray:
    """Device time stamps of ``states`` unwrapped (u32 microseconds), from the first, s."""
    if not states:
        return np.zeros(0)
    stamps = np.array([s.timestamp_us for s in states], dtype=np.int64)
    steps = np.diff(stamps) % (1 << 32)
    return np.concatenate(([0], np.cumsum(steps))) * 1e-6


def track_speeds(track: FingerTrack) -> np.ndarray:
    """Speed of each track sample over the interval that ends at it, m/s, signed by the
    direction along x (along y for a purely vertical move); 0 unless both samples touch."""
    speed = np.zeros(len(track))
    if len(track) < 2:
        return speed
    dx, dy, dt = np.diff(track.x), np.diff(track.y), np.diff(track.t)
    moving = track.contact[1:] & track.contact[:-1] & (dt > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        magnitude = np.where(moving, np.hypot(dx, dy) / dt * MM, 0.0)
    sign = np.where(dx != 0, np.sign(dx), np.where(dy < 0, -1.0, 1.0))
    speed[1:] = magnitude * sign
    return speed


def track_strokes(track: FingerTrack) -> np.ndarray:
    """The stroke of each track sample by rule S2 (spec/measurement-format.md section 4: a lift
    or a reversal of the direction starts one), -1 out of contact. The recording takes a report's
    stroke from the sample it echoes, so reports lost on the way (a gap in the device's time
    stamps, which S2 would read as a new stroke) cannot cut a stroke in two: on the reference
    served over usbip, host stalls that lost 1236 of 30000 reports turned the 26 strokes of the
    calibration protocol into 46 and changed which strokes the split held out."""
    return stroke_numbers(track.t, np.asarray(track.contact, dtype=bool), track_speeds(track))


def echoed_samples(host_us: np.ndarray, echoes_us: np.ndarray) -> np.ndarray:
    """Index of the sample each echoed host time (us, wrapping) names, given the host time
    sent with each sample of the session (``host_us``, :attr:`PlayResult.host_us`); -1 for an
    echo of no sample of this session. A device echoes the last FINGER report it applied,
    which at the start of a session is still one of the previous session: the host times of
    a session start at its own START on a monotonic clock, so such an echo names none."""
    host_us = np.asarray(host_us, dtype=np.int64) % HOST_TIME_MODULO
    echoes_us = np.asarray(echoes_us, dtype=np.int64)
    order = np.argsort(host_us, kind="stable")
    sorted_us = host_us[order]
    position = np.searchsorted(sorted_us, echoes_us, side="right") - 1
    found = (position >= 0) & (sorted_us[np.maximum(position, 0)] == echoes_us)
    return np.where(found, order[np.maximum(position, 0)], -1)


def state_columns(states: list[State]) -> dict[str, np.ndarray]:
    """The STATE reports as named SI arrays (report order)."""
    def col(getter: Any, dtype: Any = np.float64) -> np.ndarray:
        return np.array([getter(s) for s in states], dtype=dtype)

    corners = np.array([s.corner_forces_n for s in states], dtype=np.float64).reshape(-1, 4)
    return {
        "t": unwrapped_times(states),
        "sequence": col(lambda s: s.sequence, np.int64),
        "contact": col(lambda s: s.contact, bool),
        "x": col(lambda s: s.x_mm) * MM,
        "y": col(lambda s: s.y_mm) * MM,
        "f_tl": corners[:, 0], "f_tr": corners[:, 1],
        "f_bl": corners[:, 2], "f_br": corners[:, 3],
        "fn": corners.sum(axis=1),
        "fl": col(lambda s: s.lateral_force_n),
        "amplitude": col(lambda s: s.amplitude_m),
        "voltage": col(lambda s: s.voltage_v),
        "current": col(lambda s: s.current_a),
        "target_uv": col(lambda s: s.target_uv),
        "target_ev": col(lambda s: s.target_ev),
        "texture": col(lambda s: s.texture, np.int64),
        "faults": col(lambda s: s.faults, np.int64),
        "flags": col(lambda s: s.flags, np.int64),
        "echo_us": col(lambda s: s.host_time_echo_us, np.int64),
    }


def device_description(info: DeviceInfo) -> str:
    """``"hcard reference E-ViTa (protocol 1.1)"`` and the like, from DEVICE_INFO."""
    try:
        kind = {DeviceKind.EVITA: "E-ViTa", DeviceKind.COUPLED: "coupled UV+EV stimulator"}[
            DeviceKind(info.device_kind)]
    except (KeyError, ValueError):
        kind = f"device kind {info.device_kind}"
    return f"{kind} (hcard protocol {info.protocol_major}.{info.protocol_minor})"


def public_uri(uri: str) -> str:
    """The device URI without its query: the options of an in-process device (seed, hidden
    effects) describe the simulation, not the device's conditions, and are not recorded."""
    return str(uri).split("?", 1)[0]


def sidecar(result: PlayResult, *, track_path: str | None = None,
            card_path: str | None = None) -> dict[str, Any]:
    """The conditions of a play session (rule M9 keys)."""
    info = result.info
    has_ev = bool(info.capabilities & Capability.EV)
    conditions: dict[str, Any] = {
        "device": device_description(info),
        "plate_frequency_hz": float(info.plate_frequency_hz) if info.plate_frequency_hz else None,
        "firmware": {
            "protocol": f"{info.protocol_major}.{info.protocol_minor}",
            "device_kind": int(info.device_kind),
            "capabilities": int(info.capabilities),
            "frame_rate_hz": int(info.frame_rate_hz),
            "input_rate_hz": int(info.input_rate_hz),
            "touch_rate_hz": int(info.touch_rate_hz),
        },
        "limits": {
            "max_amplitude_m": result.limits.max_amplitude_m,
            "max_voltage_v": result.limits.max_voltage_v,
            "max_current_a": result.limits.max_current_a,
        },
        "card": {
            "sha256": hashlib.sha256(result.card_bytes).hexdigest(),
            "bytes": len(result.card_bytes),
            "generation": int(result.upload.status.card_generation),
            "title": result.card_title,
            "path": card_path,
        },
        "profile": dict(result.profile),
        "session": {
            "uri": public_uri(result.uri),
            "track": track_path,
            "duration_s": result.duration_s,
            "reports": len(result.states),
            "reports_lost": int(result.reports_lost),
            "reports_dropped": int(result.counters.input_dropped),
            "malformed": int(result.malformed),
            "started": result.started,
        },
        "notes": "recorded by hcard play",
    }
    if has_ev:
        conditions["voltage_form"] = "envelope"
        conditions["carrier_frequency_hz"] = float(info.ev_carrier_hz)
    return conditions


def recording(result: PlayResult, *, track_path: str | None = None,
              card_path: str | None = None) -> Measurement:
    """The session as a :class:`~hcard.calibration.measurement.Measurement` (module docstring).

    Reports whose time stamp does not move forward (a repeated report) are left out, so that time
    increases strictly (rule M7). A device without a UV channel records no amplitude column, one
    without EV no voltage column (rule M5 needs one of them).

    Raises:
        ValueError: no STATE report was received.
    """
    if not result.states:
        raise ValueError("the device sent no STATE report: nothing to record")
    columns = state_columns(result.states)
    keep = np.concatenate(([True], np.diff(columns["t"]) > 0))
    columns = {name: values[keep] for name, values in columns.items()}
    sample = echoed_samples(result.sent_host_us(), columns.pop("echo_us"))
    speed = np.where(sample >= 0, track_speeds(result.track)[np.maximum(sample, 0)], 0.0)
    speed = np.where(columns["contact"], speed, 0.0)
    stroke = np.where((sample >= 0) & columns["contact"],
                      track_strokes(result.track)[np.maximum(sample, 0)], -1)
    echo = np.where(sample >= 0, result.track.t[np.maximum(sample, 0)], math.nan)
    # an echo of no sample of this session: the last host time before the track (rule M6: no
    # NaN), one microsecond before its first sample
    echo = np.where(np.isnan(echo), result.track.t[0] - 1e-6, echo)
    info = result.info
    device_columns = ("sequence", "f_tl", "f_tr", "f_bl", "f_br", "current", "target_uv",
                      "target_ev", "texture", "faults", "flags")
    device = {name: columns[name] for name in device_columns}
    device["echo"] = echo
    return Measurement(
        t=columns["t"],
        normal_force=columns["fn"],
        lateral_force=columns["fl"],
        amplitude=columns["amplitude"] if info.capabilities & Capability.UV else None,
        voltage=columns["voltage"] if info.capabilities & Capability.EV else None,
        x=columns["x"],
        y=columns["y"],
        speed=speed,
        stroke=stroke,
        contact=columns["contact"],
        device=device,
        conditions=sidecar(result, track_path=track_path, card_path=card_path),
    )
