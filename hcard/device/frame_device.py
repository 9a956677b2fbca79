"""The frame device contract: the smallest thing a vendor implements to play hcard cards on a
device that does not speak the hcard protocol.

A frame device takes actuator commands frame by frame (plate amplitude, m peak-to-peak, and EV
envelope, V) and says what its actuators did (measured amplitude, voltage, current, and the
lateral force where it has a sensor). Everything else — the card, the renderer, velocity
compensation with the device's physics profile, the host's limits, the STATE reports that
``play``, ``record`` and ``hcard conformance`` read — is done on the host by
:class:`hcard.device.frame_driver.FrameDriver`, which a vendor subclasses with one method::

    class AcmeDriver(FrameDriver):
        name, schemes = "acme", ("acme",)

        def open_frame_device(self, uri):
            return AcmePlate(...)          # a FrameDevice

What the device must do itself, because the host cannot (spec/conformance.md section 4):
never exceed its hardware limits whatever it is sent, and ramp its outputs to zero when frames
stop arriving for :attr:`FrameDeviceInfo.watchdog_s`, saying so in :attr:`Measurement.faults`.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

import numpy as np

from hcard.device.protocol import FaultBits

MEASURED_FAULTS = (FaultBits.AMPLITUDE_LIMIT | FaultBits.VOLTAGE_LIMIT | FaultBits.CURRENT_LIMIT
                   | FaultBits.WATCHDOG | FaultBits.OVER_TEMPERATURE)
"""The :class:`FaultBits` a frame device may report per frame (its own clamps and watchdog)."""


@dataclass(frozen=True)
class FrameDeviceInfo:
    """What a frame device is: its data sheet.

    Attributes:
        model: the vendor's name of the model, for messages.
        frame_rate_hz: actuator frames per second the device plays, Hz.
        plate_frequency_hz: resonance of the vibrating plate, Hz (0: no UV channel).
        ev_carrier_hz: EV carrier frequency, Hz (0: no EV channel).
        max_amplitude_m: largest plate amplitude, m peak-to-peak (hardware).
        max_voltage_v: largest EV envelope, V (hardware; 0 without EV).
        max_current_a: largest EV current, A (hardware; 0 without EV).
        width_mm, height_mm: the active surface, mm.
        watchdog_s: frames missing this long before the device ramps its outputs to zero, s.
        device_kind: DEVICE_INFO.device_kind the host reports for it (0: none of the kinds the
            protocol names); with the plate frequency it is what a ``device-profile`` plugin
            recognises the device by.
        lateral_force: the device measures the lateral (friction) force.
    """

    model: str
    frame_rate_hz: float
    plate_frequency_hz: float
    ev_carrier_hz: float
    max_amplitude_m: float
    max_voltage_v: float
    max_current_a: float
    width_mm: float
    height_mm: float
    watchdog_s: float
    device_kind: int = 0
    lateral_force: bool = False

    @property
    def has_uv(self) -> bool:
        """The device has a vibrating plate."""
        return self.plate_frequency_hz > 0 and self.max_amplitude_m > 0

    @property
    def has_ev(self) -> bool:
        """The device has an electrovibration channel."""
        return self.ev_carrier_hz > 0 and self.max_voltage_v > 0


@dataclass(frozen=True)
class Measurement:
    """What a frame device's actuators did, one row per frame played.

    Attributes:
        t_s: device time of each frame, s.
        amplitude_m: measured plate amplitude, m peak-to-peak.
        voltage_v: measured EV envelope, V.
        current_a: measured EV current, A.
        lateral_force_n: measured lateral force, N (NaN: no sensor).
        faults: per frame, :class:`FaultBits` of :data:`MEASURED_FAULTS`.
    """

    t_s: np.ndarray
    amplitude_m: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    lateral_force_n: np.ndarray
    faults: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


class FrameDevice(abc.ABC):
    """A device that plays actuator frames and measures its actuators.

    Times are on the device's clock (s, from when it was opened). A simulated device may run
    on its own clock and advance it when asked (:meth:`measure`); a real one runs on the wall
    clock and :meth:`measure` waits.
    """

    info: FrameDeviceInfo

    @abc.abstractmethod
    def clock(self) -> float:
        """Device time now, s."""

    @abc.abstractmethod
    def play(self, first_frame: int, amplitude_m: np.ndarray, voltage_v: np.ndarray) -> None:
        """Queue actuator commands for the frames ``first_frame, first_frame + 1, ...`` (frame k
        plays at ``k / frame_rate_hz`` s): plate amplitude (m peak-to-peak) and EV envelope
        (V). A frame already played is ignored."""

    @abc.abstractmethod
    def measure(self, until_s: float) -> Measurement:
        """The frames played since the last call, up to device time ``until_s`` (s)."""

    def touch(self, t_s: float, x_mm: float, y_mm: float, normal_force_n: float,
              contact: bool) -> None:
        """Where the finger is at device time ``t_s`` (a test rig's finger; a device on a
        real finger ignores it)."""
        del t_s, x_mm, y_mm, normal_force_n, contact

    def close(self) -> None:  # noqa: B027 - a device with nothing to release needs no code
        """Release the device."""
