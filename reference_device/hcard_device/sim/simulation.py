"""The device simulation: card, finger, firmware rendering and physics, frame by frame.

One :meth:`DeviceSimulation.step` of ``n`` frames (10 kHz) runs, in order:

1. the finger's true state (a track the internal finger follows, or the host's last report);
2. the sensors: the 50 Hz touch panel (internal finger; its samples feed the renderer) and the
   four corner force sensors;
3. the targets: the card through the hcard streaming renderer (:class:`hcard.render.Renderer`,
   hybrid Position/Texture control on the touch samples), or directly streamed frames;
4. the firmware's model-based rendering (:func:`hcard.physics.actuation.actuate`): plate
   amplitude and EV envelope commands from the targets at the finger speed predicted from the
   touch samples (velocity compensation, :func:`hcard.render.finger_speed.predicted_speed`,
   the estimate ``hcard render --profile`` uses too) and the force the corner sensors
   measure, clipped to the limits;
5. the output gain: 1 while running; a linear ramp to 0 over ``ramp_down_s`` after
   :meth:`DeviceSimulation.stop` or when the watchdog expires;
6. the physics: the PI amplitude loop over the plate envelope at 60 kHz (:mod:`.plate`), the EV
   amplifier with its voltage, slew and current limits (:mod:`.amplifier`), and the finger
   (:mod:`.finger`): the friction felt and the tribometer's lateral force.

Safety holds whatever the host or the card asks: the amplitude reference is clipped to the
limit and the loop's hard clamp keeps the plate at or under it; the amplifier keeps voltage and
user current under theirs; a host that stops feeding the watchdog for ``watchdog_s`` while it
drives the finger or streams frames gets its outputs ramped to zero (fault ``WATCHDOG``) until
it feeds again.

Lowering a limit while driven (spec PS5): the commands take a lowered limit at once. The plate,
a high-Q resonator, cannot follow by itself, so the inverter brakes it (drive in antiphase at
full drive, :data:`BRAKE_DRIVE`, :mod:`.plate`) until it lands on the new limit; only then does
the lowered amplitude limit come into force (:attr:`DeviceSimulation.limits`; until then the
previous one, which the braked plate stays under, is in force). That takes at most
:attr:`DeviceSimulation.limit_settle_time_s` (E-ViTa 0.81 ms, coupled stimulator 3.52 ms). The EV
amplifier's limiter takes lowered voltage and current limits from the next frame.

Faults per frame are the protocol's STATE.faults bits
(:class:`~hcard.device.protocol.constants.FaultBits`): condition flags (limits, watchdog,
clipped card) are set on every frame they hold; event flags (``STREAM_OVERRUN``,
``INVALID_REQUEST``) on the first frame of the step after the event.

Determinism: every noise source has its own generator seeded from ``seed``, so a run is
reproducible, and splitting a run into steps of other sizes gives the same numbers: every frame
field is identical except those the plate loop's rounding reaches, which its vectorised
solution rounds differently for other cut points (amplitude within 1e-15 m, felt friction within
1e-9, lateral force within 1e-10 N; tests/device/test_sim_steps.py). A real-time server steps
every 5 ms (``step(50)``), so the fixed cost of a step is kept small: the internal finger's state
along its track, the corner sensors' noiseless forces and the bare finger's friction coefficient
are worked out :data:`LOOKAHEAD_FRAMES` ahead, and the sensors' noise is drawn in batches, all
giving the numbers of a computation frame by frame.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from hcard.device.protocol.constants import FaultBits
from hcard.physics.actuation import actuate
from hcard.physics.card_clipping import ClipReport, TextureExtremes, card_extremes, clip_items
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_error import ProfileError
from hcard.quantities import M_PER_MM
from hcard.render import Renderer, RenderOptions, RenderStream
from hcard.render.finger_speed import TouchSamples, hold, predicted_speed
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb
from hcard_device.sim.amplifier import EVAmplifier
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.counters import DeviceCounters
from hcard_device.sim.finger import FingerPhysics, FingerTruth, HostFinger, TrackFinger
from hcard_device.sim.hidden import HiddenPhysics
from hcard_device.sim.host_clock import HostClock
from hcard_device.sim.models import device_profile, finger_capacitance
from hcard_device.sim.plate import PIGains, PlateLoop, PlateModel
from hcard_device.sim.sensors import CornerForceSensors, TouchSensor

TOUCH_DTYPE = np.dtype([("x_mm", "f8"), ("y_mm", "f8"), ("contact", "?"), ("t_s", "f8")])
"""Fields of :attr:`SimBlock.touch`: the held touch sample (position mm, contact, its time s;
NaN time before the first sample)."""

HOST_SAMPLE_SPACING_S = 1e-6
"""A host sample not later than the previous one is moved this much after it, s."""

HOST_SAMPLE_MAX_AHEAD_S = 0.05
"""Most a host sample may be timed ahead of the frames simulated so far, s (the served
device's firmware times a FINGER report at its arrival on the wall clock, at most its largest
catch-up, :data:`hcard_device.firmware.REALTIME_MAX_LAG_S`, ahead); a later time is taken as
this far ahead."""

OFF_AMPLITUDE_M = 10e-9
"""Plate amplitude counted as off, m (10 nm, a fifth of the loop's 50 nm tolerance)."""

BRAKE_DRIVE = 1.0
"""Antiphase drive that brakes a plate above a lowered amplitude limit, fraction of full drive:
the inverter reverses its phase at full drive (:class:`.plate.PlateLoop` ``brake_drive``)."""

LOOKAHEAD_FRAMES = 1000
"""Frames of the internal finger worked out at a time (0.1 s at 10 kHz): its true state along
its track, the corner sensors' noiseless forces and the bare finger's friction coefficient
depend on nothing but the frame's time, so they are computed this far ahead and handed out in
slices, the numbers of a computation step by step."""

_TARGET_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Limits:
    """Limits in force (hardware limits, or lower ones set by the host).

    Not a :class:`~hcard.physics.device_limits.DeviceLimits`: a host may set a current limit of 0 A
    (no EV output), which a device profile cannot hold (its ``max_current`` is > 0;
    :func:`.models.device_profile` gives the model no voltage instead). The hardware values are
    ``config.limits``'.

    Attributes:
        max_amplitude_m: peak-to-peak plate amplitude, m.
        max_voltage_v: peak EV voltage, V.
        max_current_a: peak user current, A.
    """

    max_amplitude_m: float
    max_voltage_v: float
    max_current_a: float


@dataclass(frozen=True)
class SimBlock:
    """The frames of one :meth:`DeviceSimulation.step` (arrays of length N).

    Attributes:
        t_s: frame times, s.
        target_uv, target_ev: target relative friction per channel (renderer or stream).
        amplitude_command_m: plate amplitude command after the output gain, m.
        voltage_command_v: EV envelope command after the output gain, V.
        amplitude_m: measured plate amplitude (mean over the frame's loop samples), m p-p.
        voltage_v: EV envelope (peak of the 440 Hz carrier), V.
        current_a: peak current through the user, A.
        friction: relative friction felt ``F_t / (mu0 Fn)`` (forward physics; 1 off contact).
        lateral_force_n: lateral force a tribometer measures, N (with noise).
        normal_force_n: the finger's true normal force on the plate, N.
        corner_forces_n: (N, 4) corner force sensors, N (order ``sensors.CORNERS``).
        touch: (N,) structured array of the held touch sample (:data:`TOUCH_DTYPE`; fields
            by name, ``touch["x_mm"]``).
        texture: (N,) palette index the renderer plays, -1 for a neutral frame (no card, no
            contact, off the card, or direct streaming).
        finger_x_mm, finger_y_mm: the finger's true position, mm.
        finger_speed_m_s: its true sliding speed, m/s.
        contact: it touches the plate.
        faults: (N,) :class:`FaultBits` bits per frame (uint16).
    """

    t_s: np.ndarray
    target_uv: np.ndarray
    target_ev: np.ndarray
    amplitude_command_m: np.ndarray
    voltage_command_v: np.ndarray
    amplitude_m: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    friction: np.ndarray
    lateral_force_n: np.ndarray
    normal_force_n: np.ndarray
    corner_forces_n: np.ndarray
    touch: np.ndarray
    texture: np.ndarray
    finger_x_mm: np.ndarray
    finger_y_mm: np.ndarray
    finger_speed_m_s: np.ndarray
    contact: np.ndarray
    faults: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def target(self) -> np.ndarray:
        """Total target relative friction ``uv * ev`` (Eq. 4.1)."""
        return self.target_uv * self.target_ev

    def has(self, fault: FaultBits) -> np.ndarray:
        """Per-frame mask of frames with ``fault`` set."""
        return (self.faults & int(fault)) != 0

    @classmethod
    def _of(cls, **values: np.ndarray) -> SimBlock:
        """A block of ``values`` (every field, by name), made as ``SimBlock(**values)`` is
        without the frozen dataclass's field by field ``__setattr__`` (a step makes one)."""
        block = object.__new__(cls)
        block.__dict__.update(values)
        return block

    @staticmethod
    def concatenate(blocks: list[SimBlock]) -> SimBlock:
        """The frames of ``blocks`` one after another."""
        values = {}
        for f in fields(SimBlock):
            parts = [getattr(b, f.name) for b in blocks]
            values[f.name] = np.concatenate(parts)
        return SimBlock(**values)


@dataclass(frozen=True)
class PreparedCard:
    """A card compiled for the simulation (:meth:`DeviceSimulation.prepare_card`).

    Attributes:
        card: the card.
        renderer: its renderer (stateless; each load starts a new stream of it).
        extremes: what each texture the grid uses asks at its extremes (the clip report's
            card part).
    """

    card: pb.Card
    renderer: Renderer
    extremes: tuple[TextureExtremes, ...]


class DeviceSimulation:
    """A simulated E-ViTa or coupled stimulator (see the module documentation).

    Args:
        config: the device (:meth:`DeviceConfig.evita` or :meth:`DeviceConfig.coupled`).
        seed: seed of the noise generators.
        hidden: physical effects the hardware hides from its own profile (:mod:`.hidden`:
            effect name -> parameter values, checked against the device), or None.
    """

    def __init__(self, config: DeviceConfig, seed: int = 0,
                 hidden: HiddenPhysics | None = None) -> None:
        self.config = config
        touch_rng, force_rng, lateral_rng = (
            np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)
        )
        self.hardware_limits = Limits(
            config.limits.max_amplitude, config.limits.max_voltage, config.limits.max_current
        )
        self._limits = self.hardware_limits  # the limits set (commands, rendering, clamps)
        self._amplitude_in_force = self._limits.max_amplitude_m
        self._host_profile: DeviceProfile | None = None
        self._profile = device_profile(config)
        plate = PlateModel(
            config.limits.plate_frequency,
            config.plate_quality_factor,
            config.finger_damping_per_n,
            config.full_drive_amplitude_m,
        )
        self.plate = PlateLoop(
            plate,
            PIGains.ziegler_nichols(plate, config.pi_dead_time_s, config.pi_tuning_force_n),
            config.loop_rate_hz,
            config.limits.max_amplitude,
            brake_drive=BRAKE_DRIVE,
        )
        self.amplifier = (
            EVAmplifier(
                config.limits.carrier_frequency,
                config.frame_rate_hz,
                config.limits.max_voltage,
                config.limits.max_current,
                config.amplifier_slew_v_per_s,
            )
            if config.has_ev
            else None
        )
        self.finger_capacitance_f = finger_capacitance(config)
        self.touch_sensor = TouchSensor(config.touch_rate_hz, config.touch_noise_mm, touch_rng)
        width, height = config.surface_mm
        self.force_sensors = CornerForceSensors(width, height, config.force_noise_n, force_rng)
        self.finger_physics = FingerPhysics(
            device_profile(config), config.lateral_force_noise_n, lateral_rng, hidden=hidden
        )
        self._options = RenderOptions(frame_rate_hz=config.frame_rate_hz)
        self._frame = 0
        self._running = False
        self._gain = 0.0
        self._finger: TrackFinger | HostFinger | None = None
        # the internal finger's frames ahead: (finger, first frame, truth, noiseless corners,
        # bare finger's friction coefficient)
        self._ahead: tuple[TrackFinger, int, FingerTruth, np.ndarray, np.ndarray] | None = None
        self._history = TouchSamples.empty()
        self._pending = TouchSamples.empty()
        self._host_clock = HostClock()
        self._last_placed_s = -math.inf  # device time of the last host sample, s
        self._render_reference_s: float | None = None  # offset of the render time line, s
        self._render_shift_s = 0.0  # render time - device time, s
        self._renderer: Renderer | None = None
        self._extremes: tuple[TextureExtremes, ...] = ()
        self._stream: RenderStream | None = None
        self._card_report = ClipReport()
        self._streaming = False
        self._queue: deque[tuple[np.ndarray, np.ndarray]] = deque()
        self._queued = 0
        self._last_feed = 0.0
        self._events = 0
        self.counts = DeviceCounters()
        """The device's counters (the firmware counts into them too): here the streamed frames
        dropped because the queue was full, the frames played neutral because it ran dry, and
        the commands that carried invalid values."""

    # -- state -----------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated time, s (time of the next frame)."""
        return self._frame / self.config.frame_rate_hz

    @property
    def running(self) -> bool:
        """Whether outputs are enabled (:meth:`start`)."""
        return self._running

    @property
    def limits(self) -> Limits:
        """The limits in force (PS1, PS5): those set, except a lowered amplitude limit the
        plate is still being braked down to (:attr:`limits_pending`), for which the previous
        one stays in force."""
        return Limits(self._amplitude_in_force, self._limits.max_voltage_v,
                      self._limits.max_current_a)

    @property
    def limits_set(self) -> Limits:
        """The limits last set (:meth:`set_limits`): the commands, the model-based rendering
        and the clamps use them at once."""
        return self._limits

    @property
    def limits_pending(self) -> bool:
        """A lowered amplitude limit is set but not yet in force: the plate is above it and
        being braked (PS5)."""
        return self._amplitude_in_force > self._limits.max_amplitude_m

    @property
    def pending_settle_time_s(self) -> float:
        """Time the plate still needs to land on a pending lowered amplitude limit, at most, s
        (0 when none is pending): the unloaded plate's brake time from its present amplitude
        (a finger shortens it, by 2 % at 3 N on the E-ViTa)."""
        if not self.limits_pending:
            return 0.0
        return self.plate.brake_time(self.plate.amplitude_m, self._limits.max_amplitude_m, 0.0)

    @property
    def limit_settle_time_s(self) -> float:
        """Longest time a lowered amplitude limit takes to come into force, s: the unloaded
        plate (the slowest) braked at :data:`BRAKE_DRIVE` from the hardware limit to 0,
        ``tau0 ln((A_max + b A_full) / (b A_full))`` (E-ViTa 0.81 ms, coupled stimulator
        3.52 ms; :meth:`.plate.PlateLoop.brake_time`)."""
        return self.plate.brake_time(self.hardware_limits.max_amplitude_m, 0.0, 0.0)

    @property
    def profile(self) -> DeviceProfile:
        """The firmware's device profile (its limits are :attr:`limits`)."""
        return self._profile

    @property
    def render_options(self) -> RenderOptions:
        """The options the simulation renders cards with (its frame rate)."""
        return self._options

    @property
    def clip_report(self) -> ClipReport:
        """Clip report of the loaded card under the limits in force (empty without a card)."""
        return self._card_report

    @property
    def output_off_time_s(self) -> float:
        """Time from a stop or a watchdog expiry until the outputs are off, s: the commands
        reach zero after ``ramp_down_s`` (the EV envelope with them), and the plate, whose drive
        is then cut, decays from at most the hardware limit to under :data:`OFF_AMPLITUDE_M`
        within ``tau0 ln(A_max / OFF_AMPLITUDE_M)`` more (E-ViTa: 10 + 8.7 ms = 18.7 ms;
        coupled stimulator: 10 + 37.7 ms = 47.7 ms)."""
        config = self.config
        decay = config.plate_time_constant_s * math.log(
            max(config.limits.max_amplitude / OFF_AMPLITUDE_M, 1.0)
        )
        return config.ramp_down_s + decay

    @property
    def host_driven(self) -> bool:
        """The host drives the finger or streams frames (the watchdog is armed)."""
        return isinstance(self._finger, HostFinger) or self._streaming


    # -- commands --------------------------------------------------------------------------
    def prepare_card(self, card: pb.Card) -> PreparedCard:
        """Compile ``card`` (validated) for :meth:`load_prepared`: its renderer and the
        extremes of its textures (:func:`~hcard.physics.card_clipping.card_extremes`). Reads nothing
        the simulation changes, so it runs outside the firmware's lock: the largest valid card
        takes 0.2 s, which the device's real-time loop must not wait for (rule PU12).

        Raises:
            CardValidationError: the card is invalid.
        """
        return PreparedCard(card, Renderer(card, self._options), card_extremes(card))

    def load_card(self, card: pb.Card) -> ClipReport:
        """Play ``card`` (validated) from now on; returns what the device cannot render.

        The card replaces any previous card and ends direct streaming. Raises only for an
        invalid card (:class:`hcard.errors.CardValidationError`).
        """
        return self.load_prepared(self.prepare_card(card))

    def load_prepared(self, prepared: PreparedCard) -> ClipReport:
        """Play a card compiled by :meth:`prepare_card` from now on (from its initial state:
        also how PLAY_CARD replays the active card); returns what the device cannot render.
        Costs a clip report under the profile in force (no compilation)."""
        self._renderer = prepared.renderer
        self._extremes = prepared.extremes
        self._new_stream()
        self._streaming = False
        self._clear_queue()
        self._card_report = clip_items(self._extremes, self._profile)
        return self._card_report

    def set_limits(
        self,
        max_amplitude_m: float | None = None,
        max_voltage_v: float | None = None,
        max_current_a: float | None = None,
    ) -> Limits:
        """Set limits at or below the hardware ones (None: keep). Values above the hardware
        limit are clamped to it; negative values count as 0 and NaN leaves the limit as it was
        (both flag ``INVALID_REQUEST``). Never raises. Returns the limits set.

        The commands, the model-based rendering, the plate loop and the amplifier take them
        from the next frame. A raised limit, or one the output is at or under, is in force at
        once; an amplitude limit lowered under the plate's present amplitude comes into force
        only once the braked plate has landed on it (PS5, :attr:`limits_pending`; at most
        :attr:`limit_settle_time_s`), the previous one staying in force meanwhile. The
        amplifier's envelope collapses to lowered EV limits within the next frame, its current
        held at the limit.
        """
        hardware = self.hardware_limits
        values = []
        for name, value in (
            ("max_amplitude_m", max_amplitude_m),
            ("max_voltage_v", max_voltage_v),
            ("max_current_a", max_current_a),
        ):
            current = getattr(self._limits, name)
            if value is None:
                values.append(current)
                continue
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if math.isnan(number) or number < 0:
                self._invalid()
                values.append(current if math.isnan(number) else 0.0)
                continue
            values.append(min(number, getattr(hardware, name)))
        in_force = self._amplitude_in_force
        self._limits = Limits(*values)
        self._profile = self._profile_in_force()
        self.plate.limit_m = self._limits.max_amplitude_m
        self._amplitude_in_force = max(in_force, self._limits.max_amplitude_m)
        if not self.plate.above_limit:
            self._commit_limits()
        if self.amplifier is not None:
            self.amplifier.max_voltage_v = self._limits.max_voltage_v
            self.amplifier.max_current_a = self._limits.max_current_a
        if self._renderer is not None:
            self._card_report = clip_items(self._extremes, self._profile)
        return self._limits

    def _commit_limits(self) -> None:
        """Put the limits set in force (the plate is at or under them)."""
        self._amplitude_in_force = self._limits.max_amplitude_m

    def set_profile(self, profile: DeviceProfile | None) -> ClipReport:
        """Render with ``profile`` (a host's device profile) from now on, or with the device's
        own model again (None). The limits in force stay the device's: the profile's own limits
        are replaced by them, so no profile can raise what the device does. Returns the clip
        report of the active card under the new profile.

        Raises:
            ProfileError: the profile does not render a channel the device has, or renders one
                it lacks.
        """
        if profile is not None:
            for channel, present, model in (
                ("UV", self.config.has_uv, profile.uv_model),
                ("EV", self.config.has_ev, profile.ev_model),
            ):
                # short reasons first: the protocol's detail field holds 46 bytes (PU8)
                if present and model is None:
                    raise ProfileError(
                        f"{channel} channel: the profile has none (model "
                        f"{profile.predictor.name!r}), the device has one"
                    )
                if not present and model is not None:
                    raise ProfileError(
                        f"{channel} channel: the device has none (model "
                        f"{profile.predictor.name!r} renders one)"
                    )
        self._host_profile = profile
        self._profile = self._profile_in_force()
        if self._renderer is not None:
            self._card_report = clip_items(self._extremes, self._profile)
        return self._card_report

    @property
    def host_profile(self) -> bool:
        """A host's profile is in force (:meth:`set_profile`)."""
        return self._host_profile is not None

    def _profile_in_force(self) -> DeviceProfile:
        """The device's own profile at the limits in force, or the host's with those limits."""
        own = device_profile(
            self.config,
            max_amplitude_m=self._limits.max_amplitude_m,
            max_voltage_v=self._limits.max_voltage_v,
            max_current_a=self._limits.max_current_a,
        )
        if self._host_profile is None:
            return own
        return self._host_profile.replace(limits=own.limits)

    def start(self) -> None:
        """Enable the outputs (the watchdog, if armed, counts from now). With the host's
        finger, a new session (PO4a): its earlier touch samples are forgotten, so the next
        one is a touch-down and not a jump from where the last session ended."""
        self._running = True
        self._gain = 1.0
        self._last_feed = self.time_s
        if isinstance(self._finger, HostFinger):
            self._finger = HostFinger(self.config.surface_mm)
            self._new_finger()
            self._history = TouchSamples.empty()
            self._pending = TouchSamples.empty()
            self._forget_render_time_line()
            if self._renderer is not None:
                self._new_stream()

    def stop(self) -> None:
        """Ramp the outputs to zero over ``ramp_down_s`` and drop streamed frames."""
        self._running = False
        self._clear_queue()

    def feed_watchdog(self) -> None:
        """The host is alive (the firmware calls this on every host report)."""
        self._last_feed = self.time_s

    def host_finger(
        self, t_s: float, x_mm: float, y_mm: float, normal_force_n: float, contact: bool,
        host_time_s: float | None = None,
    ) -> float | None:
        """A finger state from the host (touch sensing on the host side); returns the device
        time (s) the sample was placed at, None when it was rejected.

        ``t_s`` is in the device clock (:attr:`time_s`); it may lie ahead of the frames
        simulated so far (at most :data:`HOST_SAMPLE_MAX_AHEAD_S`, a later time is taken as
        that far ahead): the frames before it keep the previous sample. One not later than the
        previous sample is moved just after it. Non-finite values
        are rejected (``INVALID_REQUEST``); a negative force counts as 0. ``host_time_s``: the
        host's time of the sample (FINGER.host_time_us): the finger moved between two samples
        in the host's time, so its physical speed is taken over that interval, and the sample
        is placed on the device clock by :class:`.host_clock.HostClock` (PO2), not at its
        arrival: reports that arrive late and in bursts keep the spacing the host gave them.
        """
        try:
            values = [float(v) for v in (t_s, x_mm, y_mm, normal_force_n)]
        except (TypeError, ValueError):
            self._invalid()
            return None
        if not all(math.isfinite(v) for v in values):
            self._invalid()
            return None
        t, x, y, normal_force = values
        if not isinstance(self._finger, HostFinger):
            if not self.host_driven:
                self._last_feed = self.time_s
            self._finger = HostFinger(self.config.surface_mm)
            self._new_finger()
            self._host_clock.reset()
            self._forget_render_time_line()
        host_s = None
        if host_time_s is not None and math.isfinite(host_time_s):
            t = self._host_clock.device_time(t, host_time_s)
            host_s = self._host_clock.last_host_s
        t = min(t, self.time_s + HOST_SAMPLE_MAX_AHEAD_S)
        if t <= self._last_placed_s:
            t = self._last_placed_s + HOST_SAMPLE_SPACING_S
        self._last_placed_s = t
        render_t = self._render_time(t, host_s)
        sample = TouchSamples(
            np.array([render_t]), np.array([x]), np.array([y]), np.array([bool(contact)])
        )
        self._pending = self._pending.concat(sample)
        if self._stream is not None:
            self._stream.push(render_t, x, y, max(normal_force, 0.0), bool(contact))
        self._finger.update(t, x, y, normal_force, bool(contact), host_time_s)
        return t

    def _render_time(self, placed_s: float, host_s: float | None) -> float:
        """The render time of a host sample placed at ``placed_s`` (device clock) whose
        unwrapped host time is ``host_s`` (None: timed by its arrival), s.

        The renderer works on the host's time line: a sample's render time is its host time
        plus a reference offset fixed when the time line began (the first host-timed sample
        since the host's samples were last forgotten), so the samples keep the spacing the
        host gave them; frames are rendered at device time plus :attr:`_render_shift_s`, the
        reference less the offset of the latest placement. When the device's estimate of the
        clock offset moves (PO2: a report that travelled faster), the rendered frames move
        with it, exactly as the echo age tells the host (PI3: a report's last frame is at host
        time ``host_time_echo_us + echo_age_us``); velocity, odometer and temporal phase stay
        those of the host's time line. A sample timed by its arrival keeps the current shift.
        """
        if host_s is not None:
            offset = placed_s - host_s
            if self._render_reference_s is None:
                self._render_reference_s = offset
            self._render_shift_s = self._render_reference_s - offset
        render_t = placed_s + self._render_shift_s
        last = self._last_sample_time()
        return render_t if render_t > last else last + HOST_SAMPLE_SPACING_S

    def _forget_render_time_line(self) -> None:
        """Start the render time line afresh (the samples on it were forgotten)."""
        self._last_placed_s = -math.inf
        self._render_reference_s = None
        self._render_shift_s = 0.0

    def use_internal_finger(self, track: FingerTrack) -> None:
        """Let the simulated finger follow ``track`` from now on (its first sample now), sensed
        by the 50 Hz touch panel and the corner force sensors. Host finger reports stop
        counting.

        The panel's samples are a new finger on a new render time line: the host's samples
        may have been rendered ahead of the device clock (:meth:`_render_time`), and the
        panel's, timed by the device clock, would not follow them."""
        self._finger = TrackFinger(track, self.time_s, self.config.surface_mm)
        self._new_finger()
        self._history = TouchSamples.empty()
        self._pending = TouchSamples.empty()
        self._forget_render_time_line()
        if self._renderer is not None:
            self._new_stream()

    def stream_frames(self, uv: np.ndarray | float, ev: np.ndarray | float) -> int:
        """Queue target relative friction frames (UV in [0, 1], EV in [1, 4]; broadcast
        together) for direct streaming; returns how many were queued. Frames beyond the queue
        capacity are dropped and counted (``STREAM_OVERRUN``). Out-of-range values are clipped
        and NaN read as neutral (``INVALID_REQUEST``)."""
        try:
            uv_a, ev_a = np.broadcast_arrays(
                np.atleast_1d(np.asarray(uv, dtype=np.float64)),
                np.atleast_1d(np.asarray(ev, dtype=np.float64)),
            )
        except (TypeError, ValueError):
            self._invalid()
            return 0
        uv_a, ev_a = uv_a.ravel(), ev_a.ravel()
        if not self._streaming:
            if not self.host_driven:
                self._last_feed = self.time_s
            self._streaming = True
        bad = (
            ~np.isfinite(uv_a) | ~np.isfinite(ev_a)
            | (uv_a < -_TARGET_TOLERANCE) | (uv_a > 1 + _TARGET_TOLERANCE)
            | (ev_a < 1 - _TARGET_TOLERANCE) | (ev_a > 4 + _TARGET_TOLERANCE)
        )
        if bad.any():
            self._invalid()
        uv_a = np.clip(np.nan_to_num(uv_a, nan=1.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        ev_a = np.clip(np.nan_to_num(ev_a, nan=1.0, posinf=4.0, neginf=1.0), 1.0, 4.0)
        room = self.config.stream_queue_frames - self._queued
        take = min(room, uv_a.shape[0])
        if take < uv_a.shape[0]:
            self.counts.stream_frames_dropped += uv_a.shape[0] - take
            self._events |= int(FaultBits.STREAM_OVERRUN)
        if take > 0:
            self._queue.append((uv_a[:take].copy(), ev_a[:take].copy()))
            self._queued += take
        return take

    @property
    def queued_frames(self) -> int:
        """Streamed frames waiting in the queue."""
        return self._queued

    # -- the step --------------------------------------------------------------------------
    def step(self, n_frames: int) -> SimBlock:
        """Advance ``n_frames`` frames (at ``frame_rate_hz``) and return them."""
        cfg = self.config
        n = max(int(n_frames), 0)
        rate = cfg.frame_rate_hz
        times = (self._frame + np.arange(n, dtype=np.float64)) / rate
        t_end = (self._frame + n) / rate
        faults = np.zeros(n, dtype=np.uint16)
        if n and self._events:
            faults[0] |= self._events
            self._events = 0

        # 1-2. finger, sensors.
        truth, split, coefficient = self._finger_frames(times)
        new = self._sense_touch(self._frame / rate, t_end)
        samples = self._history.concat(new)
        render_times = times + self._render_shift_s  # the samples' time line
        touch = self._held_touch(samples, render_times)
        speed_est = (
            predicted_speed(samples, render_times, self._options.dead_reckoning_s) * M_PER_MM
        )
        self._history = samples.tail(4)
        corners = self.force_sensors.add_noise(split)
        fn_est = np.maximum(np.add.reduce(corners, axis=1), 0.0)

        # 3. targets.
        uv_t, ev_t, texture = self._targets(n)

        # 4. model-based rendering (neutral targets need no actuation).
        if np.logical_or.reduce(uv_t < 1.0) or np.logical_or.reduce(ev_t > 1.0):
            commands = actuate(self._profile, uv_t, ev_t, speed_est, fn_est)
            amplitude_raw, voltage_raw = commands.amplitude, commands.voltage
            self._flag_commands(faults, uv_t, ev_t, commands.uv, commands.ev)
        else:
            amplitude_raw, voltage_raw = np.zeros(n), np.zeros(n)

        # 5. output gain (stop, watchdog).
        gain, tripped = self._output_gain(times)
        if tripped is not None:
            faults[tripped] |= int(FaultBits.WATCHDOG)
        if gain is not None:
            amplitude_raw, voltage_raw = amplitude_raw * gain, voltage_raw * gain
        amplitude_cmd = np.minimum(amplitude_raw, self._limits.max_amplitude_m)
        voltage_cmd = np.minimum(voltage_raw, self._limits.max_voltage_v)

        # 6. physics.
        m = cfg.loop_samples_per_frame
        plate = self.plate.run(amplitude_cmd.repeat(m), truth.normal_force_n.repeat(m))
        amplitude = np.add.reduce(plate.amplitude.reshape(n, m), axis=1) / m  # frame mean
        if self.limits_pending and not self.plate.above_limit:
            self._commit_limits()  # the braked plate landed on the lowered limit (PS5)
        if np.logical_or.reduce(plate.clamped):
            faults[np.logical_or.reduce(plate.clamped.reshape(n, m), axis=1)] |= int(
                FaultBits.AMPLITUDE_LIMIT)
        if self.amplifier is not None:
            contact = truth.contact
            if np.logical_and.reduce(contact):  # one load for the whole step: a number
                load: np.ndarray | float = self.finger_capacitance_f
            elif not np.logical_or.reduce(contact):
                load = 0.0
            else:
                load = np.where(contact, self.finger_capacitance_f, 0.0)
            ev_run = self.amplifier.run(voltage_cmd, load)
            voltage, current = ev_run.voltage, ev_run.current
            faults[ev_run.voltage_limited] |= int(FaultBits.VOLTAGE_LIMIT)
            faults[ev_run.current_limited] |= int(FaultBits.CURRENT_LIMIT)
        else:
            voltage, current = np.zeros(n), np.zeros(n)
        friction, lateral = self.finger_physics.respond(amplitude, voltage, truth, coefficient)

        self._frame += n
        return SimBlock._of(
            t_s=times,
            target_uv=uv_t,
            target_ev=ev_t,
            amplitude_command_m=amplitude_cmd,
            voltage_command_v=voltage_cmd,
            amplitude_m=amplitude,
            voltage_v=voltage,
            current_a=current,
            friction=friction,
            lateral_force_n=lateral,
            normal_force_n=truth.normal_force_n,
            corner_forces_n=corners,
            touch=touch,
            texture=texture,
            finger_x_mm=truth.x_mm,
            finger_y_mm=truth.y_mm,
            finger_speed_m_s=truth.speed_m_s,
            contact=truth.contact,
            faults=faults,
        )

    # -- pieces ----------------------------------------------------------------------------
    def _new_finger(self) -> None:
        """A new finger on the plate: the history hidden effects keep of it starts over."""
        hidden = self.finger_physics.hidden
        if hidden is not None:
            hidden.new_finger()

    def _invalid(self) -> None:
        self.counts.invalid_requests += 1
        self._events |= int(FaultBits.INVALID_REQUEST)

    def _last_sample_time(self) -> float:
        if len(self._pending):
            return float(self._pending.t[-1])
        if len(self._history):
            return float(self._history.t[-1])
        return -math.inf

    def _new_stream(self) -> None:
        assert self._renderer is not None
        self._stream = self._renderer.stream(t0=self.time_s)
        old = self._history.concat(self._pending)
        if len(old):
            self._stream.push(old.t, old.x, old.y, None, old.contact)

    def _finger_frames(
        self, times: np.ndarray
    ) -> tuple[FingerTruth, np.ndarray, np.ndarray | None]:
        """The finger's true state at the frames of this step (at ``times``, s), the corner
        sensors' noiseless forces (N, 4) under it and the bare finger's friction coefficient
        (:meth:`.finger.FingerPhysics.coefficient`; None: not worked out); the internal
        finger's from its frames ahead (:data:`LOOKAHEAD_FRAMES`)."""
        finger, n = self._finger, times.shape[0]
        if not isinstance(finger, TrackFinger):
            truth = finger.state(times) if finger is not None else FingerTruth.absent(n)
            split = self.force_sensors.split(truth.normal_force_n, truth.x_mm, truth.y_mm)
            return truth, split, None
        ahead = self._ahead
        if ahead is None or ahead[0] is not finger or not (
            ahead[1] <= self._frame and self._frame + n <= ahead[1] + ahead[3].shape[0]
        ):
            count = max(n, LOOKAHEAD_FRAMES)
            frames = (self._frame + np.arange(count, dtype=np.float64)) / self.config.frame_rate_hz
            truth = finger.state(frames)
            split = self.force_sensors.split(truth.normal_force_n, truth.x_mm, truth.y_mm)
            coefficient = self.finger_physics.coefficient(truth)
            split.flags.writeable = coefficient.flags.writeable = False
            ahead = self._ahead = (finger, self._frame, truth, split, coefficient)
        start, stop = self._frame - ahead[1], self._frame - ahead[1] + n
        return ahead[2].slice(start, stop), ahead[3][start:stop], ahead[4][start:stop]

    def _sense_touch(self, t0: float, t1: float) -> TouchSamples:
        """Touch samples of this step: the panel's (internal finger) or the host's."""
        if isinstance(self._finger, TrackFinger):
            times = self.touch_sensor.sample_times(t0, t1)
            if times.shape[0] == 0:
                return TouchSamples.empty()
            samples = self.touch_sensor.measure(times, *self._track_at(times))
            if self._stream is not None:
                self._stream.push(samples.t, samples.x, samples.y, None, samples.contact)
            return samples
        samples, self._pending = self._pending, TouchSamples.empty()
        return samples

    def _track_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The internal finger's position (mm) and contact at ``times`` (s, rising): from its
        frames ahead when every time is a frame's time among them (the touch panel's clock
        ticks on frames: the state is the same function of the same time), else from its
        track."""
        ahead, rate = self._ahead, self.config.frame_rate_hz
        if ahead is not None and ahead[0] is self._finger:
            frames = np.rint(times * rate)
            index = frames - ahead[1]
            truth = ahead[2]
            if (index[0] >= 0 and index[-1] < truth.normal_force_n.shape[0]
                    and np.logical_and.reduce(frames / rate == times)):
                i = index.astype(np.intp)
                return truth.x_mm[i], truth.y_mm[i], truth.contact[i]
        assert self._finger is not None  # called for the internal finger only
        state = self._finger.state(times)
        return state.x_mm, state.y_mm, state.contact

    def _targets(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """UV and EV targets and the palette index of the next ``n`` frames."""
        if self._stream is not None and not self._streaming:
            frames = self._stream.render(n, time_shift_s=self._render_shift_s)
            return frames.uv, frames.ev, frames.texture.astype(np.int32)
        neutral = np.full(n, -1, dtype=np.int32)
        if self._streaming:
            return (*self._pop_stream(n), neutral)
        return np.ones(n), np.ones(n), neutral

    def _pop_stream(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        uv, ev = np.ones(n), np.ones(n)
        filled = 0
        while filled < n and self._queue:
            chunk_uv, chunk_ev = self._queue[0]
            take = min(n - filled, chunk_uv.shape[0])
            uv[filled : filled + take] = chunk_uv[:take]
            ev[filled : filled + take] = chunk_ev[:take]
            filled += take
            if take == chunk_uv.shape[0]:
                self._queue.popleft()
            else:
                self._queue[0] = (chunk_uv[take:], chunk_ev[take:])
        self._queued -= filled
        self.counts.stream_underruns += n - filled
        return uv, ev

    def _clear_queue(self) -> None:
        self._queue.clear()
        self._queued = 0

    def _held_touch(self, samples: TouchSamples, render_times: np.ndarray) -> np.ndarray:
        """The touch sample held at each frame (:data:`TOUCH_DTYPE`; ``render_times``: the
        frames on the samples' time line, s). A step between two touch samples holds one
        sample throughout: its fields are filled in at once."""
        n = render_times.shape[0]
        index = hold(samples, render_times)
        touch = np.empty(n, dtype=TOUCH_DTYPE)
        if n and index[0] == index[-1]:  # the index never falls: one sample throughout
            i = int(index[0])
            if i < 0:
                touch.fill((0.0, 0.0, False, math.nan))
            else:
                touch.fill((samples.x[i], samples.y[i], samples.contact[i],
                            samples.t[i] - self._render_shift_s))
            return touch
        touch.fill((0.0, 0.0, False, math.nan))
        known = index >= 0
        held = index[known]
        touch["x_mm"][known] = samples.x[held]
        touch["y_mm"][known] = samples.y[held]
        touch["contact"][known] = samples.contact[held]
        touch["t_s"][known] = samples.t[held] - self._render_shift_s
        return touch

    def _flag_commands(self, faults: np.ndarray, uv_t: np.ndarray, ev_t: np.ndarray,
                       uv_r: np.ndarray, ev_r: np.ndarray) -> None:
        """Add the flags of the model-based rendering's clipping to ``faults`` (per frame;
        ``uv_r``, ``ev_r``: what the commands render of the targets ``uv_t``, ``ev_t``)."""
        uv_short = uv_r > uv_t + 1e-6
        ev_short = ev_r < ev_t - 1e-6
        if not (np.logical_or.reduce(uv_short) or np.logical_or.reduce(ev_short)):
            return  # every target rendered: nothing to flag
        missing = None  # frames that need a channel the device lacks
        if self._profile.uv_model is not None and self._limits.max_amplitude_m > 0:
            faults[uv_short] |= int(FaultBits.AMPLITUDE_LIMIT)
        else:
            missing = uv_short
        if self._profile.ev_model is not None and self._limits.max_voltage_v > 0:
            name = self._profile.voltage_limit[1]
            flag = FaultBits.CURRENT_LIMIT if name == "max_current" else FaultBits.VOLTAGE_LIMIT
            faults[ev_short] |= int(flag)
        else:
            missing = ev_short if missing is None else missing | ev_short
        if not self._streaming and self._card_report.clipped:
            faults[uv_short | ev_short] |= int(FaultBits.CARD_CLIPPED)
        if missing is not None:
            faults[missing] |= int(FaultBits.CARD_CLIPPED)

    def _output_gain(self, times: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Per-frame output gain (None: 1 throughout) and the frames where the watchdog has
        expired (None: none)."""
        n = times.shape[0]
        tripped = None
        if self.host_driven and self._running and n:
            deadline = self._last_feed + self.config.watchdog_s
            if times[-1] >= deadline:  # the times rise: the last frame tells if any trips
                tripped = times >= deadline
        if self._running and tripped is None:
            if n:
                self._gain = 1.0
            return None, None
        off = np.ones(n, dtype=bool) if tripped is None else tripped  # None: stopped
        gain = np.ones(n)
        if off.any():
            first = int(np.argmax(off))
            start = self._gain if first == 0 else 1.0
            fall = 1.0 / (self.config.ramp_down_s * self.config.frame_rate_hz)
            gain[first:] = np.maximum(start - fall * np.arange(1, n - first + 1), 0.0)
        if n:
            self._gain = float(gain[-1])
        return gain, tripped
