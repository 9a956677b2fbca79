"""Report times from the echo age (device protocol 1.3, rule PI3).

A device places each host finger sample at ``host time + offset`` (PO2), the offset being the
fastest transport seen. When a faster report arrives mid-stroke the offset moves, and the part
of the stroke after it is rendered on another clock alignment than the part before. The echo
age tells the host where every echoed sample was placed, so each report maps to the host time
whose finger it rendered; a single offset estimated from when echoes arrive (all a 1.0-1.2
device allows) cannot follow the move.

The truth here is independent of the mapping code: the grating's target at the finger
position of a constant-speed stroke, evaluated from the texture formula.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hcard import build
from hcard.card_io import to_bytes
from hcard.device.protocol import (
    ECHO_AGE_UNKNOWN,
    Command,
    Control,
    Finger,
    State,
    decode_input,
    upload_reports,
)
from hcard.track import FingerTrack
from hcard_conformance.context import session_times
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation

SPEED_MM_S = 100.0
SAMPLE_S = 0.01
X0_MM = 10.0
CYCLES_PER_MM = 1.5
BASELINE, SWING = 0.7, 0.25


def grating_card() -> bytes:
    grating = build.texture(
        BASELINE, [build.spatial(CYCLES_PER_MM, SWING, channel="uv")], channel="uv",
        locking="position", name="grating",
    )
    return to_bytes(build.card(81.0, 54.0, taxtel_mm=27.0, textures=[grating]))


@dataclasses.dataclass
class Stroke:
    """What :func:`stroke` played: the STATE reports, the track, the host times sent (us) and
    the device time at which each sample arrived, s."""

    reports: list[State]
    track: FingerTrack
    host_us: np.ndarray
    arrival_s: np.ndarray


def stroke(delays_s: list[float]) -> Stroke:
    """A host stroke at SPEED_MM_S sampled every SAMPLE_S, sample k arriving ``delays_s[k]``
    after it was taken (to the device's 0.1 ms frame)."""
    fw = Firmware(DeviceSimulation(DeviceConfig.evita(), seed=2))
    for report in upload_reports(grating_card()):
        fw.set_feature(report)
    fw.handle_output(Control(Command.START, 9).encode())
    fw.advance(0.005)
    fw.take_input_reports()
    n = len(delays_s)
    t = np.arange(n) * SAMPLE_S
    x = X0_MM + SPEED_MM_S * t
    host_s = 3.0 + t  # the host's clock: its own origin
    start = fw.sim.time_s
    arrivals = start + t + np.asarray(delays_s)
    reports: list[State] = []
    arrived = np.zeros(n)
    for k in np.argsort(arrivals, kind="stable"):
        fw.advance(arrivals[k] - fw.sim.time_s)
        arrived[k] = fw.sim.time_s
        fw.handle_output(Finger.from_si(host_s[k], x[k], 27.0, 0.5, True).encode())
        reports += [decode_input(r) for r in fw.take_input_reports()]
    fw.advance(2 * SAMPLE_S)
    reports += [decode_input(r) for r in fw.take_input_reports()]
    track = FingerTrack(t=t, x=x, y=np.full(n, 27.0), normal_force=np.full(n, 0.5),
                        contact=np.ones(n, dtype=bool))
    return Stroke(reports, track, np.rint(host_s * 1e6).astype(np.int64), arrived - host_s)


def grating_at(t_s: np.ndarray) -> np.ndarray:
    """The target of the grating under the finger at track time ``t_s`` (texture formula)."""
    x = X0_MM + SPEED_MM_S * t_s
    return np.clip(BASELINE + SWING * np.cos(2 * np.pi * CYCLES_PER_MM * x), 0.0, 1.0)


def mapping_error(reports: list[State], track: FingerTrack, host_us: np.ndarray) -> float:
    """95th percentile of |reported target - grating at the mapped time| over the stroke
    (after the first two samples, where the finger's speed is known)."""
    keep, t = session_times(reports, track, host_us)
    target = np.array([s.target_uv for s in reports])
    judged = keep & (t >= 2 * SAMPLE_S) & (t <= track.t[-1])
    assert judged.sum() > 100
    return float(np.percentile(np.abs(target[judged] - grating_at(t[judged])), 95))


# the transport: 4 ms at first, then a report that travels in 0.5 ms moves the offset by 3.5 ms
MOVING_OFFSET = [0.004] * 12 + [0.0005] + [0.001, 0.002, 0.0015] * 6


def test_the_echo_age_names_where_each_sample_was_placed() -> None:
    """PI3 against PO2 computed here: a sample is placed at its host time plus the smallest
    ``arrival - host time`` so far (which may grow by 50 ppm of host time per step: 0.5 us per
    sample here), and the age is the report's device time less that placement."""
    played = stroke(MOVING_OFFSET)
    offset = np.minimum.accumulate(played.arrival_s)  # arrival_s holds arrival - host time
    host_s = played.host_us * 1e-6
    checked = 0
    for state in played.reports:
        if state.host_time_echo_us == 0:  # no sample applied yet: the age says so
            assert state.echo_age_us == ECHO_AGE_UNKNOWN
            continue
        k = int(np.flatnonzero(played.host_us == state.host_time_echo_us)[0])
        placed_us = 1e6 * (host_s[k] + offset[k])
        assert state.echo_age_us == pytest.approx(state.timestamp_us - placed_us, abs=20), k
        checked += 1
    assert checked > 200
    assert np.ptp(offset) > 0.003  # the offset did move within the stroke


def test_reports_map_to_the_finger_they_rendered_though_the_offset_moved() -> None:
    played = stroke(MOVING_OFFSET)
    reports, track, host_us = played.reports, played.track, played.host_us
    assert mapping_error(reports, track, host_us) < 0.02
    # the same reports without the echo age (what a protocol 1.2 device sends): one offset for
    # the stroke, off by 3.5 ms x 100 mm/s = 0.35 mm = half a grating period for one part
    legacy = [dataclasses.replace(s, echo_age_us=ECHO_AGE_UNKNOWN) for s in reports]
    assert mapping_error(legacy, track, host_us) > 0.2


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_transport_jitter_maps_exactly(seed: int) -> None:
    """Delays of 0.3-4 ms drawn at random, as over a busy USB/IP link. Mapped by the echo age,
    a report is off its finger only where the device itself rendered off it: for one sample
    period after a report that travelled faster than all before moved the offset (PO2), until
    the next sample arrives, the spacing of the placed samples is short by the move and the
    renderer's speed estimate is high. Everywhere else the target is the grating under the
    finger."""
    rng = np.random.default_rng(seed)
    delays = list(rng.uniform(0.0003, 0.004, size=30))
    played = stroke(delays)
    keep, t = session_times(played.reports, played.track, played.host_us)
    target = np.array([s.target_uv for s in played.reports])
    judged = keep & (t >= 2 * SAMPLE_S) & (t <= played.track.t[-1])
    error = np.abs(target - grating_at(t))[judged]
    offset = played.arrival_s
    moved = np.flatnonzero(offset < np.minimum.accumulate(offset)[np.maximum(
        np.arange(len(offset)) - 1, 0)] - 1e-6)
    after_move = np.zeros(judged.sum(), dtype=bool)
    for k in moved:
        after_move |= (t[judged] >= played.track.t[k]) & (t[judged] < played.track.t[k]
                                                          + SAMPLE_S + max(delays))
    assert after_move.mean() < 0.5
    assert np.max(error[~after_move]) < 0.02
    assert np.median(error) < 0.005
