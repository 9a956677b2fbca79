"""The faulty device's hardware, simulated on its own clock: a plate and an EV amplifier that
play actuator frames (:class:`~hcard.device.frame_device.FrameDevice`), with the device faults
of :mod:`.faults` built in (:class:`PlateFaults`; all zero: a conforming device).

- **Frames.** Frame ``k`` plays at ``k / frame_rate_hz`` s of device time, and the device
  advances when it is measured (:meth:`FaultyPlate.measure`), as fast as the host asks. Its
  command reaches the actuators ``output_delay_s`` later (fault ``output-latency``: a queue
  behind the frame input).
- **Hardware limits.** Each amplitude command is clamped to [0, max amplitude] (NaN: 0), each
  voltage command to [0, max voltage] and to the voltage at which the carrier into the
  electrode's capacitance draws the maximum current (``I = 2 pi f C V``); a clamp raises its
  fault bit. The clamps act on the commands, before the actuators.
- **Plate.** The amplitude envelope ``w`` moves toward ``g c`` (``c`` the clamped command,
  ``g = 1 + uv_gain_error``), integrated exactly over each frame with the command held:
  ``w += (g c - w) (1 - exp(-dt / T))``, where ``T`` is the plate's time constant ``tau``
  while rising (a resonant plate driven at resonance settles as ``1 - exp(-t / tau)``: -3 dB
  bandwidth ``1 / (2 pi tau)``, 10-90 % rise time ``tau ln 9``) and ``tau /``
  :data:`BRAKE_SPEEDUP` while falling (the amplifier damps the plate actively). The measured
  amplitude is ``w`` plus ``residual_amplitude_m`` (fault ``residual-vibration``).
- **EV.** The voltage envelope is ``(1 + ev_gain_error)`` times the clamped command within the
  frame; the current is that of the carrier into the electrode's capacitance.
- **Watchdog.** Once no frame has arrived for ``watchdog_s`` (plus ``watchdog_delay_s``) the
  commands drop to 0 and WATCHDOG is reported until frames arrive again; before the first frame
  the outputs are off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard.device.frame_device import FrameDevice, FrameDeviceInfo, Measurement
from hcard.device.protocol import FaultBits
from hcard_conformance.faulty.profile import PLATE, plate_profile

TAU_S = 0.1e-3
"""The plate's time constant without fault, s: -3 dB at 1.6 kHz, 10-90 % rise in 0.22 ms."""
BRAKE_SPEEDUP = 10.0
"""How much faster the actively damped plate falls than it rises."""


@dataclass(frozen=True)
class PlateFaults:
    """The device faults of one plate (each 0 without the fault; see :mod:`.faults`).

    Attributes:
        output_delay_s: time from a frame's slot to the actuators playing it, s.
        added_tau_s: added to the plate's time constant :data:`TAU_S`, s.
        uv_gain_error: relative error of the plate amplitude against the command (signed).
        ev_gain_error: relative error of the EV voltage against the command (signed).
        watchdog_delay_s: the watchdog acts this long after the data sheet's watchdog time, s.
        residual_amplitude_m: plate amplitude on top of the commanded one, m peak-to-peak.
    """

    output_delay_s: float = 0.0
    added_tau_s: float = 0.0
    uv_gain_error: float = 0.0
    ev_gain_error: float = 0.0
    watchdog_delay_s: float = 0.0
    residual_amplitude_m: float = 0.0


class FaultyPlate(FrameDevice):
    """The faulty device's plate and EV amplifier on their own clock.

    Args:
        faults: the hardware's faults (default none).
        info: its data sheet (default :data:`~.profile.PLATE`).
    """

    def __init__(self, faults: PlateFaults | None = None,
                 info: FrameDeviceInfo = PLATE) -> None:
        self.info = info
        self.faults = faults or PlateFaults()
        self.closed = False
        dt = 1.0 / info.frame_rate_hz
        self._dt = dt
        tau = TAU_S + self.faults.added_tau_s
        self._rise = 1.0 - math.exp(-dt / tau)
        self._fall = 1.0 - math.exp(-dt * BRAKE_SPEEDUP / tau)
        self._delay_frames = round(self.faults.output_delay_s / dt)
        self._watchdog_frames = (info.watchdog_s + self.faults.watchdog_delay_s) / dt
        capacitance = plate_profile().load_capacitance or 0.0
        self._amps_per_volt = 2.0 * math.pi * info.ev_carrier_hz * capacitance
        at_max_current = (info.max_current_a / self._amps_per_volt if self._amps_per_volt > 0
                          else math.inf)
        self._max_voltage = min(info.max_voltage_v, at_max_current)
        self._voltage_clamp = (FaultBits.CURRENT_LIMIT if at_max_current < info.max_voltage_v
                               else FaultBits.VOLTAGE_LIMIT)
        self._frame = 0                              # the next frame to play
        self._commands: dict[int, tuple[float, float]] = {}  # frame -> (amplitude m, voltage V)
        self._last_fed: int | None = None            # the last frame a command arrived for
        self._held = (0.0, 0.0, 0)                   # clamped command in force, its faults
        self._envelope = 0.0                         # plate amplitude without residual, m

    def clock(self) -> float:
        """Device time: that of the next frame to play, s."""
        return self._frame * self._dt

    def play(self, first_frame: int, amplitude_m: np.ndarray, voltage_v: np.ndarray) -> None:
        """Queue commands for frames ``first_frame ..`` (those already played are ignored)."""
        commands = zip(np.asarray(amplitude_m, dtype=float).tolist(),
                       np.asarray(voltage_v, dtype=float).tolist(), strict=True)
        for k, command in enumerate(commands, start=first_frame):
            if k >= self._frame:
                self._commands[k] = command
                self._last_fed = k if self._last_fed is None else max(self._last_fed, k)

    def _clamped(self, amplitude: float, voltage: float) -> tuple[float, float, int]:
        """A command within the hardware limits, and the fault bits of its clamps."""
        faults = 0
        amplitude = amplitude if amplitude > 0 else 0.0   # NaN, zero or negative: off
        if amplitude > self.info.max_amplitude_m:         # +inf included
            amplitude, faults = self.info.max_amplitude_m, faults | FaultBits.AMPLITUDE_LIMIT
        voltage = voltage if voltage > 0 else 0.0
        if voltage > self._max_voltage:
            voltage, faults = self._max_voltage, faults | self._voltage_clamp
        return amplitude, voltage, int(faults)

    def measure(self, until_s: float) -> Measurement:
        """Play every frame up to device time ``until_s`` (s) and return what was measured."""
        last = math.floor(until_s / self._dt + 1e-9)
        n = max(last - self._frame + 1, 0)
        amplitude = np.empty(n)
        voltage = np.empty(n)
        faults = np.zeros(n, dtype=np.uint16)
        uv_gain = 1.0 + self.faults.uv_gain_error
        ev_gain = 1.0 + self.faults.ev_gain_error
        for i in range(n):
            frame = self._frame + i
            command = self._commands.pop(frame - self._delay_frames, None)
            if self._last_fed is not None and frame - self._last_fed > self._watchdog_frames:
                self._held = (0.0, 0.0, int(FaultBits.WATCHDOG))
            elif command is not None:
                self._held = self._clamped(*command)
            target_m, target_v, fault_bits = self._held
            goal = uv_gain * target_m
            step = self._rise if goal >= self._envelope else self._fall
            self._envelope += (goal - self._envelope) * step
            amplitude[i] = self._envelope
            voltage[i] = ev_gain * target_v
            faults[i] = fault_bits
        t = (self._frame + np.arange(n)) * self._dt
        self._frame += n
        return Measurement(t, amplitude + self.faults.residual_amplitude_m, voltage,
                           voltage * self._amps_per_volt, np.full(n, np.nan), faults)

    def close(self) -> None:
        """Nothing to release; the plate stops."""
        self.closed = True
