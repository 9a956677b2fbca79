"""Play a card on a device along a finger track, and record what the device reports.

:func:`play` uploads the card, takes the finger state from the host (FINGER reports at the
track's sample times: on the wall clock for real and USB/IP devices, on the simulation's clock
for ``sim://``), starts rendering, collects every STATE report, and stops. :func:`recording_csv`
writes the reports as CSV, one row per report, SI units:

==================  ==========================================================================
``t_s``             device time stamp, unwrapped, relative to the first report, s
``sequence``        report sequence number (u16, wrapping)
``contact``         1 while a finger touches the surface
``x_mm``, ``y_mm``  finger position, mm
``fn_n``            normal force, sum of the four corner sensors, N
``f_tl_n`` ...      corner forces top-left, top-right, bottom-left, bottom-right, N
``lateral_n``       lateral (friction) force, N
``amplitude_m``     measured plate vibration amplitude, peak-to-peak, m
``voltage_v``       measured EV voltage envelope, V
``current_a``       measured EV current, A
``target_uv``       UV target relative friction being rendered, [0, 1]
``target_ev``       EV target relative friction being rendered, [1, 4]
``texture``         active palette index, -1 for none
``faults``          fault bits (``hcard_device.protocol.FaultBits``), integer
``flags``           state bits (``hcard_device.protocol.StateFlags``), integer
``echo_s``          host time of the last FINGER report applied, s (wrapping at 4295 s)
==================  ==========================================================================
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb
from hcard_device.drivers.base import Driver, UploadOutcome
from hcard_device.protocol import (
    FRICTION_SCALE,
    Capability,
    ClipReport,
    Counters,
    DeviceInfo,
    FaultBits,
    State,
)

RECORDING_COLUMNS = (
    "t_s", "sequence", "contact", "x_mm", "y_mm", "fn_n", "f_tl_n", "f_tr_n", "f_bl_n", "f_br_n",
    "lateral_n", "amplitude_m", "voltage_v", "current_a", "target_uv", "target_ev", "texture",
    "faults", "flags", "echo_s",
)
"""Columns of :func:`recording_csv`, in order."""
TAIL_S = 0.05
"""Reports collected after the last track sample before STOP, s."""
MIN_NORMAL_FORCE_N = 0.05
"""Reports with less normal force are left out of the friction comparison, N."""
MIN_REFERENCE_REPORTS = 20
"""Unmodulated reports needed to estimate the finger's friction coefficient."""


@dataclass(frozen=True)
class FrictionError:
    """Measured relative friction against the target, over the reports in contact.

    The finger's friction coefficient without modulation, ``mu0``, is the median of
    lateral / normal force over the reports whose target is 1 (no modulation); measured
    relative friction is then (lateral / normal) / mu0, compared with ``target_uv * target_ev``.

    Attributes:
        mean_abs: mean absolute error, relative friction.
        rms: root mean square error, relative friction.
        reports: reports compared.
        mu0: the estimated unmodulated friction coefficient.
    """

    mean_abs: float
    rms: float
    reports: int
    mu0: float


@dataclass(frozen=True)
class PlayResult:
    """What :func:`play` saw.

    Attributes:
        states: every STATE report, in arrival order.
        duration_s: driver clock time from START to the end of collection, s.
        upload: the upload outcome (status, clip report).
        info: DEVICE_INFO.
        counters: COUNTERS read at the end.
        reports_lost: reports missed (sequence gaps), host side.
        malformed: input reports that could not be decoded.
    """

    states: list[State]
    duration_s: float
    upload: UploadOutcome
    info: DeviceInfo
    counters: Counters
    reports_lost: int
    malformed: int

    @property
    def faults(self) -> FaultBits:
        """Every fault seen in the reports or latched by the device."""
        bits = self.counters.latched_faults
        for state in self.states:
            bits |= state.faults
        return FaultBits(bits)


def play(driver: Driver, card: pb.Card, track: FingerTrack, *,
         tail_s: float = TAIL_S) -> PlayResult:
    """Upload ``card``, drive ``track`` as the host's finger, record, stop.

    Finger reports go out at the track's sample times (relative to its first sample), on the
    driver's clock. Between samples the driver collects STATE reports; a KEEPALIVE is sent when
    samples are further apart than half the device's watchdog time.

    Raises:
        DeviceError: the device is missing, refuses the card or vanishes.
    """
    info = driver.info()
    upload = driver.upload_card(card)
    driver.clear_counters()
    if info.capabilities & Capability.HOST_FINGER:
        driver.set_touch_source(host=True)
    keepalive_s = max(info.watchdog_ms / 2000.0, 0.005)
    states: list[State] = []
    driver.start()
    start = driver.clock()
    t_first = float(track.t[0])
    last_sent = start
    for t, x, y, fn, contact in zip(track.t, track.x, track.y, track.fn, track.contact,
                                    strict=True):
        due = start + (float(t) - t_first)
        while due - last_sent > keepalive_s:
            last_sent += keepalive_s
            states += driver.collect_until(last_sent)
            driver.keepalive()
        states += driver.collect_until(due)
        driver.send_finger(float(t), float(x), float(y), float(fn), bool(contact))
        last_sent = due
    states += driver.collect_until(driver.clock() + tail_s)
    duration = driver.clock() - start
    driver.stop()
    counters = driver.counters()
    return PlayResult(states, duration, upload, info, counters, driver.reports_lost,
                      driver.malformed_inputs)


def unwrapped_times(states: list[State]) -> np.ndarray:
    """Device time stamps of ``states`` unwrapped (u32 microseconds), from the first, s."""
    if not states:
        return np.zeros(0)
    stamps = np.array([s.timestamp_us for s in states], dtype=np.int64)
    steps = np.diff(stamps) % (1 << 32)
    return np.concatenate(([0], np.cumsum(steps))) * 1e-6


def recording_table(states: list[State]) -> np.ndarray:
    """The recording as a float array, one row per report, :data:`RECORDING_COLUMNS`."""
    table = np.zeros((len(states), len(RECORDING_COLUMNS)))
    table[:, 0] = unwrapped_times(states)
    for i, s in enumerate(states):
        table[i, 1:] = (
            s.sequence, s.contact, s.x_mm, s.y_mm, s.normal_force_n, *s.corner_forces_n,
            s.lateral_force_n, s.amplitude_m, s.voltage_v, s.current_a, s.target_uv,
            s.target_ev, s.texture, s.faults, s.flags, s.host_time_echo_us * 1e-6,
        )
    return table


def recording_csv(states: list[State]) -> bytes:
    """CSV bytes of the recording (header row, :data:`RECORDING_COLUMNS`)."""
    buffer = io.StringIO()
    buffer.write(",".join(RECORDING_COLUMNS) + "\n")
    formats = ["%.6f", "%d", "%d", "%.2f", "%.2f", "%.3f", "%.3f", "%.3f", "%.3f", "%.3f",
               "%.3f", "%.9g", "%.1f", "%.8g", "%.4f", "%.4f", "%d", "%d", "%d", "%.6f"]
    np.savetxt(buffer, recording_table(states), delimiter=",", fmt=formats)
    return buffer.getvalue().encode()


def friction_error(states: list[State]) -> FrictionError | None:
    """Measured against target relative friction (see :class:`FrictionError`); None when
    there are too few unmodulated reports in contact to estimate the finger's mu0."""
    if not states:
        return None
    table = recording_table(states)
    fn, lateral = table[:, 5], np.abs(table[:, 10])
    target = table[:, 14] * table[:, 15]
    usable = (table[:, 2] > 0) & (fn > MIN_NORMAL_FORCE_N)
    mu = np.divide(lateral, fn, out=np.zeros_like(fn), where=fn > 0)
    reference = usable & (np.abs(target - 1.0) < 1e-3)
    if np.count_nonzero(reference) < MIN_REFERENCE_REPORTS:
        return None
    mu0 = float(np.median(mu[reference]))
    if mu0 <= 0:
        return None
    error = mu[usable] / mu0 - target[usable]
    return FrictionError(float(np.mean(np.abs(error))), float(np.sqrt(np.mean(error**2))),
                         int(np.count_nonzero(usable)), mu0)


def clip_text(clip: ClipReport) -> str:
    """One phrase on what the device clips of the card (its first clipped item)."""
    if not clip.item_count:
        return "renders as written (nothing clipped)"
    name = f" '{clip.texture_name}'" if clip.texture_name else ""
    channel = {1: "UV", 2: "EV"}.get(clip.channel, "?")
    return (f"clipped: {clip.item_count} item(s) in {clip.clipped_textures} texture(s), e.g. "
            f"texture {clip.texture}{name} {channel} asks {clip.target_x1e4 / FRICTION_SCALE:.3f},"
            f" gets {clip.achievable_x1e4 / FRICTION_SCALE:.3f}")


def summary(result: PlayResult) -> list[str]:
    """Summary lines: duration, reports received and dropped, faults, friction error."""
    states = result.states
    dropped = result.counters.input_dropped
    faults = result.faults
    fault_names = ", ".join(f.name or str(int(f)) for f in FaultBits if f in faults) or "none"
    lines = [
        f"played {result.duration_s:.3f} s: {len(states)} reports received, "
        f"{result.reports_lost} lost in transit (sequence gaps), {dropped} dropped by the device, "
        f"{result.malformed} malformed",
        f"card: {result.upload.bytes_sent} bytes in {result.upload.reports_sent} reports, "
        f"generation {result.upload.status.card_generation}; {clip_text(result.upload.clip)}",
        f"faults: {fault_names}",
    ]
    error = friction_error(states)
    if error is None:
        lines.append("friction error vs target: n/a (too few unmodulated reports in contact "
                     "to estimate the finger's friction coefficient)")
    else:
        lines.append(f"friction error vs target: mean {error.mean_abs:.3f}, rms {error.rms:.3f} "
                     f"(relative friction, {error.reports} reports in contact, "
                     f"mu0 {error.mu0:.3f})")
    return lines
