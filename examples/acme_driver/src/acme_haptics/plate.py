"""The Acme TX-1 friction plate, simulated: what the vendor's hardware does with the frames it
is sent.

- **Plate.** The vibration amplitude follows the drive ``u`` through a first-order envelope
  of time constant ``tau`` (a resonant plate driven at resonance: the envelope of
  ``m x'' + c x' + k x = F sin(w0 t)`` settles as ``1 - exp(-t / tau)``, ``tau = 2 m / c``),
  integrated exactly over each frame with the drive held (zero-order hold):
  ``w[k+1] = a w[k] + (1 - a) G u[k]``, ``a = exp(-dt / tau)``, ``G`` the amplitude at full
  drive. A command ``w_cmd`` at or above the plate's amplitude is driven at ``u = w_cmd / G``
  (it settles there: -3 dB bandwidth ``1 / (2 pi tau)``, 10-90 % rise time ``tau ln 9``); one
  below it brakes the plate in antiphase, ``u = max((w_cmd - a w) / ((1 - a) G), -b)``, which
  lands on the command in one frame when ``b`` suffices (a lowered limit is met at once, not
  after ``tau ln(w / w_cmd)`` of free decay).
- **Hardware limit.** Commands are clamped to ``max_amplitude_m`` (and NaN or negative ones to
  0) before the plate, whatever the host sends; the clamp is reported as AMPLITUDE_LIMIT.
- **Watchdog.** With no frame queued the plate holds the last command; once frames have been
  missing for ``watchdog_s`` the command drops to 0 (the envelope decays with ``tau``) and
  WATCHDOG is reported until frames arrive again.
- **Finger friction.** A lateral-force sensor measures ``F = mu0 mu' Fn`` of the rig's finger
  (:meth:`AcmePlate.touch`) while it slides, with ``mu'`` from the dimensionless group of
  ultrasonic friction reduction (thesis Eqs. 2.30 and 2.33)::

      Psi = U / (w f mu0 (1 + nu)),     mu' = 1 - exp(-Psi / Psi*)

  (``U`` sliding speed, ``w`` peak-to-peak amplitude, ``f`` plate frequency), and 1 without
  vibration. The sensor adds Gaussian noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hcard.device.frame_device import FrameDevice, FrameDeviceInfo, Measurement
from hcard.device.protocol import FaultBits

VIBRATION_FLOOR_M = 1e-12
"""Amplitudes below this (m) count as no vibration (an envelope decayed to nothing)."""


@dataclass(frozen=True)
class PlatePhysics:
    """The simulated plate and finger.

    Attributes:
        tau_s: time constant of the amplitude envelope, s.
        full_drive_m: amplitude the plate settles at under full drive (``G``), m peak-to-peak.
        brake_drive: largest antiphase drive, a fraction of full drive (``b``).
        mu0: friction coefficient without vibration.
        psi_star: characteristic value of the dimensionless group (Eq. 2.33).
        poisson_ratio: of the finger pad (Eq. 2.30).
        amplitude_noise_m: standard deviation of the amplitude measurement, m.
        force_noise_n: standard deviation of the lateral-force sensor, N.
    """

    tau_s: float = 0.25e-3
    full_drive_m: float = 4.0e-6
    brake_drive: float = 1.0
    mu0: float = 0.55
    psi_star: float = 2.38
    poisson_ratio: float = 0.33
    amplitude_noise_m: float = 0.1e-9
    force_noise_n: float = 1e-3


TX1 = FrameDeviceInfo(
    model="Acme TX-1", frame_rate_hz=10_000.0, plate_frequency_hz=31_500.0, ev_carrier_hz=0.0,
    max_amplitude_m=3.0e-6, max_voltage_v=0.0, max_current_a=0.0, width_mm=120.0,
    height_mm=80.0, watchdog_s=0.020, device_kind=0, lateral_force=True)
"""The TX-1's data sheet: a UV plate at 31.5 kHz, 3 um peak-to-peak, 10 kHz frames."""


def relative_friction(amplitude_m: np.ndarray, speed_m_s: np.ndarray, physics: PlatePhysics,
                      plate_frequency_hz: float) -> np.ndarray:
    """``mu'`` of Eq. 2.33 at each amplitude (m peak-to-peak) and sliding speed (m/s): 1
    without vibration; 0 for a finger at rest on a vibrating plate."""
    w = np.asarray(amplitude_m, dtype=float)
    u = np.asarray(speed_m_s, dtype=float)
    out = np.ones(np.broadcast(w, u).shape)
    vibrating = np.broadcast_to(w > VIBRATION_FLOOR_M, out.shape)
    denominator = w * plate_frequency_hz * physics.mu0 * (1.0 + physics.poisson_ratio)
    psi = np.divide(u, denominator, out=np.zeros(out.shape), where=vibrating)
    out[vibrating] = 1.0 - np.exp(-psi[vibrating] / physics.psi_star)
    return out


class AcmePlate(FrameDevice):
    """A simulated TX-1 on its own clock: :meth:`measure` advances it to the time asked.

    Args:
        info: its data sheet (default :data:`TX1`).
        physics: plate and finger (default :class:`PlatePhysics`).
        seed: of the measurement noise.
    """

    def __init__(self, info: FrameDeviceInfo = TX1, physics: PlatePhysics | None = None,
                 seed: int = 0) -> None:
        self.info = info
        self.physics = physics or PlatePhysics()
        self._rng = np.random.default_rng(seed)
        self._dt = 1.0 / info.frame_rate_hz
        self._frame = 0                       # the next frame to play
        self._queue: dict[int, float] = {}     # frame -> commanded amplitude, m
        self._held = 0.0                      # the command in force, m
        self._last_fed: int | None = None     # the last frame a command was queued for
        self._envelope = 0.0                  # plate amplitude, m
        self._finger: list[tuple[float, float, float, float, bool]] = []
        self.closed = False

    def clock(self) -> float:
        """Device time: that of the next frame to play, s."""
        return self._frame * self._dt

    def play(self, first_frame: int, amplitude_m: np.ndarray, voltage_v: np.ndarray) -> None:
        """Queue amplitude commands (the TX-1 has no EV: ``voltage_v`` is ignored)."""
        del voltage_v
        for k, value in enumerate(np.asarray(amplitude_m, dtype=float).tolist()):
            if first_frame + k >= self._frame:
                self._queue[first_frame + k] = value
                self._last_fed = max(self._last_fed or 0, first_frame + k)

    def touch(self, t_s: float, x_mm: float, y_mm: float, normal_force_n: float,
              contact: bool) -> None:
        """The rig's finger at ``t_s`` (s): position (mm), normal force (N), contact."""
        self._finger.append((t_s, x_mm, y_mm, normal_force_n, contact))
        del self._finger[:-3]

    def _finger_state(self, t_s: float) -> tuple[float, float]:
        """Sliding speed (m/s) and normal force (N) of the finger at ``t_s``: from the last two
        samples at or before it (0 out of contact)."""
        known = [f for f in self._finger if f[0] <= t_s + 1e-12]
        if not known or not known[-1][4]:
            return 0.0, 0.0
        t1, x1, y1, fn, _ = known[-1]
        if len(known) < 2 or not known[-2][4] or t1 <= known[-2][0]:
            return 0.0, fn
        t0, x0, y0, _, _ = known[-2]
        return math.hypot(x1 - x0, y1 - y0) * 1e-3 / (t1 - t0), fn

    def _step(self, envelope: float, command: float, decay: float) -> float:
        """The plate amplitude one frame on from ``envelope`` toward ``command`` (m)."""
        gain = self.physics.full_drive_m
        if command >= envelope:
            drive = command / gain
        else:  # brake: antiphase drive landing on the command, at most brake_drive
            drive = max((command - decay * envelope) / ((1.0 - decay) * gain),
                        -self.physics.brake_drive)
        return max(decay * envelope + (1.0 - decay) * gain * drive, 0.0)

    def measure(self, until_s: float) -> Measurement:
        """Play every frame up to device time ``until_s`` and return what was measured."""
        last = math.floor(until_s / self._dt + 1e-9)
        n = max(last - self._frame + 1, 0)
        t = (self._frame + np.arange(n)) * self._dt
        amplitude = np.zeros(n)
        force = np.zeros(n)
        faults = np.zeros(n, dtype=np.uint16)
        decay = math.exp(-self._dt / self.physics.tau_s)
        limit = self.info.max_amplitude_m
        for i in range(n):
            frame = self._frame + i
            if frame in self._queue:
                command = self._queue.pop(frame)
                if not command > 0:  # NaN, zero or negative: off
                    command = 0.0
                if command > limit:  # +inf included
                    command = limit
                    faults[i] |= FaultBits.AMPLITUDE_LIMIT
                self._held = command
            elif (self._last_fed is not None
                  and (frame - self._last_fed) * self._dt > self.info.watchdog_s):
                self._held = 0.0
                faults[i] |= FaultBits.WATCHDOG
            self._envelope = self._step(self._envelope, self._held, decay)
            amplitude[i] = self._envelope
            speed, fn = self._finger_state(float(t[i]))
            if speed > 0 and fn > 0:
                mu = relative_friction(np.array(self._envelope), np.array(speed), self.physics,
                                       self.info.plate_frequency_hz)
                force[i] = self.physics.mu0 * float(mu) * fn
        self._frame += n
        measured_amplitude = np.maximum(
            amplitude + self._rng.normal(0.0, self.physics.amplitude_noise_m, n), 0.0)
        measured_force = force + self._rng.normal(0.0, self.physics.force_noise_n, n)
        return Measurement(t, measured_amplitude, np.zeros(n), np.zeros(n), measured_force,
                           faults)

    def close(self) -> None:
        """Nothing to release; the plate stops."""
        self.closed = True
