"""``sim://`` (``sim://evita``, ``sim://coupled?seed=1``): the device in this process.

The firmware and its simulation run on the driver's clock, not the wall clock: waiting for an
input report, :meth:`SimDriver.collect_until` and idling advance the simulation by exactly the
time asked (1 ms at a time while waiting for a report), so a track plays as fast as the CPU
allows and the outcome is reproducible for a seed. Reports and feature requests take the same
codec and firmware paths as over USB; a feature request the firmware refuses raises
:class:`DeviceStall`, as the USB STALL does.
"""

from __future__ import annotations

import collections
from collections.abc import Sequence
from typing import Any

from hcard_device.drivers.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard_device.drivers.errors import DeviceStall
from hcard_device.drivers.uri import DeviceUri, parse_uri
from hcard_device.protocol import INPUT_RATE_HZ, ProtocolError, State
from hcard_device.usb.device import PRODUCTS
from hcard_device.usb.server import make_firmware

STEP_S = 1.0 / INPUT_RATE_HZ
"""Simulated time advanced per step while waiting for an input report, s (one report period)."""
CHUNK_S = 0.010
"""Longest single advance of the firmware before its input reports are collected, s."""
PENDING_CAPACITY = 65_536
"""Input reports held for the host before the oldest are dropped (65 s at 1 kHz)."""


class SimDriver(Driver):
    """The in-process driver (see the module docstring).

    Attributes:
        firmware: the :class:`~hcard_device.firmware.Firmware` it drives.
    """

    name = "sim"
    description = "in-process firmware and simulation on the driver's clock: sim://[evita|coupled]"
    schemes = ("sim",)
    realtime = False

    def __init__(self, uri: DeviceUri, firmware: Any, *,
                 timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.firmware = firmware
        self._time_s = 0.0
        self._pending: collections.deque[bytes] = collections.deque(maxlen=PENDING_CAPACITY)

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> SimDriver:
        uri = parse_uri(uri) if isinstance(uri, str) else uri
        return cls(uri, make_firmware(uri.variant, uri.seed, uri.effects),
                   timeout_s=timeout_s)

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (),
                  *, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """The in-process devices, always available."""
        return [DeviceListing(f"sim://{variant}", cls.name, f"in-process {product}")
                for variant, product in PRODUCTS.items()]

    # ---- the clock --------------------------------------------------------------------

    def clock(self) -> float:
        """Simulated time since the driver opened, s."""
        return self._time_s

    def advance(self, seconds: float) -> None:
        """Run the device for ``seconds`` of simulated time, collecting its input reports."""
        target = self._time_s + max(seconds, 0.0)
        while self._time_s < target:
            step = min(target - self._time_s, CHUNK_S)
            self.firmware.advance(step)
            # land exactly on the target: rounding must never leave the clock just short of it
            self._time_s = target if target - self._time_s - step < 1e-12 else self._time_s + step
            self._pending.extend(self.firmware.take_input_reports())

    def _idle(self, seconds: float) -> None:
        self.advance(seconds)

    def collect_until(self, t_s: float) -> list[State]:
        if t_s > self._time_s:
            self.advance(t_s - self._time_s)
        states = []
        while self._pending:
            state = self.parse_input(self._pending.popleft())
            if state is not None:
                states.append(state)
        return states

    # ---- transport primitives: direct firmware calls ---------------------------------

    def _write_output(self, report: bytes) -> None:
        self.firmware.handle_output(report)

    def _set_feature(self, report: bytes) -> None:
        try:
            self.firmware.set_feature(report)
        except ProtocolError as exc:
            raise DeviceStall(f"{self.uri}: the device refused the SET_REPORT ({exc})") from None

    def _get_feature(self, report_id: int, size: int) -> bytes:
        try:
            return bytes(self.firmware.get_feature(report_id))[:size]
        except ProtocolError as exc:
            raise DeviceStall(f"{self.uri}: the device refused the GET_REPORT ({exc})") from None

    def _read_input(self, timeout_s: float) -> bytes | None:
        waited = 0.0
        while not self._pending and waited < timeout_s - 1e-12:
            step = min(STEP_S, timeout_s - waited)
            self.advance(step)
            waited += step
        return self._pending.popleft() if self._pending else None

    def _close(self) -> None:
        self._pending.clear()
