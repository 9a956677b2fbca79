"""The faults of the faulty device and its URI grammar: ``faulty://FAULT?strength=S``.

Each fault is one defect with a continuous strength in a physical unit (strength 0 is the
fault-free device); ``faulty://none`` is the device without any. A fault lives either in the
simulated hardware (``device``: :mod:`.plate`) or in the driver's rendering on the host
(``driver``: :mod:`.host_faults`), and sets one field of that side's fault record
(:class:`~.plate.PlateFaults`, :class:`~.host_faults.RenderingFaults`) to ``strength *
si_per_unit``.

>>> from hcard.device.uri import parse_uri
>>> setting = parse_fault(parse_uri("faulty://output-latency?strength=30",
...                                 schemes=("faulty",)))
>>> setting.fault.field, round(setting.si_value, 6)
('output_delay_s', 0.03)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hcard.device.errors import UriError
from hcard.device.uri import DeviceUri

SCHEME = "faulty"
"""URI scheme of the faulty device."""
NO_FAULT = "none"
"""Fault name of the device without a fault."""
STRENGTH = "strength"
"""The one URI option: the fault's strength, in the fault's unit."""
DEVICE, DRIVER = "device", "driver"
"""Where a fault lives: the simulated hardware, or the driver's rendering on the host."""


@dataclass(frozen=True)
class Fault:
    """One defect of the faulty device.

    Attributes:
        name: its name in the URI (``faulty://NAME``).
        where: :data:`DEVICE` or :data:`DRIVER`.
        quantity: what the strength measures, in words.
        unit: the strength's unit (``ms``, ``%``, ``nm``, ``deg``, ``mm``, ``Hz``).
        field: the field of the fault record it sets.
        si_per_unit: the field's value per unit of strength (negative: a deficit).
        most: the largest strength accepted (the smallest is 0).
    """

    name: str
    where: str
    quantity: str
    unit: str
    field: str
    si_per_unit: float
    most: float


FAULTS: tuple[Fault, ...] = (
    Fault("output-latency", DEVICE, "latency added between a frame and the plate playing it",
          "ms", "output_delay_s", 1e-3, 1000.0),
    Fault("slow-plate", DEVICE, "time constant added to the plate's amplitude envelope", "ms",
          "added_tau_s", 1e-3, 100.0),
    Fault("weak-plate", DEVICE, "plate amplitude short of the commanded one", "%",
          "uv_gain_error", -0.01, 100.0),
    Fault("plate-overdrive", DEVICE, "plate amplitude beyond the commanded one (the hardware "
          "clamp acts on the command)", "%", "uv_gain_error", 0.01, 100.0),
    Fault("weak-ev", DEVICE, "EV voltage short of the commanded one", "%", "ev_gain_error",
          -0.01, 100.0),
    Fault("late-watchdog", DEVICE, "watchdog acting this long after its data-sheet time", "ms",
          "watchdog_delay_s", 1e-3, 10_000.0),
    Fault("residual-vibration", DEVICE, "plate amplitude left on top of the commanded one", "nm",
          "residual_amplitude_m", 1e-9, 2500.0),
    Fault("touch-lag", DRIVER, "finger samples applied this long after they arrive", "ms",
          "touch_lag_s", 1e-3, 1000.0),
    Fault("touch-offset", DRIVER, "finger position read this far along +x", "mm",
          "touch_offset_mm", 1.0, 120.0),
    Fault("phase-offset", DRIVER, "phase added to every component", "deg", "phase_offset_rad",
          math.pi / 180.0, 180.0),
    Fault("frequency-scale", DRIVER, "every component frequency read this much too high", "%",
          "frequency_error", 0.01, 100.0),
    Fault("amplitude-deficit", DRIVER, "every component amplitude read this much too small",
          "%", "amplitude_error", -0.01, 100.0),
    Fault("depth-deficit", DRIVER, "every target's distance from neutral friction rendered "
          "this much too small", "%", "depth_error", -0.01, 100.0),
    Fault("velocity-locked", DRIVER, "position-locked textures whose shortest period is below "
          "this rendered velocity-locked", "mm", "velocity_locked_below_mm", 1.0, 1000.0),
    Fault("band-limit", DRIVER, "band limit raised above the required 1000 Hz (the fade of "
          "components near it moved up)", "Hz", "band_limit_excess_hz", 1.0, 3000.0),
)
"""Every fault, device faults first. ``band-limit``'s largest strength keeps the raised band
limit within 0.4 x the device's 10 kHz frame rate (spec/README.md R1)."""

FAULTS_BY_NAME = {fault.name: fault for fault in FAULTS}


@dataclass(frozen=True)
class FaultSetting:
    """The fault a URI names and its strength.

    Attributes:
        fault: the fault, None for ``faulty://none``.
        strength: in the fault's unit (0 for none).
    """

    fault: Fault | None
    strength: float

    @property
    def si_value(self) -> float:
        """The value of the fault record's field (SI units, signed), 0 without a fault."""
        return 0.0 if self.fault is None else self.strength * self.fault.si_per_unit

    def on(self, where: str) -> dict[str, float]:
        """The fault record fields this setting changes on ``where`` (``device``/``driver``)."""
        if self.fault is None or self.fault.where != where:
            return {}
        return {self.fault.field: self.si_value}


def fault_uri(name: str, strength: float) -> str:
    """The URI of fault ``name`` at ``strength`` (its unit)."""
    return f"{SCHEME}://{name}?{STRENGTH}={strength:g}"


def _bad(uri: DeviceUri, reason: str) -> UriError:
    return UriError(f"bad device URI {uri.text!r}: {reason} (expected e.g. "
                    f"{fault_uri('output-latency', 30)} or {SCHEME}://{NO_FAULT})")


def parse_fault(uri: DeviceUri) -> FaultSetting:
    """The fault and strength ``uri`` names (``faulty://FAULT?strength=S``,
    ``faulty://none``).

    Raises:
        UriError: a path, an unknown fault or option, a missing strength, or a strength that
            is not a number within the fault's range; the message names the option and what
            it allows.
    """
    if uri.path not in ("", "/"):
        raise _bad(uri, f"{SCHEME}:// takes no path (got {uri.path!r})")
    name = uri.host
    known = ", ".join((NO_FAULT, *FAULTS_BY_NAME))
    unknown = sorted(set(uri.options) - {STRENGTH})
    if unknown:
        raise _bad(uri, f"unknown option {unknown[0]!r} (the one option is {STRENGTH})")
    if name == NO_FAULT:
        if STRENGTH in uri.options:
            raise _bad(uri, f"fault {NO_FAULT} takes no option {STRENGTH}")
        return FaultSetting(None, 0.0)
    if not name:
        raise _bad(uri, f"the URI names no fault (known: {known})")
    if name not in FAULTS_BY_NAME:
        raise _bad(uri, f"unknown fault {name!r} (known: {known})")
    fault = FAULTS_BY_NAME[name]
    allowed = (f"the {fault.quantity}, {fault.unit}: a number in [0, {fault.most:g}]")
    text = uri.options.get(STRENGTH)
    if text is None:
        raise _bad(uri, f"option {STRENGTH} is required: {allowed}")
    try:
        strength = float(text)
    except ValueError:
        strength = math.nan
    if not (math.isfinite(strength) and 0.0 <= strength <= fault.most):
        raise _bad(uri, f"option {STRENGTH}={text!r} must be {allowed}")
    return FaultSetting(fault, strength)
