"""``sim://`` (``sim://evita``, ``sim://coupled?seed=1``): the device in this process.

The firmware and its simulation run on the driver's clock, not the wall clock: waiting for an
input report, :meth:`SimDriver.collect_until` and idling advance the simulation by exactly the
time asked (1 ms at a time while waiting for a report), so a track plays as fast as the CPU
allows and the outcome is reproducible for a seed. Reports and feature requests take the same
codec and firmware paths as over USB; a feature request the firmware refuses raises
:class:`DeviceStall`, as the USB STALL does.

The driver also provides the host library's devices simulated in this process
(:mod:`hcard.device.in_process`): it checks the model options of ``sim://`` and ``loopback``
URIs (:meth:`SimDriver.resolve_model`) and serves the device of a ``loopback`` URI in this
process (:meth:`SimDriver.serve_in_process`).

Descriptors (:meth:`SimDriver.report_descriptor`, :meth:`SimDriver.hid_descriptor`; protocol
PD1, PD2) are read with GET_DESCRIPTOR control transfers from the USB device the reference
device serves around this firmware (:func:`~hcard_device.usb.device.build_usb_device`, built
when first asked, never plugged in): the bytes a USB host would read.

Every ``sim://`` URI opens a new device. :meth:`SimDriver.another_host` opens a second host on
the same device (a :class:`SharedDevice`: one clock, every host gets every STATE report, as two
processes that open one hidraw node; spec rule PN10), for checks of session ownership.
"""

from __future__ import annotations

import collections
import re
import struct
from collections.abc import Callable, Sequence
from typing import Any

from usbip.core import Urb
from usbip.device import IN

from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing, Driver
from hcard.device.errors import DeviceError, DeviceStall
from hcard.device.protocol import INPUT_RATE_HZ, ProtocolError, State
from hcard.device.transports.usb_descriptors import read_hid_descriptor, read_report_descriptor
from hcard.device.uri import DeviceUri, ambient_pressure, parse_uri, uri_error
from hcard_device.usb.device import PRODUCTS, STALL_STATUS, build_usb_device
from hcard_device.usb.server import DeviceServer, make_firmware

STEP_S = 1.0 / INPUT_RATE_HZ
"""Simulated time advanced per step while waiting for an input report, s (one report period)."""
CHUNK_S = 0.010
"""Longest single advance of the firmware before its input reports are collected, s."""
PENDING_CAPACITY = 65_536
"""Input reports held for the host before the oldest are dropped (65 s at 1 kHz)."""
HID_INTERFACE = 0
"""bInterfaceNumber of the reference device's one HID interface."""


class SharedDevice:
    """One simulated device and its clock, shared by the hosts (drivers) attached to it.

    Attributes:
        firmware: the :class:`~hcard_device.firmware.Firmware`.
        time_s: simulated time since the device was opened, s.
    """

    def __init__(self, firmware: Any) -> None:
        self.firmware = firmware
        self.time_s = 0.0
        self._queues: list[collections.deque[bytes]] = []
        self._watches: list[tuple[Callable[[], bool], Callable[[], None]]] = []

    def attach(self) -> collections.deque[bytes]:
        """A new host's input queue: it gets every STATE report produced from now on."""
        queue: collections.deque[bytes] = collections.deque(maxlen=PENDING_CAPACITY)
        self._queues.append(queue)
        return queue

    def detach(self, queue: collections.deque[bytes]) -> None:
        """A host closed: stop feeding its queue."""
        self._queues = [q for q in self._queues if q is not queue]  # by identity

    def call_when(self, due: Callable[[], bool], action: Callable[[], None]) -> None:
        """Run ``action`` once, between two steps of :meth:`advance`, when ``due()`` holds:
        another host acting at a chosen moment of a session driven by this one."""
        self._watches.append((due, action))

    def advance(self, seconds: float) -> None:
        """Run the device for ``seconds`` of simulated time (in steps of at most
        :data:`CHUNK_S`), handing its input reports to every attached host."""
        target = self.time_s + max(seconds, 0.0)
        while self.time_s < target:
            step = min(target - self.time_s, CHUNK_S)
            self.firmware.advance(step)
            # land exactly on the target: rounding must never leave the clock just short of it
            self.time_s = target if target - self.time_s - step < 1e-12 else self.time_s + step
            reports = self.firmware.take_input_reports()
            for queue in self._queues:
                queue.extend(reports)
            self._run_watches()

    def _run_watches(self) -> None:
        for watch in list(self._watches):
            due, action = watch
            if due():
                self._watches.remove(watch)
                action()  # may advance the device itself (time only moves forward)


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
                 timeout_s: float = DEFAULT_TIMEOUT_S, device: SharedDevice | None = None) -> None:
        super().__init__(uri, timeout_s=timeout_s)
        self.device = device if device is not None else SharedDevice(firmware)
        self.firmware = self.device.firmware
        self._pending = self.device.attach()
        self._usb_device: Any = None  # built on the first descriptor request

    def another_host(self) -> SimDriver:
        """A second host on this driver's device (same firmware and clock, its own copy of
        every STATE report from now on; spec rule PN10). Close it like any driver."""
        return type(self)(self.uri, self.firmware, timeout_s=self.timeout_s, device=self.device)

    @classmethod
    def resolve_model(cls, uri: DeviceUri, variant: str, options: dict[str, str]) -> DeviceUri:
        """``uri`` with its model options (``device``, ``seed``, ``effect``, ``EFFECT.PARAM``,
        ``ambient_pressure``) checked and the hidden effects resolved with their defaults
        (:mod:`.sim.hidden`).

        Raises:
            UriError: an unknown option, device or effect, a bad seed or parameter value.
        """
        from hcard_device.sim.hidden import HiddenEffectError, parse_assignments, resolve

        text = uri.text
        assignments = [f"{key}={value}" for key, value in options.items() if "." in key]
        unknown = sorted(set(options) - {"device", "seed", "effect", "ambient_pressure"}
                         - {k for k in options if "." in k})
        if unknown:
            raise uri_error(text, uri.scheme, f"unknown option(s) {', '.join(unknown)} "
                            "(known: device, seed, effect, EFFECT.PARAM, ambient_pressure)")
        if variant not in PRODUCTS:
            raise uri_error(text, uri.scheme,
                            f"unknown device {variant!r} (known: {', '.join(PRODUCTS)})")
        seed_text = options.get("seed", "0")
        if not re.fullmatch(r"[0-9]+", seed_text):
            raise uri_error(text, uri.scheme, f"seed {seed_text!r} is not a non-negative integer")
        names = [name.strip() for name in options.get("effect", "").split(",") if name.strip()]
        try:
            effects = resolve(variant, parse_assignments(names, assignments))
        except HiddenEffectError as exc:
            raise uri_error(text, uri.scheme, str(exc)) from None
        pressure = None
        if "ambient_pressure" in options:
            try:
                pressure = ambient_pressure(options["ambient_pressure"])
            except ValueError as exc:
                raise uri_error(text, uri.scheme, str(exc)) from None
        return DeviceUri(uri.text, uri.scheme, host=uri.host, port=uri.port, busid=uri.busid,
                         variant=variant, seed=int(seed_text), effects=effects, options=options,
                         ambient_pressure_pa=pressure)

    @classmethod
    def serve_in_process(cls, uri: DeviceUri) -> DeviceServer:
        """Start the device of a ``loopback`` URI in this process (the driver that connects
        through it stops it)."""
        server = DeviceServer(variant=uri.variant, seed=uri.seed, loopback=True,
                              effects=uri.effects, ambient_pressure_pa=uri.ambient_pressure_pa)
        server.start()
        return server

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> SimDriver:
        uri = parse_uri(uri) if isinstance(uri, str) else uri
        return cls(uri, make_firmware(uri.variant, uri.seed, uri.effects,
                                      ambient_pressure_pa=uri.ambient_pressure_pa),
                   timeout_s=timeout_s)

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (),
                  *, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """The in-process devices, always available."""
        return [DeviceListing(f"sim://{variant}", cls.name, f"in-process {product}")
                for variant, product in PRODUCTS.items()]

    # ---- the clock --------------------------------------------------------------------

    def clock(self) -> float:
        """Simulated time since the device was opened, s (shared by its hosts)."""
        return self.device.time_s

    def advance(self, seconds: float) -> None:
        """Run the device for ``seconds`` of simulated time, collecting its input reports."""
        self.device.advance(seconds)

    def _idle(self, seconds: float) -> None:
        self.advance(seconds)

    def collect_until(self, t_s: float) -> list[State]:
        if t_s > self.clock():
            self.advance(t_s - self.clock())
        states = []
        while self._pending:
            state = self.accept_input(self._pending.popleft())
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

    def _control_in(self, request_type: int, request: int, value: int, index: int,
                    length: int) -> bytes:
        """A standard control-IN request answered by the USB device served around this
        firmware (module docstring), as a USB/IP server answers it; a STALL raises
        :class:`DeviceStall`."""
        if self._usb_device is None:
            variant = self.uri.variant if self.uri.variant in PRODUCTS else "evita"
            self._usb_device, _interface = build_usb_device(self.firmware, variant)
        setup = struct.pack("<BBHHH", request_type, request, value, index, length)
        urb = self._usb_device.handle_urb(Urb(direction=IN, ep=0, setup=setup, length=length))
        if urb.status == STALL_STATUS:
            raise DeviceStall(f"{self.uri}: the device STALLed control request "
                              f"0x{request:02X} (wValue 0x{value:04X})")
        if urb.status:
            raise DeviceError(f"{self.uri}: control request 0x{request:02X} failed "
                              f"(status {urb.status})")
        return bytes(urb.buffer[:urb.actual])

    def _report_descriptor(self) -> bytes:
        return read_report_descriptor(self._control_in, HID_INTERFACE)

    def _hid_descriptor(self) -> bytes:
        return read_hid_descriptor(self._control_in, HID_INTERFACE)

    def _close(self) -> None:
        self._pending.clear()
        self.device.detach(self._pending)
