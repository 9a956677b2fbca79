"""Rendering on the host for a device that takes actuator frames (:mod:`.frame_device`).

What the reference firmware does on the device, done here on the host, with the same core
code: the card's target friction frame by frame (:class:`hcard.render.RenderStream`, the
finger samples as the host receives them) or streamed targets, then actuator commands from the
device's physics profile (:func:`hcard.physics.actuation.actuate`, velocity compensation,
Eq. 2.30) at the finger speed every host and device uses
(:func:`hcard.render.finger_speed.predicted_speed`) and the finger's force, clamped at the
limits in force.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hcard.device.protocol import FaultBits
from hcard.physics.actuation import actuate
from hcard.physics.profile import DeviceProfile
from hcard.quantities import M_PER_MM
from hcard.render import Renderer, RenderOptions, RenderStream
from hcard.render.finger_speed import TouchSamples, predicted_speed
from hcard.v1 import card_pb2 as pb

STREAM_CAPACITY_FRAMES = 2000
"""Streamed target frames held before the oldest new ones are dropped (STREAM_OVERRUN)."""


@dataclass(frozen=True)
class FingerSample:
    """One finger sample from the host.

    Attributes:
        t_s: its time (host clock = device clock for a frame driver), s.
        placed_s: device time from which it applies (its time, or its arrival if later), s.
        x_mm, y_mm: position, mm.
        normal_force_n: normal force, N.
        contact: the finger touches the surface.
        host_time_us: its time as FINGER carries it (us, modulo 2**32), echoed in STATE.
    """

    t_s: float
    placed_s: float
    x_mm: float
    y_mm: float
    normal_force_n: float
    contact: bool
    host_time_us: int


@dataclass(frozen=True)
class FrameBlock:
    """Consecutive frames rendered on the host.

    Attributes:
        first: index of the first frame (frame k plays at k / frame rate).
        uv, ev: target relative friction.
        texture: palette index (-1: none).
        amplitude_m, voltage_v: actuator commands sent, m peak-to-peak and V.
        faults: per frame, :class:`FaultBits` raised on the host (its clamps, stream overrun).
        stream_queued: streamed frames still queued after each frame.
        finger: the finger sample applied at each frame (None: none yet).
    """

    first: int
    uv: np.ndarray
    ev: np.ndarray
    texture: np.ndarray
    amplitude_m: np.ndarray
    voltage_v: np.ndarray
    faults: np.ndarray
    stream_queued: np.ndarray
    finger: list[FingerSample | None]


class HostRendering:
    """Targets and actuator commands for a frame device, frame by frame.

    Args:
        profile: the device's physics profile (what ``actuate`` inverts).
        frame_rate_hz: the device's frame rate, Hz.
    """

    def __init__(self, profile: DeviceProfile, frame_rate_hz: float) -> None:
        self.profile = profile
        self.frame_rate_hz = float(frame_rate_hz)
        self.options = RenderOptions(frame_rate_hz=self.frame_rate_hz,
                                     band_limit_hz=min(1000.0, 0.4 * self.frame_rate_hz))
        self.renderer: Renderer | None = None
        self._stream: RenderStream | None = None
        self._fingers: deque[FingerSample] = deque()
        self._applied: FingerSample | None = None
        self._samples = TouchSamples.empty()  # the last applied ones, for the speed
        self._queue: deque[tuple[float, float]] = deque()
        self.streaming = False
        self._last_pushed = -math.inf
        self.stream_dropped = 0
        self.stream_gaps = 0

    # ------------------------------------------------------------------ inputs

    def load(self, card: pb.Card) -> None:
        """Render ``card`` from the next frame on (it is validated by the caller)."""
        self.renderer = Renderer(card, self.options)
        self._stream = None

    def restart(self) -> None:
        """Render the card afresh from the next finger sample on, and empty the stream (START,
        STOP)."""
        self._stream = None
        self.streaming = False
        self._queue.clear()

    def finger(self, t_s: float, arrived_s: float, x_mm: float, y_mm: float,
               normal_force_n: float, contact: bool, host_time_us: int) -> None:
        """A finger sample from the host at time ``t_s`` that arrived at ``arrived_s`` (s)."""
        self._fingers.append(FingerSample(t_s, max(t_s, arrived_s), x_mm, y_mm,
                                          normal_force_n, contact, host_time_us))

    def stream(self, uv: np.ndarray, ev: np.ndarray) -> None:
        """Queue streamed target frames (played from the next frame on, in order)."""
        self.streaming = True
        room = STREAM_CAPACITY_FRAMES - len(self._queue)
        take = min(room, uv.shape[0])
        self._queue.extend(zip(uv[:take].tolist(), ev[:take].tolist(), strict=True))
        self.stream_dropped += uv.shape[0] - take

    @property
    def queued(self) -> int:
        """Streamed frames waiting."""
        return len(self._queue)

    # ------------------------------------------------------------------ frames

    def frames(self, first: int, count: int, *, running: bool,
               limits: tuple[float, float]) -> FrameBlock:
        """Frames ``first .. first + count - 1``: targets (the card's while ``running``, or the
        streamed ones; neutral otherwise) and the commands for them, clamped at ``limits``
        (amplitude m, voltage V); zero commands while not ``running``. A target the profile
        cannot render at its limits, or one the commands were clamped for, raises the limit's
        fault bit (CARD_CLIPPED as well while playing the card)."""
        times = (first + np.arange(count)) / self.frame_rate_hz
        applied = self._apply_fingers(times)
        uv, ev = np.ones(count), np.ones(count)
        texture = np.full(count, -1, dtype=np.int32)
        faults = np.zeros(count, dtype=np.uint16)
        queued = np.zeros(count, dtype=np.int64)
        if running and self.streaming:
            for k in range(count):
                if self._queue:
                    uv[k], ev[k] = self._queue.popleft()
                elif k == 0 or queued[k - 1] > 0:
                    self.stream_gaps += 1
                queued[k] = len(self._queue)
        elif running and self.renderer is not None:
            uv, ev, texture = self._card_frames(first, count, times)
        amplitude, voltage = np.zeros(count), np.zeros(count)
        if running and (np.any(uv < 1.0) or np.any(ev > 1.0)):
            speed = predicted_speed(self._samples, times,
                                    self.options.dead_reckoning_s) * M_PER_MM
            force = np.array([max(f.normal_force_n, 0.0) if f is not None and f.contact
                              else 0.0 for f in applied])
            commands = actuate(self.profile, uv, ev, speed, force)
            amplitude, voltage = commands.amplitude, commands.voltage
            card = 0 if self.streaming else int(FaultBits.CARD_CLIPPED)
            faults[commands.uv_clipped] |= int(FaultBits.AMPLITUDE_LIMIT) | card
            faults[commands.ev_clipped] |= int(FaultBits.VOLTAGE_LIMIT) | card
        max_amplitude, max_voltage = limits
        faults[amplitude > max_amplitude] |= int(FaultBits.AMPLITUDE_LIMIT)
        faults[voltage > max_voltage] |= int(FaultBits.VOLTAGE_LIMIT)
        return FrameBlock(first, uv, ev, texture, np.minimum(amplitude, max_amplitude),
                          np.minimum(voltage, max_voltage), faults, queued, applied)

    def _apply_fingers(self, times: np.ndarray) -> list[FingerSample | None]:
        """The sample applied at each frame time (the newest placed at or before it), pushing
        each newly applied one to the card's render stream."""
        applied: list[FingerSample | None] = []
        for t in times.tolist():
            while self._fingers and self._fingers[0].placed_s <= t + 1e-12:
                self._applied = self._fingers.popleft()
                self._push(self._applied)
                self._remember(self._applied)
            applied.append(self._applied)
        return applied

    def _remember(self, sample: FingerSample) -> None:
        """Keep ``sample`` (a repeat of the newest time replaces it) among the last four."""
        samples = self._samples
        if len(samples) and sample.t_s <= samples.t[-1]:
            samples = TouchSamples(samples.t[:-1], samples.x[:-1], samples.y[:-1],
                                   samples.contact[:-1])
        new = TouchSamples(np.array([sample.t_s]), np.array([sample.x_mm]),
                           np.array([sample.y_mm]), np.array([sample.contact]))
        self._samples = samples.concat(new).tail(4)

    def _push(self, sample: FingerSample) -> None:
        if self.renderer is None:
            return
        if self._stream is None:
            self._stream = self.renderer.stream(0.0)  # frame k at k / rate, the device's
            self._last_pushed = -math.inf
        if sample.t_s <= self._last_pushed:
            return  # a repeat of the newest time: the renderer already holds that instant
        self._stream.push(sample.t_s, sample.x_mm, sample.y_mm, sample.normal_force_n,
                          sample.contact)
        self._last_pushed = sample.t_s

    def _card_frames(self, first: int, count: int,
                     times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The card's targets at frames ``first ..``: neutral before the first finger sample."""
        if self._stream is None:
            return np.ones(count), np.ones(count), np.full(count, -1, dtype=np.int32)
        self._stream.next_frame = first
        frames = self._stream.render(count)
        return (np.asarray(frames.uv, dtype=float), np.asarray(frames.ev, dtype=float),
                np.asarray(frames.texture, dtype=np.int32))
