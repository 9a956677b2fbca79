"""Negative-control drivers: deliberately faulty implementations the suite must fail.

They exist to prove that the conformance checks can fail (DESIGN.md section 7; issue 6 item 5).
Each is the in-process ``sim://`` device with one documented defect; none is a conforming device.
Open them with :func:`open_control` (``hcard conformance --driver control:NAME``):

``position-only``
    The E-ViTa whose renderer runs the position-only baseline (``RenderOptions(mode=
    "position-only")``) on the 50 Hz touch samples: the texture under the last touch sample,
    held for 20 ms, without dead reckoning or velocity-integrated phase. Dense textures alias;
    coarse ones are right away from taxtel boundaries.
``latency-30ms``
    The E-ViTa behind a transport that holds every FINGER report for 30 ms of device time
    before the firmware sees it (a slow host stack).
``no-ev``
    The coupled UV+EV stimulator whose firmware ignores the EV channel: it advertises EV but
    renders every EV target as 1 (no electrovibration), so friction increases never happen.
``over-limit``
    The E-ViTa whose firmware accepts and reports a lowered LIMITS request but never applies it
    to the plate loop or the model-based rendering: the plate goes up to the hardware limit
    whatever the host set.
"""

from __future__ import annotations

import collections
from collections.abc import Callable

import numpy as np

from hcard.render import RenderMode, RenderOptions
from hcard_device.drivers.base import DEFAULT_TIMEOUT_S
from hcard_device.drivers.sim import SimDriver
from hcard_device.drivers.uri import parse_uri
from hcard_device.firmware import Firmware
from hcard_device.protocol import ReportId
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim.simulation import Limits

ADDED_LATENCY_S = 0.030
"""Delay the ``latency-30ms`` control adds to every FINGER report, s."""


class PositionOnlySimulation(DeviceSimulation):
    """A device whose renderer is the position-only baseline (test control, not conforming)."""

    def __init__(self, config: DeviceConfig, seed: int = 0) -> None:
        super().__init__(config, seed)
        self._options = RenderOptions(frame_rate_hz=config.frame_rate_hz,
                                      mode=RenderMode.POSITION_ONLY)


class NoEVSimulation(DeviceSimulation):
    """A coupled device whose firmware drops every EV target to 1 (test control)."""

    def _targets(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        uv, _ev, texture = super()._targets(n)
        return uv, np.ones(n), texture


class UnenforcedLimitsSimulation(DeviceSimulation):
    """A device that reports host-set limits but keeps enforcing only its hardware limits
    (test control: it violates spec rule PS1 whenever the host lowers a limit).

    :attr:`limits` (what LIMITS answers) is the host's request; the commands, the plate
    loop's clamp, the amplifier and the model-based rendering keep the hardware limits.
    """

    def __init__(self, config: DeviceConfig, seed: int = 0) -> None:
        super().__init__(config, seed)
        self._reported = self.hardware_limits

    @property
    def limits(self) -> Limits:
        """The limits the device claims to enforce (the host's last request)."""
        return self._reported

    def set_limits(self, max_amplitude_m: float | None = None,
                   max_voltage_v: float | None = None,
                   max_current_a: float | None = None) -> Limits:
        self._reported = super().set_limits(max_amplitude_m, max_voltage_v, max_current_a)
        super().set_limits(*(getattr(self.hardware_limits, name) for name in
                             ("max_amplitude_m", "max_voltage_v", "max_current_a")))
        return self._reported


class DelayedFingerDriver(SimDriver):
    """``sim://`` with every FINGER report held for :data:`ADDED_LATENCY_S` of device time."""

    def __init__(self, *args: object, delay_s: float = ADDED_LATENCY_S, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.delay_s = float(delay_s)
        self._held: collections.deque[tuple[float, bytes]] = collections.deque()

    def _write_output(self, report: bytes) -> None:
        if report and report[0] == ReportId.FINGER:
            self._held.append((self.clock() + self.delay_s, bytes(report)))
            return
        super()._write_output(report)

    def advance(self, seconds: float) -> None:
        """Run the device, delivering each held FINGER report when its delay has passed."""
        target = self.clock() + max(seconds, 0.0)
        while self._held and self._held[0][0] <= target:
            due, report = self._held.popleft()
            if due > self.clock():
                super().advance(due - self.clock())
            self.firmware.handle_output(report)
        if target > self.clock():
            super().advance(target - self.clock())


def _sim_driver(simulation: DeviceSimulation, uri: str,
                cls: type[SimDriver] = SimDriver) -> SimDriver:
    return cls(parse_uri(uri), Firmware(simulation), timeout_s=DEFAULT_TIMEOUT_S)


CONTROLS: dict[str, Callable[[], SimDriver]] = {
    "position-only": lambda: _sim_driver(PositionOnlySimulation(DeviceConfig.evita()), "sim://"),
    "latency-30ms": lambda: _sim_driver(DeviceSimulation(DeviceConfig.evita()), "sim://",
                                        DelayedFingerDriver),
    "no-ev": lambda: _sim_driver(NoEVSimulation(DeviceConfig.coupled()), "sim://coupled"),
    "over-limit": lambda: _sim_driver(UnenforcedLimitsSimulation(DeviceConfig.evita()),
                                      "sim://"),
}
"""The negative controls by name (see the module docstring)."""


def open_control(name: str) -> SimDriver:
    """Open the negative-control driver ``name`` (``position-only``, ``latency-30ms``,
    ``no-ev``, ``over-limit``; a ``control:`` prefix is accepted).

    Raises:
        ValueError: unknown control name.
    """
    key = name.removeprefix("control:")
    if key not in CONTROLS:
        raise ValueError(f"unknown negative control {name!r}; known: {', '.join(CONTROLS)}")
    return CONTROLS[key]()
