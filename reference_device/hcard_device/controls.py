"""Negative-control drivers: deliberately faulty implementations the suite must fail.

They exist to prove that the conformance checks can fail (spec/conformance.md section 6, rule QN1).
Each is the in-process ``sim://`` device with one documented defect; none is a conforming device.
They are the reference device's driver of the URI scheme ``control`` (:class:`ControlDriver`,
registered with its other plugins), so ``hcard conformance --driver control:NAME`` and
:func:`hcard.device.open_device` reach them like any device; :func:`open_control` opens one by
name:

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
``swapped-channels``
    The coupled stimulator whose firmware hands the UV target stream to the EV actuation and
    the EV stream to the UV actuation (and reports them as it routed them): friction
    decreases go to electrovibration, which can only raise friction, and increases to the
    plate, which can only lower it, so neither happens.
``inverted-phase``
    The E-ViTa whose renderer adds half a cycle to every component's phase (a sign slip in
    ``cos(2 pi cycles + phase)``): every grating sits half a period off the card's.
``frequency-off``
    The E-ViTa whose renderer reads every component's frequency 15 % high (a scale slip):
    gratings come out with a 13 % shorter period.
``weak-actuator``
    The E-ViTa whose piezo delivers 35 % of the full-drive amplitude the firmware's plate
    loop was tuned for (an actuator far off its gain): the loop responds slower and the
    plate saturates below the amplitudes the rendering asks for.
``ignored-watchdog``
    The E-ViTa whose main loop feeds its own watchdog every frame (instead of on host
    reports, rule PS3): a silent host leaves the plate driven.
``late-limits``
    The E-ViTa as it was before rule PS5: a lowered LIMITS request is in force at once for new
    commands, but the plate is not braked: its drive is only cut and it decays at its own rate
    (tau 1.57 ms), so the reports of the next few milliseconds after lowering the amplitude
    limit while driven show the plate above it. Limits set at rest are honoured.
``no-ownership``
    The E-ViTa as it was before protocol 1.2 sessions (it reports 1.1): a second host's START
    and upload are carried out under the first host's session, and TAKE_OVER is unknown.
    Served over USB/IP in this process (one device, any number of drivers; see
    :mod:`hcard_device.served_controls`), since two ``sim://`` drivers never share one.
``no-attribution``
    The E-ViTa with sessions (protocol 1.4) whose firmware is not told which USB/IP connection
    a request came from: sessions are kept by token alone (PN1-PN9 hold), but another
    connection's FINGER, KEEPALIVE, START or STOP with the owner's token and SET of LIMITS are
    carried out under the owner's session and its KEEPALIVEs keep a silent owner's session
    alive (PN12, PN13 broken). Served over USB/IP in this process like ``no-ownership``.
``shared-halts``
    The E-ViTa served over USB/IP like ``no-ownership``, whose interrupt-OUT endpoint has one
    halt for all its connections (PN14 broken): another connection's ENDPOINT_HALT STALLs the
    session owner's output reports, and any SET_CONFIGURATION clears it.
``blocking-writes``
    The E-ViTa served over USB/IP like ``no-ownership``, whose connections write each answer
    with a send that waits for the client (PN15 broken): a client that parks IN URBs and stops
    reading stops every connection's STATE stream.
``accepts-bad-crc``
    The E-ViTa whose upload store never compares the CRC-32 of the received bytes with the one
    UPLOAD_BEGIN declared (protocol PU3, 9.3): a card whose CRC is wrong is committed, as long
    as its length is right and it parses. Fails ``device.upload-integrity`` case ``bad-crc``.
``reads-any-major``
    The E-ViTa whose card check reads a card of any major version as if it were version 1
    (protocol PU3 and README V1 ask it to refuse a major version it does not read with
    INVALID_CARD): a well-formed card of major version 2 is committed and played. Fails
    ``device.upload-integrity`` case ``unknown-major`` and passes the others.
``silent-refusals``
    The E-ViTa whose firmware ignores a malformed or refused output report without counting it
    in ``rejected_requests`` or flagging INVALID_REQUEST (protocol PE2): the host never learns
    that what it sent was not carried out. Fails ``device.refusals`` (``short-report`` among
    others).
``unplayed-commit``
    The E-ViTa whose renderer never takes the card a COMMIT puts in force: the upload is
    checked and committed as PU3 asks (UPLOAD_STATUS COMMITTED with its CRC-32 and the next
    generation, STATE CARD_LOADED and that generation), but the plate goes on rendering what it
    rendered before (nothing, neutral friction, on a fresh device). Fails
    ``device.upload-integrity`` (U2, U3: every case, its card A never plays).
``profile-raises-limits``
    The E-ViTa that puts a host's device profile in force with the profile's own ``limits``
    (clamped only to its hardware limits), in place of the limits the host set with LIMITS
    (protocol PU10: a profile never raises a limit): after a host lowered the limits, a
    profile written for the device's full range drives the plate past them. Fails
    ``device.profile-upload`` case ``limits-not-raised``.
``sticky-profile``
    The E-ViTa whose CONTROL DEVICE_PROFILE clears the state flag HOST_PROFILE but keeps
    rendering with the host's profile (protocol PU11: the device's own profile goes back in
    force): every later recording says "the device's own profile" of what the host's rendered.
    Fails ``device.profile-upload`` case ``own-profile-restored``.
``misdeclared-state``
    The E-ViTa whose report descriptor declares the STATE input report one byte short (Report
    Count 57 for the 58 bytes after its ID: :func:`state_declared_short`), an off-by-one in the
    firmware's descriptor table (protocol PD1, PD2). The reports themselves are the reference
    device's; a host stack that sizes its input buffers from the descriptor cannot take a STATE
    report whole. Fails ``device.descriptor`` (``declares-reports``, ``exact-bytes``).
``wrapped-forces``
    The E-ViTa whose force readout keeps the low 16 bits of each corner force in mN (an
    integer cast where the firmware should saturate, protocol PI2): a corner loaded past
    32.767 N reads negative, a finger pressing the plate as one pulling it. Fails
    ``device.saturation`` (``corner-force``).
``drops-reports``
    The E-ViTa whose firmware loses :data:`DROPPED_FRACTION` of its STATE reports at random as
    it produces them (an IN endpoint starved by the firmware's main loop), and counts them
    honestly as PT5 asks: the sequence advances over them, COUNTERS ``input_dropped`` and
    STATE ``dropped_reports`` count them, the next report sent carries INPUT_DROPPED. Fails
    ``device.report-loss`` case ``loss-fraction``, passes ``sequence-gaps`` and
    ``drops-counted``.

The controls of the host driver (``host-accepts-any-major``, ``host-refuses-newer-minor``,
``host-crashes-on-short-report``, ``host-barges-in``) are the conforming device behind a
``sim://`` driver with one defect in its protocol logic: :mod:`hcard_device.host_controls`.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from google.protobuf.message import DecodeError

from hcard.device.base import DEFAULT_TIMEOUT_S, DeviceListing
from hcard.device.errors import UriError
from hcard.device.protocol import REPORT_DESCRIPTOR, FaultBits, ReportId, State, crc32
from hcard.device.protocol.descriptor import report_count, report_id, usage
from hcard.device.protocol.upload import UploadStore
from hcard.device.uri import DeviceUri, parse_uri
from hcard.physics.card_clipping import ClipReport
from hcard.physics.profile import DeviceProfile
from hcard.render import RenderMode, RenderOptions
from hcard.v1 import card_pb2 as pb
from hcard_conformance import check_names
from hcard_device.card_check import CardOutcome, InlineChecker
from hcard_device.firmware import Firmware
from hcard_device.host_controls import (
    AnyMajorHostDriver,
    BargingDriver,
    NewerMinorRefusingDriver,
    ShortReportCrashingDriver,
)
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim.simulation import Limits, PreparedCard, SimBlock
from hcard_device.sim_driver import SimDriver

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


def _remap_card(card: pb.Card, change: Callable[[pb.Texture, pb.Component | None], None]
                ) -> pb.Card:
    """A copy of ``card`` with ``change(texture, component)`` applied to every texture
    (component None) and every component."""
    mapped = pb.Card()
    mapped.CopyFrom(card)
    for texture in mapped.textures:
        change(texture, None)
        for component in texture.components:
            change(texture, component)
    return mapped


Misread = Callable[[pb.Texture, "pb.Component | None"], None]
"""A card-reading defect: changes a component (or, given None, its texture) in place."""


class CardMisreadSimulation(DeviceSimulation):
    """A device whose firmware misreads every card it loads with ``misread`` (test control)."""

    def __init__(self, config: DeviceConfig, misread: Misread, seed: int = 0) -> None:
        super().__init__(config, seed)
        self.misread = misread

    def load_prepared(self, prepared: PreparedCard) -> ClipReport:
        """Every card goes into force through here (a COMMIT compiles the card elsewhere,
        rule PU12): the misread card is compiled again, as this firmware reads it."""
        return super().load_prepared(self.prepare_card(_remap_card(prepared.card,
                                                                   self.misread)))


class SwappedChannelsSimulation(DeviceSimulation):
    """UV targets routed to the EV actuation and EV targets to the UV actuation
    (``swapped-channels``)."""

    def _targets(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        uv, ev, texture = super()._targets(n)
        return ev, uv, texture


def invert_phase(_texture: pb.Texture, component: pb.Component | None) -> None:
    """Half a cycle added to every component's phase (``inverted-phase``)."""
    if component is not None:
        component.phase = math.remainder(component.phase + math.pi, 2 * math.pi)


FREQUENCY_ERROR = 1.15
"""Factor the ``frequency-off`` control applies to every component frequency."""


def raise_frequency(_texture: pb.Texture, component: pb.Component | None) -> None:
    """Every component frequency read :data:`FREQUENCY_ERROR` times too high
    (``frequency-off``)."""
    if component is not None:
        component.frequency *= FREQUENCY_ERROR


ACTUATOR_GAIN = 0.35
"""Fraction of the nominal full-drive amplitude the ``weak-actuator`` control's piezo gives."""


class WeakActuatorSimulation(DeviceSimulation):
    """A plate whose full-drive amplitude is :data:`ACTUATOR_GAIN` of the one its PI loop was
    tuned for (``weak-actuator``); firmware, profile and limits are the nominal device's."""

    def __init__(self, config: DeviceConfig, seed: int = 0) -> None:
        super().__init__(config, seed)
        nominal = self.plate.plate
        self.plate.plate = dataclasses.replace(
            nominal, full_drive_amplitude_m=nominal.full_drive_amplitude_m * ACTUATOR_GAIN)


class SelfFedWatchdogSimulation(DeviceSimulation):
    """A firmware that feeds its watchdog from its own main loop (``ignored-watchdog``)."""

    def step(self, n_frames: int) -> SimBlock:
        self.feed_watchdog()
        return super().step(n_frames)


class LateLimitsSimulation(DeviceSimulation):
    """A device that puts a lowered limit in force at once and lets the plate decay to it at
    its own rate (``late-limits``; test control: it violates PS1 for ``tau ln(A / L)`` after
    lowering the amplitude limit ``L`` under the amplitude ``A`` while driven, and PS5)."""

    def __init__(self, config: DeviceConfig, seed: int = 0) -> None:
        super().__init__(config, seed)
        self.plate.brake_drive = 0.0  # the drive is cut, never reversed

    def set_limits(self, max_amplitude_m: float | None = None,
                   max_voltage_v: float | None = None,
                   max_current_a: float | None = None) -> Limits:
        limits = super().set_limits(max_amplitude_m, max_voltage_v, max_current_a)
        self._commit_limits()  # in force whatever the plate does: the SET completes at once
        return limits


class UnplayedCardSimulation(DeviceSimulation):
    """A renderer that never takes a card (``unplayed-commit``): every card goes into force
    through :meth:`load_prepared`, which here leaves the one rendered before."""

    def load_prepared(self, prepared: PreparedCard) -> ClipReport:
        """Nothing changes: the card is reported committed and never played."""
        return self.clip_report


class ProfileLimitsSimulation(DeviceSimulation):
    """A device whose host profile brings its own limits (``profile-raises-limits``; test
    control: it violates PU10 and, with limits the host lowered, PS1)."""

    def set_profile(self, profile: DeviceProfile | None) -> ClipReport:
        """The profile in force, and its ``limits`` as the limits in force (up to the
        hardware's): the defect."""
        if profile is not None and profile.limits is not None:
            limits = profile.limits
            self.set_limits(limits.max_amplitude, limits.max_voltage, limits.max_current)
        return super().set_profile(profile)


class StickyProfileSimulation(DeviceSimulation):
    """A device that reports its own profile back in force after DEVICE_PROFILE (HOST_PROFILE
    clear) but goes on rendering with the host's last one (``sticky-profile``)."""

    def __init__(self, config: DeviceConfig, seed: int = 0) -> None:
        self._kept: DeviceProfile | None = None
        super().__init__(config, seed)

    def set_profile(self, profile: DeviceProfile | None) -> ClipReport:
        """Remember a host's profile for good; None clears the flag only."""
        if profile is not None:
            self._kept = profile
        return super().set_profile(profile)

    def _profile_in_force(self) -> DeviceProfile:
        """The host's last profile at the limits in force, once one was given: the defect."""
        own = super()._profile_in_force()
        return own if self._kept is None else self._kept.replace(limits=own.limits)


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


class NoCrcUploadStore(UploadStore):
    """An upload store that skips the CRC-32 comparison of PU3 (``accepts-bad-crc``): before
    a COMMIT is judged, the declared CRC-32 is replaced by that of the bytes received, so the
    comparison always holds; length and card checks stay."""

    def _staged(self, now_s: float) -> bytearray | None:
        self.expected_crc = crc32(bytes(self._staging))
        return super()._staged(now_s)


def _no_crc_firmware(simulation: DeviceSimulation) -> Firmware:
    """The firmware of ``accepts-bad-crc``: the reference one with :class:`NoCrcUploadStore`."""
    firmware = Firmware(simulation)
    firmware.upload = NoCrcUploadStore(firmware.upload.max_card_bytes)
    return firmware


class AnyMajorChecker(InlineChecker):
    """A card check that reads every major version as 1 (``reads-any-major``): the version is
    overwritten before the reference check runs, so only a card of an unknown major version
    that would otherwise be valid gets through."""

    def check_card(self, data: bytes, options: RenderOptions) -> CardOutcome:
        """The reference check of ``data`` read as version 1 (bytes that do not parse are left
        to it)."""
        try:
            card = pb.Card.FromString(data)
        except DecodeError:
            return super().check_card(data, options)
        card.version.major = 1
        return super().check_card(card.SerializeToString(deterministic=True), options)


class SilentRefusalFirmware(Firmware):
    """A firmware that drops malformed and refused output reports silently
    (``silent-refusals``)."""

    def _refuse(self) -> None:
        """Nothing: neither counted nor flagged (PE2 asks both)."""


def state_declared_short(descriptor: bytes = REPORT_DESCRIPTOR) -> bytes:
    """``descriptor`` with the Report Count of STATE one less (``misdeclared-state``): its
    report declared one byte shorter than the protocol's STATE, in as many bytes as before."""
    declared = report_id(ReportId.STATE) + usage(ReportId.STATE)
    right = declared + report_count(State.size() - 1)
    if right not in descriptor:
        raise ValueError("the descriptor does not declare STATE at its size")
    return descriptor.replace(right, declared + report_count(State.size() - 2), 1)


FORCE_COUNTS = 1 << 16
"""Counts of a 16-bit force field (mN)."""


class WrappedForcesSimulation(DeviceSimulation):
    """The E-ViTa whose corner forces keep the low 16 bits of their value in mN
    (``wrapped-forces``)."""

    def step(self, n_frames: int) -> SimBlock:
        block = super().step(n_frames)
        counts = np.rint(block.corner_forces_n * 1000.0)
        wrapped = (counts + FORCE_COUNTS // 2) % FORCE_COUNTS - FORCE_COUNTS // 2
        block.corner_forces_n[...] = wrapped / 1000.0
        return block


class MisdeclaredStateFirmware(Firmware):
    """A firmware whose USB interface declares STATE one byte short (``misdeclared-state``)."""

    report_descriptor = state_declared_short()


def _any_major_firmware(simulation: DeviceSimulation) -> Firmware:
    """The firmware of ``reads-any-major``: the reference one with :class:`AnyMajorChecker`."""
    return Firmware(simulation, checker=AnyMajorChecker())


DROPPED_FRACTION = 0.05
"""Fraction of its STATE reports the ``drops-reports`` control loses (at random)."""


class LossyFirmware(Firmware):
    """A firmware that loses ``dropped_fraction`` of its STATE reports at random as it produces
    them and counts each as PT5 asks (``drops-reports``; the draws are seeded by ``seed``)."""

    def __init__(self, sim: DeviceSimulation, *, dropped_fraction: float = DROPPED_FRACTION,
                 seed: int = 0) -> None:
        super().__init__(sim)
        self.dropped_fraction = float(dropped_fraction)
        self._draws = np.random.default_rng(seed)

    def _emit(self, data: bytes, faults: int) -> None:
        if self._draws.random() >= self.dropped_fraction:
            super()._emit(data, faults)
            return
        # produced (numbered, counted) but never queued for the host; the drop is counted
        # and flagged in the next report sent, as for a full queue
        self.counts.latched_faults |= faults
        self._sequence = (self._sequence + 1) & 0xFFFF
        self.counts.input_reports += 1
        self.counts.input_dropped += 1
        self._pending_faults |= FaultBits.INPUT_DROPPED


def _firmware_driver(firmware: Firmware, uri: str) -> SimDriver:
    return SimDriver(parse_uri(uri), firmware, timeout_s=DEFAULT_TIMEOUT_S)


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
    "swapped-channels": lambda: _sim_driver(SwappedChannelsSimulation(DeviceConfig.coupled()),
                                            "sim://coupled"),
    "inverted-phase": lambda: _sim_driver(
        CardMisreadSimulation(DeviceConfig.evita(), invert_phase), "sim://"),
    "frequency-off": lambda: _sim_driver(
        CardMisreadSimulation(DeviceConfig.evita(), raise_frequency), "sim://"),
    "weak-actuator": lambda: _sim_driver(WeakActuatorSimulation(DeviceConfig.evita()), "sim://"),
    "ignored-watchdog": lambda: _sim_driver(SelfFedWatchdogSimulation(DeviceConfig.evita()),
                                            "sim://"),
    "late-limits": lambda: _sim_driver(LateLimitsSimulation(DeviceConfig.evita()), "sim://"),
    "no-ownership": lambda: _no_ownership(),
    "no-attribution": lambda: _no_attribution(),
    "shared-halts": lambda: _shared_halts(),
    "blocking-writes": lambda: _blocking_writes(),
    "accepts-bad-crc": lambda: _firmware_driver(
        _no_crc_firmware(DeviceSimulation(DeviceConfig.evita())), "sim://"),
    "drops-reports": lambda: _firmware_driver(
        LossyFirmware(DeviceSimulation(DeviceConfig.evita())), "sim://"),
    "reads-any-major": lambda: _firmware_driver(
        _any_major_firmware(DeviceSimulation(DeviceConfig.evita())), "sim://"),
    "silent-refusals": lambda: _firmware_driver(
        SilentRefusalFirmware(DeviceSimulation(DeviceConfig.evita())), "sim://"),
    "unplayed-commit": lambda: _sim_driver(UnplayedCardSimulation(DeviceConfig.evita()),
                                           "sim://"),
    "profile-raises-limits": lambda: _sim_driver(ProfileLimitsSimulation(DeviceConfig.evita()),
                                                 "sim://"),
    "sticky-profile": lambda: _sim_driver(StickyProfileSimulation(DeviceConfig.evita()),
                                          "sim://"),
    "misdeclared-state": lambda: _firmware_driver(
        MisdeclaredStateFirmware(DeviceSimulation(DeviceConfig.evita())), "sim://"),
    "wrapped-forces": lambda: _sim_driver(WrappedForcesSimulation(DeviceConfig.evita()),
                                          "sim://"),
    "host-accepts-any-major": lambda: _sim_driver(DeviceSimulation(DeviceConfig.evita()),
                                                  "sim://", AnyMajorHostDriver),
    "host-refuses-newer-minor": lambda: _sim_driver(DeviceSimulation(DeviceConfig.evita()),
                                                    "sim://", NewerMinorRefusingDriver),
    "host-crashes-on-short-report": lambda: _sim_driver(
        DeviceSimulation(DeviceConfig.evita()), "sim://", ShortReportCrashingDriver),
    "host-barges-in": lambda: _sim_driver(DeviceSimulation(DeviceConfig.evita()), "sim://",
                                          BargingDriver),
}
"""The negative controls by name (see the module docstring)."""

CATCHES: dict[str, tuple[str, str]] = {
    "position-only": (check_names.DEVICE_FRICTION, "dense-grating"),
    "latency-30ms": (check_names.DEVICE_LATENCY, "boundary-move"),
    "no-ev": (check_names.DEVICE_FRICTION, "bipolar"),
    "over-limit": (check_names.DEVICE_SAFETY, "host-limits"),
    "swapped-channels": (check_names.DEVICE_FRICTION, "bipolar"),
    "inverted-phase": (check_names.RENDERER_SPATIAL_PHASE, "coarse-grating@moderate-stroke"),
    "frequency-off": (check_names.RENDERER_COMPONENT_FREQUENCY, "single-grating@moderate-stroke"),
    "weak-actuator": (check_names.DEVICE_DYNAMICS, "rise-time"),
    "ignored-watchdog": (check_names.DEVICE_WATCHDOG, "host-silent"),
    "late-limits": (check_names.DEVICE_SAFETY, "limits-while-driven"),
    "no-ownership": (check_names.DEVICE_SESSION_OWNERSHIP, "second-host-refused"),
    "no-attribution": (check_names.DEVICE_SESSION_OWNERSHIP, "other-connection-refused"),
    "shared-halts": (check_names.DEVICE_SESSION_OWNERSHIP, "halts-per-connection"),
    "blocking-writes": (check_names.DEVICE_SESSION_OWNERSHIP, "beside-non-reader"),
    "accepts-bad-crc": (check_names.DEVICE_UPLOAD_INTEGRITY, "bad-crc"),
    "drops-reports": (check_names.DEVICE_REPORT_LOSS, "loss-fraction"),
    "reads-any-major": (check_names.DEVICE_UPLOAD_INTEGRITY, "unknown-major"),
    "silent-refusals": (check_names.DEVICE_REFUSALS, "short-report"),
    "unplayed-commit": (check_names.DEVICE_UPLOAD_INTEGRITY, "valid-after"),
    "profile-raises-limits": (check_names.DEVICE_PROFILE_UPLOAD, "limits-not-raised"),
    "sticky-profile": (check_names.DEVICE_PROFILE_UPLOAD, "own-profile-restored"),
    "misdeclared-state": (check_names.DEVICE_DESCRIPTOR, "declares-reports"),
    "wrapped-forces": (check_names.DEVICE_SATURATION, "corner-force"),
    "host-accepts-any-major": (check_names.DEVICE_HOST_DRIVER, "refuses-major"),
    "host-refuses-newer-minor": (check_names.DEVICE_HOST_DRIVER, "newer-minor"),
    "host-crashes-on-short-report": (check_names.DEVICE_HOST_DRIVER, "short-state"),
    "host-barges-in": (check_names.DEVICE_HOST_DRIVER, "busy-device"),
}
"""The (check, case) each negative control exists to fail (spec/conformance.md section 6, QN1):
the proof that the threshold of that check bites.
``tests/conformance/test_negative_controls.py`` runs every control against its case and requires
FAIL."""


def _no_ownership() -> SimDriver:
    """The ``no-ownership`` control: the E-ViTa without protocol 1.2 sessions, served over
    USB/IP in this process so that two drivers share it (a USB/IP driver, not a SimDriver;
    :mod:`hcard_device.served_controls`)."""
    from hcard_device.served_controls import open_no_ownership

    return open_no_ownership()  # type: ignore[return-value]


def _no_attribution() -> SimDriver:
    """The ``no-attribution`` control: the E-ViTa whose sessions are attributed to no
    connection, served over USB/IP in this process (:mod:`hcard_device.served_controls`)."""
    from hcard_device.served_controls import open_no_attribution

    return open_no_attribution()  # type: ignore[return-value]


def _shared_halts() -> SimDriver:
    """The ``shared-halts`` control: the E-ViTa whose connections share one OUT halt, served
    over USB/IP in this process (:mod:`hcard_device.served_controls`)."""
    from hcard_device.served_controls import open_shared_halts

    return open_shared_halts()  # type: ignore[return-value]


def _blocking_writes() -> SimDriver:
    """The ``blocking-writes`` control: the E-ViTa whose connections wait on their clients'
    sockets, served over USB/IP in this process (:mod:`hcard_device.served_controls`)."""
    from hcard_device.served_controls import open_blocking_writes

    return open_blocking_writes()  # type: ignore[return-value]


def open_control(name: str) -> SimDriver:
    """Open the negative-control driver ``name`` (a key of :data:`CONTROLS`; a ``control:``
    prefix is accepted).

    Raises:
        ValueError: unknown control name.
    """
    key = name.removeprefix("control:")
    if key not in CONTROLS:
        raise ValueError(f"unknown negative control {name!r}; known: {', '.join(CONTROLS)}")
    return CONTROLS[key]()


class ControlDriver:
    """The negative controls as a driver plugin: ``control:NAME`` opens the control ``NAME``
    (:data:`CONTROLS`); they are never listed as devices."""

    name = "control"
    description = "negative controls of the conformance suite (faulty devices): control:NAME"
    schemes = ("control",)
    kind = "driver"

    @classmethod
    def open(cls, uri: DeviceUri | str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> SimDriver:
        """Open the control the URI names.

        Raises:
            UriError: no control of that name.
        """
        text = str(uri)
        name = text.split(":", 1)[1].lstrip("/") if ":" in text else text
        if name not in CONTROLS:
            raise UriError(f"bad device URI {text!r}: unknown negative control {name!r} "
                           f"(known: {', '.join(CONTROLS)})")
        return CONTROLS[name]()

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (), *,
                  timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """None: a negative control is opened by name, never found."""
        return []
