"""A play session as a recording in the measurement format (spec/measurement-format.md).

One row per STATE report (spec/device-protocol.md section 6), the columns of rule MF3 in SI
units (``t_s`` device time from the first report, ``x_m``, ``y_m``, ``speed_m_s``, ``fn_n``,
``fl_n``, ``amplitude_m``, ``voltage_v``, ``contact``) and the device columns of rule MF12
(``sequence``, corner forces, ``current_a``, ``target_uv``, ``target_ev``, ``texture``,
``faults``, ``flags``, ``echo_s``), with the sidecar keys of rule MF9 for what the device and the
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
import os
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from hcard.calibration.measurement import DEVICE_COLUMNS, Measurement, write_measurement_blocks
from hcard.calibration.splits import stroke_numbers
from hcard.device.play_result import HOST_TIME_MODULO, PlayResult
from hcard.device.protocol import Capability, DeviceInfo, DeviceKind, Limits, State
from hcard.device.protocol.constants import (
    AMPLITUDE_UNIT_M,
    CURRENT_UNIT_A,
    FORCE_UNIT_N,
    FRICTION_SCALE,
    POSITION_UNIT_MM,
    VOLTAGE_UNIT_V,
    StateFlags,
)
from hcard.device.state_log import state_field
from hcard.device.uri import stated_ambient_pressure
from hcard.quantities import M_PER_MM, S_PER_US
from hcard.render.touch import speed_estimate
from hcard.track import FingerTrack


def unwrap_stamps(stamps_us: np.ndarray) -> np.ndarray:
    """Device time stamps (u32 microseconds, wrapping) unwrapped: microseconds since the
    first, int64."""
    stamps = np.asarray(stamps_us, dtype=np.int64)
    if not stamps.size:
        return np.zeros(0, dtype=np.int64)
    steps = np.diff(stamps) % HOST_TIME_MODULO
    return np.concatenate(([0], np.cumsum(steps)))


def unwrapped_times(states: Sequence[State]) -> np.ndarray:
    """Device time stamps of ``states`` unwrapped (u32 microseconds), from the first, s."""
    return unwrap_stamps(state_field(states, "timestamp_us")) * S_PER_US


def track_speeds(track: FingerTrack) -> np.ndarray:
    """Speed of each track sample over the interval that ends at it, m/s, signed by the
    direction along x (along y for a purely vertical move); 0 unless both samples touch."""
    speed = speed_estimate(track.t, track.x, track.y, np.asarray(track.contact, dtype=bool))
    dx, dy = np.diff(track.x), np.diff(track.y)
    speed[1:] *= M_PER_MM * np.where(dx != 0, np.sign(dx), np.where(dy < 0, -1.0, 1.0))
    return speed


def track_strokes(track: FingerTrack) -> np.ndarray:
    """The stroke of each track sample by rule MS2 (spec/measurement-format.md section 4: a lift
    or a reversal of the direction starts one), -1 out of contact. The recording takes a report's
    stroke from the sample it echoes, so reports lost on the way (a gap in the device's time
    stamps, which MS2 would read as a new stroke) cannot cut a stroke in two: on the reference
    served over usbip, host stalls that lost 1236 of 30000 reports turned the 26 strokes of the
    calibration protocol into 46 and changed which strokes the split held out."""
    return stroke_numbers(track.t, np.asarray(track.contact, dtype=bool), track_speeds(track))


class EchoIndex:
    """Which track sample an echoed host time names (:meth:`samples`), given the host time
    sent with each sample of the session (``host_us``, :attr:`PlayResult.host_us`)."""

    def __init__(self, host_us: np.ndarray) -> None:
        host_us = np.asarray(host_us, dtype=np.int64) % HOST_TIME_MODULO
        self._order = np.argsort(host_us, kind="stable")
        self._sorted_us = host_us[self._order]

    def samples(self, echoes_us: np.ndarray) -> np.ndarray:
        """Index of the sample each echo (us, wrapping) names; -1 for an echo of no sample of
        this session (:func:`echoed_samples`)."""
        echoes_us = np.asarray(echoes_us, dtype=np.int64)
        if not self._sorted_us.size:
            return np.full(echoes_us.shape, -1, dtype=np.int64)
        position = np.searchsorted(self._sorted_us, echoes_us, side="right") - 1
        at = np.maximum(position, 0)
        found = (position >= 0) & (self._sorted_us[at] == echoes_us)
        return np.where(found, self._order[at], -1)


def echoed_samples(host_us: np.ndarray, echoes_us: np.ndarray) -> np.ndarray:
    """Index of the sample each echoed host time (us, wrapping) names, given the host time
    sent with each sample of the session (``host_us``, :attr:`PlayResult.host_us`); -1 for an
    echo of no sample of this session. A device echoes the last FINGER report it applied,
    which at the start of a session is still one of the previous session: the host times of
    a session start at its own START on a monotonic clock, so such an echo names none."""
    return EchoIndex(host_us).samples(echoes_us)


def state_columns(rows: np.ndarray) -> dict[str, np.ndarray]:
    """Packed STATE reports (:data:`~hcard.device.state_log.STATE_ROW`, report order)
    as named SI arrays, ``t`` left out (it needs the reports before, :func:`unwrap_stamps`)."""
    corners = rows["corner_forces_mn"].astype(np.float64) * FORCE_UNIT_N
    return {
        "sequence": rows["sequence"].astype(np.int64),
        "contact": (rows["flags"] & StateFlags.CONTACT) != 0,
        "x": rows["x_10um"] * POSITION_UNIT_MM * M_PER_MM,
        "y": rows["y_10um"] * POSITION_UNIT_MM * M_PER_MM,
        "f_tl": corners[:, 0], "f_tr": corners[:, 1],
        "f_bl": corners[:, 2], "f_br": corners[:, 3],
        "fn": corners.sum(axis=1),
        "fl": rows["lateral_force_mn"] * FORCE_UNIT_N,
        "amplitude": rows["amplitude_nm"] * AMPLITUDE_UNIT_M,
        "voltage": rows["voltage_dv"] * VOLTAGE_UNIT_V,
        "current": rows["current_10na"] * CURRENT_UNIT_A,
        "target_uv": rows["target_uv_x1e4"] / FRICTION_SCALE,
        "target_ev": rows["target_ev_x1e4"] / FRICTION_SCALE,
        "texture": rows["texture"].astype(np.int64),
        "faults": rows["faults"].astype(np.int64),
        "flags": rows["flags"].astype(np.int64),
        "echo_us": rows["host_time_echo_us"].astype(np.int64),
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


def limits_record(limits: Limits) -> dict[str, float]:
    """LIMITS as the sidecar records them (rule MF9 ``limits``), SI units."""
    return {"max_amplitude_m": limits.max_amplitude_m, "max_voltage_v": limits.max_voltage_v,
            "max_current_a": limits.max_current_a}


def sidecar(result: PlayResult, *, track_path: str | None = None,
            card_path: str | None = None,
            ambient_pressure_pa: float | None = None) -> dict[str, Any]:
    """The conditions of a play session (rule MF9 keys); ``ambient_pressure_pa``: the air
    pressure the lab measured around the plate, Pa (else the one an in-process device's URI
    states, else none)."""
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
        "limits": limits_record(result.limits),
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
    if result.limits_at_start is not None:
        conditions["limits_at_start"] = limits_record(result.limits_at_start)
    pressure = ambient_pressure_pa
    if pressure is None:
        pressure = stated_ambient_pressure(result.uri)
    if pressure is not None:  # the air around the plate
        conditions["ambient_pressure_pa"] = pressure
    if has_ev:
        conditions["voltage_form"] = "envelope"
        conditions["carrier_frequency_hz"] = float(info.ev_carrier_hz)
    return conditions


BLOCK_REPORTS = 8192
"""Reports per block when a recording is written (:func:`write_recording`)."""
REPORTED_DEVICE_COLUMNS = tuple(q for q in DEVICE_COLUMNS if q != "echo")
"""The device columns of rule MF12 taken from the reports as they are (``echo`` is derived)."""
FORCE_COLUMNS = ("t", "normal_force", "lateral_force", "speed", "contact")
"""The recording's columns besides the targets that the rendered friction error reads."""


def recording_blocks(result: PlayResult, *,
                     block_reports: int = BLOCK_REPORTS) -> Iterator[Measurement]:
    """The session's recording (:func:`recording`) as consecutive blocks of at most
    ``block_reports`` reports, without conditions: the blocks joined are the recording.

    Raises:
        ValueError: no STATE report was received (raised here, before any block is made).
    """
    rows = result.states.rows()
    if not rows.size:
        raise ValueError("the device sent no STATE report: nothing to record")
    return _blocks(result, rows, block_reports)


def _blocks(result: PlayResult, rows: np.ndarray, block_reports: int) -> Iterator[Measurement]:
    """:func:`recording_blocks` of the packed reports ``rows`` (at least one)."""
    track = result.track
    speeds, strokes = track_speeds(track), track_strokes(track)
    echoes = EchoIndex(result.sent_host_us())
    has_uv = bool(result.info.capabilities & Capability.UV)
    has_ev = bool(result.info.capabilities & Capability.EV)
    previous_stamp = int(rows["timestamp_us"][0])
    elapsed_us = 0
    for first in range(0, rows.size, block_reports):
        block = rows[first:first + block_reports]
        stamps = np.concatenate(([previous_stamp], block["timestamp_us"].astype(np.int64)))
        steps = np.diff(stamps) % HOST_TIME_MODULO
        elapsed = elapsed_us + np.cumsum(steps)
        previous_stamp, elapsed_us = int(stamps[-1]), int(elapsed[-1])
        # a report whose time stamp does not move forward (a repeat) is left out (rule MF7)
        keep = steps > 0
        if first == 0:
            keep[0] = True
        columns = {name: values[keep] for name, values in state_columns(block).items()}
        sample = echoes.samples(columns.pop("echo_us"))
        echoed = sample >= 0
        at = np.maximum(sample, 0)
        contact = columns["contact"]
        # an echo of no sample of this session: the last host time before the track (rule
        # MF6: no NaN), one microsecond before its first sample
        echo = np.where(echoed, track.t[at], track.t[0] - 1e-6)
        device = {name: columns[name] for name in REPORTED_DEVICE_COLUMNS}
        device["echo"] = echo
        yield Measurement(
            t=elapsed[keep] * S_PER_US,
            normal_force=columns["fn"],
            lateral_force=columns["fl"],
            amplitude=columns["amplitude"] if has_uv else None,
            voltage=columns["voltage"] if has_ev else None,
            x=columns["x"],
            y=columns["y"],
            speed=np.where(echoed & contact, speeds[at], 0.0),
            stroke=np.where(echoed & contact, strokes[at], -1),
            contact=contact,
            device=device,
        )


def recording(result: PlayResult, *, track_path: str | None = None,
              card_path: str | None = None) -> Measurement:
    """The session as a :class:`~hcard.calibration.measurement.Measurement` (module docstring).

    Reports whose time stamp does not move forward (a repeated report) are left out, so that time
    increases strictly (rule MF7). A device without a UV channel records no amplitude column, one
    without EV no voltage column (rule MF5 needs one of them).

    Raises:
        ValueError: no STATE report was received.
    """
    whole = next(recording_blocks(result, block_reports=max(len(result.states), 1)))
    whole.conditions = sidecar(result, track_path=track_path, card_path=card_path)
    return whole


def force_recording(result: PlayResult) -> Measurement:
    """The columns of the session's recording that the rendered friction error reads (time,
    normal and lateral force, speed, contact, the two targets; 7 of its 21 columns), joined
    block by block, so a long session's summary holds 57 bytes per report besides the packed
    reports, not the whole recording.

    Raises:
        ValueError: no STATE report was received.
    """
    kept: list[dict[str, np.ndarray]] = []  # the 7 columns of each block; the rest is dropped
    for block in recording_blocks(result):
        kept.append({name: getattr(block, name) for name in FORCE_COLUMNS}
                    | {name: block.device[name] for name in ("target_uv", "target_ev")})
    joined = {name: np.concatenate([part[name] for part in kept]) for name in kept[0]}
    return Measurement(t=joined["t"], normal_force=joined["normal_force"],
                       lateral_force=joined["lateral_force"], speed=joined["speed"],
                       contact=joined["contact"],
                       device={name: joined[name] for name in ("target_uv", "target_ev")},
                       conditions={})


def write_recording(result: PlayResult, path: str | os.PathLike[str], *,
                    track_path: str | None = None, card_path: str | None = None,
                    ambient_pressure_pa: float | None = None) -> int:
    """Write the session's recording (:func:`recording`) and its sidecar to ``path``, block by
    block (:data:`BLOCK_REPORTS` reports in memory at a time besides the packed reports),
    the CSV and its sidecar replacing the earlier pair together; returns the rows written.

    Raises:
        ValueError: no STATE report was received (nothing is written).
        OSError: the files cannot be written (the earlier CSV and sidecar at ``path`` are both
            kept).
    """
    blocks = recording_blocks(result)
    conditions = sidecar(result, track_path=track_path, card_path=card_path,
                         ambient_pressure_pa=ambient_pressure_pa)
    return write_measurement_blocks(blocks, conditions, path)
