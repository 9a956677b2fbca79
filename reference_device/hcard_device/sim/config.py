"""Physical constants and limits of the simulated devices, each with its source.

Two presets (thesis chapters 4 and 5):

- :meth:`DeviceConfig.evita` -- the E-ViTa of thesis chapter 5 (section 5.1): a glass plate
  54 x 81 x 1.6 mm resonating at 60,750 Hz (half wavelength 8 mm), a PI amplitude loop at 60 kHz
  (closed-loop bandwidth 400 Hz at 2 um, amplitude held within 50 nm for Fn < 3 N), a 5" capacitive
  touch screen sampled at 50 Hz, four corner force sensors, 10 kframes/s synthesis. UV only.
- :meth:`DeviceConfig.coupled` -- the coupled UV+EV stimulator of chapter 4 (section 4.2.1): an
  aluminium plate at 38,220 Hz and an EV amplifier to 2000 V modulated at 440 Hz, its current
  limited to 250 uA (section 3.6.3, [84]).

SI units (s, m, N, V, A, Hz, F) except positions on the touch surface, which are in mm like the
card and the renderer. Values the thesis does not give are marked "assumption" in
:data:`EVITA_SOURCES` and :data:`COUPLED_SOURCES` together with the reason for the value chosen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS, DeviceLimits
from hcard.quantities import ATMOSPHERE_PA
from hcard.rates import DEFAULT_FRAME_RATE_HZ, TOUCH_RATE_HZ

EVITA_LIMITS = replace(COUPLED_STIMULATOR_LIMITS, max_voltage=0.0, plate_frequency=60_750.0)
"""The E-ViTa of chapter 5: a glass plate resonating at 60,750 Hz (section 5.1.1), no EV
amplifier (0 V, section 5.1), and the coupled stimulator's 2.5 um peak-to-peak amplitude range
(section 2.4); its current limit and carrier are the coupled stimulator's (unused without EV)."""

EVITA_PLATE_QUALITY_FACTOR = 300.0
"""Unloaded quality factor of the E-ViTa plate. The envelope of a resonator is first order with
time constant ``tau = Q / (pi f0)``: 1.57 ms at 60,750 Hz, the "about 1.5 ms" mechanical time
response of a fast plate (section 4.3.2; "can be reduced to 1-2 ms", section 4.4)."""

COUPLED_PLATE_RESPONSE_S = 15e-3
"""10-90 % mechanical response of a plate of the chapter-4 standalone design (section 4.3.2,
"about 15 ms" for the design of [86]); a first-order envelope rises 10-90 % in ``tau ln 9``."""


@dataclass(frozen=True)
class DeviceConfig:
    """A simulated device: physical constants, hardware limits and sensor characteristics.

    Build one with :meth:`evita` or :meth:`coupled`, and vary it with
    :func:`dataclasses.replace` (or :meth:`replace`).

    Attributes:
        name: short identifier.
        frame_rate_hz: synthesis frame rate, Hz (10 kframes/s SPI, section 5.1.1).
        loop_rate_hz: rate of the PI amplitude loop, Hz (60 kHz, section 5.1.1); a whole
            multiple of ``frame_rate_hz``.
        touch_rate_hz: touch-screen sampling rate, Hz (50 Hz, section 5.1.1).
        touch_noise_mm: standard deviation of the touch position jitter, mm (assumption).
        surface_mm: (width, height) of the touch surface, mm; the corner force sensors sit at
            its corners and the card's coordinates are those of this surface.
        limits: the hardware limits, plate resonance and EV carrier (:data:`EVITA_LIMITS`,
            :data:`~hcard.physics.device_limits.COUPLED_STIMULATOR_LIMITS`), SI units; the
            firmware's model renders with them and the simulated hardware enforces them.
            ``limits.load_capacitance`` is the model's (None: Eq. 3.8's 33 pF).
        plate_quality_factor: unloaded quality factor ``Q0`` of the plate.
        finger_damping_per_n: relative increase of the plate's damping ``1/Q`` per newton of
            finger force: ``1/Q(Fn) = (1 + d Fn) / Q0``.
        full_drive_amplitude_m: peak-to-peak amplitude the unloaded plate settles at under full
            drive, m (drive headroom over ``limits.max_amplitude``).
        pi_dead_time_s: apparent dead time ``L`` of the amplitude measurement chain used by
            the Ziegler-Nichols reaction-curve tuning of the PI loop, s.
        pi_tuning_force_n: finger force at which the PI loop was tuned, N.
        amplifier_slew_v_per_s: output slew-rate limit of the EV amplifier, V/s.
        finger_capacitance_f: physical capacitance the EV amplifier drives through a finger in
            contact, F; None: the model's (``limits.load_capacitance``, else Eq. 3.8, 33 pF).
            Not a limit, so not in ``limits``: it is the simulated hardware's load, which may
            differ from the load the firmware's model assumes (``limits.load_capacitance``);
            the model computes the voltage for the current limit on the assumed load, the
            amplifier enforces the current on the physical one.
        force_noise_n: standard deviation of each corner force sensor, N.
        lateral_force_noise_n: standard deviation of the tribometer's lateral force, N.
        mu0: friction coefficient without vibration in the dimensionless group (Eq. 2.30).
        psi_star: characteristic value of the dimensionless group (Eq. 2.33).
        watchdog_s: time without :meth:`DeviceSimulation.feed_watchdog` after which a
            host-driven output ramps to zero, s.
        ramp_down_s: duration of the linear ramp to zero of the commands (watchdog, stop), s.
        stream_queue_frames: capacity of the direct frame-streaming queue, frames.
        ambient_pressure_pa: air pressure around the plate, Pa (one atmosphere; it acts only
            through a hidden ``squeeze-film-share``, :mod:`.hidden`).
    """

    name: str
    frame_rate_hz: float = DEFAULT_FRAME_RATE_HZ
    loop_rate_hz: float = 60_000.0
    touch_rate_hz: float = TOUCH_RATE_HZ
    touch_noise_mm: float = 0.02
    surface_mm: tuple[float, float] = (81.0, 54.0)
    limits: DeviceLimits = EVITA_LIMITS
    plate_quality_factor: float = EVITA_PLATE_QUALITY_FACTOR
    finger_damping_per_n: float = 0.03
    full_drive_amplitude_m: float = 3.7e-6
    pi_dead_time_s: float = 0.385e-3
    pi_tuning_force_n: float = 0.5
    amplifier_slew_v_per_s: float = 40e6
    finger_capacitance_f: float | None = None
    force_noise_n: float = 0.005
    lateral_force_noise_n: float = 0.0078
    mu0: float = 0.5
    psi_star: float = 2.38
    watchdog_s: float = 0.1
    ramp_down_s: float = 0.01
    stream_queue_frames: int = 2000
    ambient_pressure_pa: float = ATMOSPHERE_PA
    sources: dict[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.limits, DeviceLimits):
            raise ValueError(
                f"DeviceConfig.limits must be a DeviceLimits, got {type(self.limits).__name__}"
            )
        positive = (
            "frame_rate_hz", "loop_rate_hz", "touch_rate_hz",
            "plate_quality_factor", "full_drive_amplitude_m", "pi_dead_time_s",
            "amplifier_slew_v_per_s", "mu0", "psi_star",
            "watchdog_s", "ramp_down_s", "ambient_pressure_pa",
        )
        for name in positive:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"DeviceConfig.{name} must be a finite number > 0, got {value}")
        non_negative = (
            "touch_noise_mm", "finger_damping_per_n", "pi_tuning_force_n",
            "force_noise_n", "lateral_force_noise_n",
        )
        for name in non_negative:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"DeviceConfig.{name} must be a finite number >= 0, got {value}")
        ratio = self.loop_rate_hz / self.frame_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"DeviceConfig.loop_rate_hz ({self.loop_rate_hz}) must be a whole multiple of "
                f"frame_rate_hz ({self.frame_rate_hz})"
            )
        if self.finger_capacitance_f is not None and not (
            math.isfinite(self.finger_capacitance_f) and self.finger_capacitance_f > 0
        ):
            raise ValueError("DeviceConfig.finger_capacitance_f must be None or a number > 0 F")
        loaded_full_drive = self.full_drive_amplitude_m / (1 + 3 * self.finger_damping_per_n)
        if self.limits.max_amplitude >= loaded_full_drive:
            raise ValueError(
                "DeviceConfig.full_drive_amplitude_m leaves no drive headroom over "
                "limits.max_amplitude at a 3 N finger"
            )
        width, height = self.surface_mm
        if not (width > 0 and height > 0):
            raise ValueError("DeviceConfig.surface_mm must be two positive sizes")
        if self.stream_queue_frames < 1:
            raise ValueError("DeviceConfig.stream_queue_frames must be >= 1")

    # -- derived ---------------------------------------------------------------------------
    @property
    def loop_samples_per_frame(self) -> int:
        """PI loop samples per synthesis frame (6 at 60 kHz / 10 kHz)."""
        return round(self.loop_rate_hz / self.frame_rate_hz)

    @property
    def has_uv(self) -> bool:
        """Whether the device can vibrate its plate (UV channel)."""
        return self.limits.max_amplitude > 0

    @property
    def has_ev(self) -> bool:
        """Whether the device has an EV amplifier (EV channel)."""
        return self.limits.max_voltage > 0

    @property
    def plate_time_constant_s(self) -> float:
        """Unloaded envelope time constant ``tau = Q0 / (pi f0)``, s."""
        return self.plate_quality_factor / (math.pi * self.limits.plate_frequency)

    def replace(self, **changes: Any) -> DeviceConfig:
        """A copy with some fields changed (:func:`dataclasses.replace`)."""
        return replace(self, **changes)

    # -- presets ---------------------------------------------------------------------------
    @classmethod
    def evita(cls, **changes: Any) -> DeviceConfig:
        """The E-ViTa of thesis section 5.1 (UV only); ``changes`` replace fields."""
        config = cls(name="e-vita", sources=dict(EVITA_SOURCES))
        return replace(config, **changes) if changes else config

    @classmethod
    def coupled(cls, **changes: Any) -> DeviceConfig:
        """The coupled UV+EV stimulator of thesis section 4.2.1; ``changes`` replace fields."""
        tau = COUPLED_PLATE_RESPONSE_S / math.log(9.0)
        frequency = COUPLED_STIMULATOR_LIMITS.plate_frequency
        config = cls(
            name="coupled-stimulator",
            surface_mm=(80.0, 50.0),
            limits=COUPLED_STIMULATOR_LIMITS,
            plate_quality_factor=math.pi * frequency * tau,
            sources={**EVITA_SOURCES, **COUPLED_SOURCES},
        )
        return replace(config, **changes) if changes else config


EVITA_SOURCES: dict[str, str] = {
    "frame_rate_hz": "section 5.1.1: SPI at 10 kframes/s (a 500 Hz sinusoid with 20 points)",
    "loop_rate_hz": "section 5.1.1: closed loop on the vibration amplitude running at 60 kHz",
    "touch_rate_hz": "section 5.1.1: 5\" capacitive touch screen sampled at 50 Hz",
    "touch_noise_mm": (
        "assumption: position jitter of a capacitive panel after its own filtering; the "
        "renderer's two-sample velocity (x 50 Hz x sqrt 2) turns 0.02 mm into 1.4 mm/s"
    ),
    "surface_mm": "section 5.1.1: the 81 x 54 mm glass plate is the touched surface",
    "limits.plate_frequency": "section 5.1.1: resonating at 60,750 Hz",
    "plate_quality_factor": (
        "assumption from section 4.3.2/4.4: envelope tau = Q/(pi f0) = 1.57 ms, the ~1.5 ms "
        "mechanical response of a fast plate"
    ),
    "finger_damping_per_n": (
        "assumption: the finger's damping grows 1/Q by 3 %/N (9 % at 3 N); section 5.1.1's "
        "'held within 50 nm for Fn < 3 N' at 400 Hz bounds it (here: 30 nm at 2 um for "
        "force steps between 0 and 3 N, 37 nm at 2.5 um)"
    ),
    "full_drive_amplitude_m": (
        "assumption: drive headroom chosen so that a 0 -> 2 um step, saturating the drive, "
        "rises 10-90 % in ~1.5 ms (section 4.3.2 'mechanical time response around 1.5 ms')"
    ),
    "pi_dead_time_s": (
        "assumption: apparent dead time of the amplitude sensing chain in the Ziegler-Nichols "
        "tuning (section 5.1.1: 'PI ... tuned with the Ziegler-Nichols method'); the value "
        "for which the tuned loop has the 400 Hz bandwidth at 2 um of Fig. 5.3b"
    ),
    "limits.max_amplitude": (
        "section 2.4: amplitudes up to 2.5 um peak-to-peak, the range of ultrasonic displays "
        "(hcard.physics.device_limits.COUPLED_STIMULATOR_LIMITS)"
    ),
    "limits.max_voltage": "section 5.1: the E-ViTa has no EV amplifier (0 V)",
    "limits.max_current": "section 3.6.3 / [84]: user current limited to 250 uA",
    "limits.carrier_frequency": "section 4.2.1: voltage modulated at 440 Hz",
    "amplifier_slew_v_per_s": (
        "assumption: 40 V/us, fast enough that the amplifier's rise 'can be neglected' "
        "(section 4.4); the current limit binds first"
    ),
    "finger_capacitance_f": "Eq. 3.8 with the section 3.6.1 layers: C = 33 pF",
    "force_noise_n": "assumption: 5 mN per resistive corner sensor (CP 150, section 5.1.1)",
    "lateral_force_noise_n": "section 4.2.1: ATI nano 43 resolution 7.8 mN",
    "mu0": "Figs. 2.21, 2.24: mu0 = 0.5 in the dimensionless group (Eq. 2.30)",
    "psi_star": "Fig. 2.24: Psi* = 2.38 (FE model), Eq. 2.33",
    "watchdog_s": "hcard protocol choice: 100 ms without a host report",
    "ramp_down_s": "hcard protocol choice: commands ramp linearly to zero over 10 ms",
    "stream_queue_frames": "hcard protocol choice: 0.2 s of frames at 10 kHz",
}
"""Where each E-ViTa value comes from (thesis sections, or "assumption" with the reason)."""

COUPLED_SOURCES: dict[str, str] = {
    "surface_mm": "assumption: an 80 x 50 mm STIMTAC-size plate (size not given in 4.2.1)",
    "limits.plate_frequency": "section 4.2.1: aluminium plate resonating at 38,220 Hz",
    "plate_quality_factor": (
        "section 4.3.2: the standalone design responds in about 15 ms (10-90 %), "
        "tau = 15 ms / ln 9, Q = pi f0 tau"
    ),
    "limits.max_voltage": "section 4.2.1: UVA2kV amplifier, programmable voltage up to 2000 V",
    "limits.max_current": "section 3.6.3 / [84]: current limited to I_s = 250 uA",
    "limits.carrier_frequency": "section 4.2.1: voltage modulated at 440 Hz",
}
"""Where the coupled stimulator's values differ from the E-ViTa's."""
