"""The simulated finger: where it is (kinematics) and what it feels (physics).

Kinematics (:class:`TrackFinger`, :class:`HostFinger`): the finger's true state at each frame --
position (mm), normal force (N), contact and sliding speed (m/s) -- from a
:class:`~hcard.track.FingerTrack` it follows (linear between samples) or from the latest state a
host reported. A finger outside the surface is off the plate.

Physics (:class:`FingerPhysics`), built from the predictors of :mod:`.models`:

- the friction felt is the coupled forward map (Eq. 4.1) of the measured plate amplitude and EV
  envelope at the finger's true speed and force:
  ``friction = mu'(w, U, Fn) * (1 + <F_e(V)> / Fn)``, ``mu'`` from the dimensionless group
  (Eqs. 2.30-2.33), ``<F_e>`` the carrier-averaged Kaczmarek force through the leakage gain
  (Eqs. 3.12, 3.22-3.23; the envelope is taken as slow against the carrier);
- the lateral force a tribometer measures is ``F_t = mu_f * friction * Fn`` plus its noise, with
  ``mu_f = F_l / Fn`` the bare finger's friction coefficient (load power law Eq. 1.7/2.35,
  occlusion Fig. 1.11, speed peak Fig. 1.12; :class:`FingerFriction`), so that
  ``F_t = mu(w) (Fn + F_e)`` (Eq. 4.1).

Without contact the friction reads 1 (neutral) and the tribometer reads its noise only.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from hcard.physics.profile import DeviceProfile
from hcard.quantities import M_PER_MM, S_PER_US
from hcard.render.touch import segment_speeds, step_speed
from hcard.track import FingerTrack
from hcard_builtins.physics.finger import FingerFriction
from hcard_device.sim.hidden import HiddenPhysics
from hcard_device.sim.sensors import NormalDraws

HOST_TIME_WRAP_S = (1 << 32) * S_PER_US
"""A host's FINGER time stamps wrap at 2^32 us, s."""


@dataclass(frozen=True)
class FingerTruth:
    """True finger state at N frame times.

    Attributes:
        x_mm, y_mm: position, mm.
        normal_force_n: normal force on the plate, N (0 off the plate).
        contact: the finger touches the plate.
        speed_m_s: sliding speed, m/s.
        contact_time_s: time since the touch-down of the current contact, s.
        held: position, force, contact and speed are the same in every frame (a state the
            host reported, held between its reports).
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    normal_force_n: np.ndarray
    contact: np.ndarray
    speed_m_s: np.ndarray
    contact_time_s: np.ndarray
    held: bool = False

    @functools.cached_property
    def checked(self) -> bool:
        """Force, speed and contact time are all finite and >= 0, so the physics may skip
        its input checks on them (the finger models that know it set it when they build
        the state)."""
        return finite_non_negative(self.normal_force_n, self.speed_m_s, self.contact_time_s)

    def slice(self, start: int, stop: int) -> FingerTruth:
        """The frames ``start .. stop - 1`` (views; checked when all frames are, which is
        worked out once for the whole state)."""
        part = object.__new__(FingerTruth)
        part.__dict__.update(  # frozen: set as the dataclass __init__ would, without its checks
            x_mm=self.x_mm[start:stop], y_mm=self.y_mm[start:stop],
            normal_force_n=self.normal_force_n[start:stop], contact=self.contact[start:stop],
            speed_m_s=self.speed_m_s[start:stop], contact_time_s=self.contact_time_s[start:stop],
            held=self.held,
        )
        if self.checked:
            part.__dict__["checked"] = True  # as the cached property stores it
        return part

    @staticmethod
    def absent(n: int) -> FingerTruth:
        """No finger on the plate for ``n`` frames."""
        zeros = np.zeros(n)
        return FingerTruth(zeros, zeros.copy(), zeros.copy(), np.zeros(n, dtype=bool),
                           zeros.copy(), zeros.copy())


def _on_plate(
    x: np.ndarray, y: np.ndarray, contact: np.ndarray, surface_mm: tuple[float, float]
) -> np.ndarray:
    width, height = surface_mm
    return contact & (x >= 0) & (x <= width) & (y >= 0) & (y <= height)


def finite_non_negative(*arrays: np.ndarray) -> bool:
    """Every value of every array is finite and >= 0 (two reductions per array: a NaN makes
    them NaN, which fails the comparison)."""
    for values in arrays:
        if values.size and not (
            np.minimum.reduce(values, axis=None) >= 0.0
            and np.maximum.reduce(values, axis=None) < math.inf
        ):
            return False
    return True


class TrackFinger:
    """A finger following a track; track time ``track.t[0]`` falls at simulation time
    ``start_s``. Before the track and after its last sample the finger is off the plate.

    Args:
        track: the touch samples to follow.
        start_s: simulation time of the track's first sample, s.
        surface_mm: the plate's (width, height), mm.
    """

    def __init__(self, track: FingerTrack, start_s: float, surface_mm: tuple[float, float]):
        self.t = track.t - track.t[0] + start_s
        self.x, self.y, self.normal_force = track.x, track.y, track.normal_force
        self.contact = track.contact
        self.surface_mm = surface_mm
        previous = np.concatenate(([False], self.contact[:-1]))
        touchdown = self.contact & ~previous
        self.touchdown_t = np.where(touchdown, self.t, -np.inf)
        np.maximum.accumulate(self.touchdown_t, out=self.touchdown_t)
        # the finger moves straight between samples: each segment's speed is rule R4's estimate
        # at its end sample, in contact or not (the contact of the segment is applied below)
        self.speed = np.zeros(len(track))
        self.speed[:-1] = segment_speeds(self.t, self.x, self.y)[1:] * M_PER_MM

    @property
    def end_s(self) -> float:
        """Simulation time of the track's last sample, s."""
        return float(self.t[-1])

    def state(self, times: np.ndarray) -> FingerTruth:
        """True state at ``times`` (s): position and force interpolated linearly, contact and
        speed of the segment the time falls in."""
        i = np.searchsorted(self.t, times, side="right") - 1
        inside = (i >= 0) & (times <= self.t[-1])
        j = np.minimum(np.maximum(i, 0), len(self.t) - 1)
        x = np.interp(times, self.t, self.x)
        y = np.interp(times, self.t, self.y)
        fn = np.maximum(np.interp(times, self.t, self.normal_force), 0.0)
        contact = _on_plate(x, y, inside & self.contact[j], self.surface_mm)
        speed = np.where(contact, self.speed[j], 0.0)
        contact_time = np.where(contact, times - self.touchdown_t[j], 0.0)
        return FingerTruth(x, y, np.where(contact, fn, 0.0), contact, speed, contact_time)


@dataclass(frozen=True)
class _HeldReport:
    """A host's report as the finger holds it from its time ``t`` (s, device clock) on."""

    t: float
    x: float
    y: float
    normal_force: float  # 0 off the plate
    speed_m_s: float  # 0 off the plate
    on: bool  # in contact and on the plate
    touchdown_s: float


class HostFinger:
    """A finger whose state the host reports (touch sensing on the host side); from the time
    of each report on, until the next one, the state it reported holds, and the speed is
    that of the last two reports of a contact.

    A report may be timed ahead of the frames simulated so far (the served device times a
    FINGER report at its arrival on the wall clock without first running the simulation up
    to it, :meth:`hcard_device.firmware.Firmware.handle_output`): the frames before that time
    keep the previous report's state.

    Args:
        surface_mm: the plate's (width, height), mm.
    """

    def __init__(self, surface_mm: tuple[float, float]) -> None:
        self.surface_mm = surface_mm
        self.t = self.x = self.y = self.normal_force = 0.0
        self.host_t: float | None = None
        self.contact = False
        self.speed_m_s = 0.0
        self.touchdown_s = 0.0
        # in time order; the first holds since before every frame still to be simulated
        self._held = [_HeldReport(-math.inf, 0.0, 0.0, 0.0, 0.0, False, 0.0)]

    def update(self, t: float, x: float, y: float, normal_force: float, contact: bool,
               host_t: float | None = None) -> None:
        """A new report at time ``t`` (s, device clock), later than the previous one, of a
        finger at ``x``, ``y`` (mm) pressing with ``normal_force`` (N, negative counts as 0);
        ``host_t``: the host's time of the sample (s, wrapping at 2^32 us), which times the
        move from the previous sample when both have one (else the device's times do)."""
        interval = t - self.t
        if host_t is not None and self.host_t is not None:
            interval = (host_t - self.host_t) % HOST_TIME_WRAP_S
        moving = contact and self.contact  # rule R4: no estimate at a touch-down
        self.speed_m_s = step_speed(x - self.x, y - self.y, interval, moving) * M_PER_MM
        if contact and not self.contact:
            self.touchdown_s = t
        self.t, self.x, self.y, self.contact = t, x, y, contact
        self.normal_force = max(normal_force, 0.0)
        self.host_t = host_t
        width, height = self.surface_mm
        on = bool(contact and 0 <= x <= width and 0 <= y <= height)
        self._held.append(_HeldReport(
            t, x, y, self.normal_force if on else 0.0, self.speed_m_s if on else 0.0, on,
            self.touchdown_s))

    def state(self, times: np.ndarray) -> FingerTruth:
        """The held state at ``times`` (s, rising; each call's later than the previous
        call's): at each time, that of the latest report not after it."""
        held = self._held
        n = times.shape[0]
        if n == 0:
            return self._constant(held[0], times)
        first, last = float(times[0]), float(times[-1])
        # reports superseded before this call's first time are no longer needed
        drop = 0
        while drop + 1 < len(held) and held[drop + 1].t <= first:
            drop += 1
        if drop:
            del held[:drop]
        if len(held) == 1 or held[1].t > last:
            return self._constant(held[0], times)
        starts = np.array([report.t for report in held])
        index = np.searchsorted(starts, times, side="right") - 1
        np.maximum(index, 0, out=index)

        def column(name: str) -> np.ndarray:
            return np.array([getattr(report, name) for report in held])[index]

        on = column("on")
        contact_time = np.where(on, np.maximum(times - column("touchdown_s"), 0.0), 0.0)
        truth = FingerTruth(column("x"), column("y"), column("normal_force"), on,
                            column("speed_m_s"), contact_time)
        self._held = held[int(index[-1]):]
        return truth

    @staticmethod
    def _constant(report: _HeldReport, times: np.ndarray) -> FingerTruth:
        """The state of ``report`` at every one of ``times``."""
        n = times.shape[0]
        contact_time = (np.maximum(times - report.touchdown_s, 0.0) if report.on
                        else np.zeros(n))
        x, y, force, sliding = np.array(
            [[report.x], [report.y], [report.normal_force], [report.speed_m_s]]).repeat(n, axis=1)
        contact = np.empty(n, dtype=bool)
        contact.fill(report.on)
        truth = FingerTruth(x, y, force, contact, sliding, contact_time, held=True)
        # the held values are scalars: checking them is cheaper than checking the arrays
        truth.__dict__["checked"] = (
            0.0 <= report.normal_force < math.inf and 0.0 <= report.speed_m_s < math.inf
            and math.isfinite(report.touchdown_s)
        )
        return truth


class FingerPhysics:
    """What the finger feels and what a tribometer under it measures.

    Args:
        profile: the device's predictors (its forward map is the coupled model, Eq. 4.1).
        lateral_noise_n: standard deviation of the tribometer, N.
        rng: random generator of the tribometer noise.
        finger: the bare finger's friction model (default :class:`FingerFriction`).
        hidden: physical effects the hardware hides (:mod:`.hidden`), or None.
    """

    def __init__(
        self,
        profile: DeviceProfile,
        lateral_noise_n: float,
        rng: np.random.Generator,
        finger: FingerFriction | None = None,
        hidden: HiddenPhysics | None = None,
    ) -> None:
        self.profile = profile
        self.lateral_noise_n = lateral_noise_n
        self._draws = NormalDraws(rng)
        self.finger = finger if finger is not None else FingerFriction()
        self.hidden = hidden

    @property
    def rng(self) -> np.random.Generator:
        """The random generator of the tribometer noise."""
        return self._draws.rng

    def friction(
        self, amplitude_m: np.ndarray, voltage_v: np.ndarray, truth: FingerTruth, *,
        measured: bool = False,
    ) -> np.ndarray:
        """Relative friction felt ``F_t / (mu0 Fn)`` (Eq. 4.1) per frame; 1 without contact.

        ``measured``: the amplitude and the voltage are the plate loop's and the amplifier's
        outputs, one per frame, finite and >= 0 by construction (not checked again)."""
        if not np.logical_or.reduce(truth.contact):  # .any(), without its wrapper
            return np.ones(truth.contact.shape[0])
        shape = truth.normal_force_n.shape
        trusted = (
            amplitude_m.shape == shape and voltage_v.shape == shape and truth.checked
            and (measured or (
                finite_non_negative(amplitude_m)
                # the voltage acts only through an EV channel
                and (self.profile.ev_model is None or finite_non_negative(voltage_v))
            ))
        )
        uv, ev = self.profile.forward(amplitude_m, voltage_v, truth.speed_m_s, truth.normal_force_n,
                                      trusted=trusted)
        if self.hidden:
            uv = self.hidden.uv(uv, truth)
            ev = self.hidden.ev(ev, voltage_v, truth.normal_force_n)
        return np.where(truth.contact, uv * ev, 1.0)

    def coefficient(self, truth: FingerTruth) -> np.ndarray:
        """The bare finger's friction coefficient ``mu_f = F_l / Fn`` (Eq. 1.8,
        :class:`FingerFriction`) at each frame where it presses (contact and ``Fn > 0``), 0
        elsewhere. A function of the finger's state alone (the simulation works it out with
        the internal finger's frames ahead)."""
        pressing = truth.contact & (truth.normal_force_n > 0)
        if not np.logical_or.reduce(pressing):
            return np.zeros(pressing.shape[0])
        every = np.logical_and.reduce(pressing)  # then no frame needs picking out
        inputs = {
            "normal_force": truth.normal_force_n if every else truth.normal_force_n[pressing],
            "speed": truth.speed_m_s if every else truth.speed_m_s[pressing],
            "contact_time": truth.contact_time_s if every else truth.contact_time_s[pressing],
        }
        if truth.checked:
            if truth.held:  # one speed: its factor (Fig. 1.12) is one number
                inputs["speed"] = truth.speed_m_s.item(0)
            mu = self.finger.friction_coefficient_trusted(**inputs)
        else:
            mu = self.finger.friction_coefficient(**inputs)
        if every:
            return mu
        out = np.zeros(pressing.shape[0])
        out[pressing] = mu
        return out

    def respond(self, amplitude_m: np.ndarray, voltage_v: np.ndarray, truth: FingerTruth,
                coefficient: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The friction felt (:meth:`friction`) and the lateral force measured
        (:meth:`lateral_force`) over the next frames of the simulation, from the plate loop's
        measured amplitude (m) and the amplifier's voltage envelope (V), one per frame. With
        hidden effects (:mod:`.hidden`) the amplitude and voltage under the finger, the finger's
        friction coefficient and the sensor's reading are theirs; their state moves on by
        these frames (call once per step, in order)."""
        hidden = self.hidden
        if not hidden:
            friction = self.friction(amplitude_m, voltage_v, truth, measured=True)
            return friction, self.lateral_force(friction, truth, coefficient)
        history = hidden.advance(truth)
        amplitude_m = hidden.amplitude(amplitude_m, truth)
        voltage_v = hidden.voltage(voltage_v, history)
        friction = self.friction(amplitude_m, voltage_v, truth, measured=True)
        if coefficient is None:
            coefficient = self.coefficient(truth)
        factor = hidden.finger_factor(truth, history)
        if factor is not None:
            coefficient = coefficient * factor
        force = hidden.sensor(coefficient * friction * truth.normal_force_n)
        force = force + self._draws.take(friction.shape[0]) * self.lateral_noise_n
        return friction, force

    def lateral_force(self, friction: np.ndarray, truth: FingerTruth,
                      coefficient: np.ndarray | None = None) -> np.ndarray:
        """Lateral force a tribometer measures, N: ``mu_f friction Fn`` plus noise
        (``coefficient``: :meth:`coefficient` of ``truth``, worked out when None)."""
        if coefficient is None:
            coefficient = self.coefficient(truth)
        force = coefficient * friction
        force *= truth.normal_force_n  # 0 where the finger does not press
        force += self._draws.take(friction.shape[0]) * self.lateral_noise_n
        return force
