"""Fault and status bit flags the simulation reports per frame (and the firmware forwards)."""

from __future__ import annotations

from enum import IntFlag


class Faults(IntFlag):
    """Bit flags of a frame's faults.

    Attributes:
        AMPLITUDE_LIMIT: the plate amplitude command was held at the amplitude limit, or the
            hard clamp on the plate cut or limited the drive (the amplitude never exceeds it).
        VOLTAGE_LIMIT: the EV envelope was held at the voltage limit or slew-rate limited.
        CURRENT_LIMIT: the EV envelope was lowered so that the user current stays below the
            current limit (``i = C dv/dt``).
        WATCHDOG: no host report within the watchdog time; outputs ramp (or are) at zero.
        CARD_CLIPPED: the loaded card asks for more than the device can render (see the clip
            report of :meth:`DeviceSimulation.load_card`), or this frame's target needs a
            channel the device lacks.
        STREAM_OVERRUN: streamed frames were dropped (queue full) since the last report.
        OVER_TEMPERATURE: reserved (the simulation has no thermal model).
        INVALID_REQUEST: a command carried invalid values (NaN, negative limits, out-of-range
            targets), which were replaced by safe ones.
    """

    NONE = 0
    AMPLITUDE_LIMIT = 1 << 0
    VOLTAGE_LIMIT = 1 << 1
    CURRENT_LIMIT = 1 << 2
    WATCHDOG = 1 << 3
    CARD_CLIPPED = 1 << 4
    STREAM_OVERRUN = 1 << 5
    OVER_TEMPERATURE = 1 << 6
    INVALID_REQUEST = 1 << 7
