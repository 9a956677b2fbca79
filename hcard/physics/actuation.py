"""Model-based rendering: target relative friction per channel to actuator commands.

The renderer gives, per frame, the UV target ``uv`` in [0, 1] and the EV target ``ev`` >= 1
(``Frames.uv``, ``Frames.ev``); the total is ``uv * ev`` (Eq. 4.1). With the finger state
(speed, normal force) a :class:`~hcard.physics.profile.DeviceProfile` turns them into

- the peak-to-peak plate amplitude ``w`` (m): the UV model's inverse at the finger speed, so the
  amplitude follows the speed and the same card feels the same at 20 and 100 mm/s (velocity
  compensation through the dimensionless group, Eqs. 2.30-2.33, stated for w > 1 um; or, valid
  at any amplitude, through the numerical inverse of the spring-slider, Eqs. 2.19-2.28, for a
  profile whose UV model is ``"spring-slider"``);
- the peak voltage envelope ``V`` (V) of the sinusoidal EV carrier: the EV force needed is
  ``F_e = (ev - 1) F_n`` (Eq. 4.1); a carrier ``V sin(2 pi f_c t)`` through the leakage gain
  ``g`` (Eq. 3.22) gives the mean force ``F(g V / sqrt 2)`` for a force going as ``v^2``
  (Eqs. 3.12, 3.23), so ``V = sqrt(2) F^-1(F_e) / g``;

clipped to the device limits (plate amplitude, amplifier voltage, user current), with a report
of what was clipped and by how much friction the rendering falls short.

The friction reported (``ActuatorCommands.uv``) is the forward model at the finger's actual
speed, even where the amplitude was chosen at the speed floor: a finger slower than the floor
feels less friction than the target (Eq. 2.30: ``Psi`` falls with ``U``), and that shortfall is
reported (:class:`UVModelRange`). A UV model with a stated amplitude range (the dimensionless
group: w > 1 um, sections 2.7.1, 2.10) has every frame whose amplitude falls below it flagged
(``ActuatorCommands.uv_out_of_range``), since there the model's friction is not to be trusted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from hcard.physics.predictor import PredictorError
from hcard.quantities import UM_PER_M

if TYPE_CHECKING:
    from hcard.physics.device_limits import DeviceLimits
    from hcard.physics.profile import DeviceProfile
    from hcard.render import Frames

DEFAULT_SPEED_FLOOR = 5e-3
"""Slowest finger speed used for velocity compensation, m/s (the low end of the 5-100 mm/s
exploration range of Fig. 2.24). A slower or resting finger gets the amplitude for this speed:
the dimensionless group (Eq. 2.30) has no finite amplitude for U = 0. The friction reported
is that of this amplitude at the finger's actual speed."""

UV_TARGET_FLOOR = 1e-6
"""Smallest UV target handed to the inverse: ``mu' = 0`` needs an infinite amplitude in the
dimensionless group (Eq. 2.33), so lower targets are solved at this value (and then clipped to
the device's largest amplitude, with the shortfall reported)."""

TARGET_TOLERANCE = 1e-9
"""Slack on the channel ranges: ``uv`` may be up to this much above 1, ``ev`` below 1."""

REACH_TOLERANCE = 1e-3
"""A frame whose rendered UV friction misses its target by more than this, with no clipping
and at or above the speed floor, is counted unreachable (:class:`UVModelRange`)."""

_CLIP_SLACK = 1e-9
"""A raw command counts as clipped only when it exceeds its limit by this relative margin."""


@dataclass(frozen=True)
class ChannelClipping:
    """Clipping of one channel over a rendering.

    Attributes:
        channel: ``"uv"`` or ``"ev"``.
        frames: number of frames rendered.
        clipped: frames whose command was held at a limit (or that need a missing channel).
        limit: the limit that clipped (``"max_amplitude"``, ``"max_voltage"``,
            ``"max_current"``, ``"no UV channel"``, ``"no EV channel"``; ``""`` if none).
        worst_shortfall: the largest ``|rendered - target|`` relative friction over clipped
            frames (0 when nothing was clipped).
    """

    channel: str
    frames: int
    clipped: int
    limit: str
    worst_shortfall: float

    @property
    def fraction(self) -> float:
        """Share of the frames that were clipped, in [0, 1]."""
        return self.clipped / self.frames if self.frames else 0.0

    def __str__(self) -> str:
        if not self.clipped:
            return f"{self.channel}: no clipping"
        return (
            f"{self.channel}: {self.clipped} of {self.frames} frames "
            f"({100 * self.fraction:.1f}%) clipped by {self.limit}, worst shortfall "
            f"{self.worst_shortfall:.3f} relative friction"
        )


@dataclass(frozen=True)
class UVModelRange:
    """Where the UV rendering leaves the conditions its model was chosen for.

    Attributes:
        frames: number of frames rendered.
        below_amplitude_range: frames with vibration whose amplitude is below the UV model's
            stated range (``amplitude_minimum``); their rendered friction is an extrapolation.
        amplitude_minimum: that bound, m (None: the model states no bound).
        source: where the bound comes from (e.g. "Eq. 2.33 holds for w > 1 um ...").
        below_speed_floor: frames with vibration where the finger is slower than the speed
            floor; their amplitude was chosen at the floor and the friction reported is the one
            it gives at the actual speed.
        worst_speed_shortfall: largest ``|target - rendered|`` relative friction over those
            frames (0 when there are none).
        unreachable: frames at or above the speed floor, not clipped, whose rendered friction
            still misses the target by more than :data:`REACH_TOLERANCE` (the model has no
            amplitude for it, e.g. inside the jump of the spring-slider at ``w_c``).
        worst_unreachable: largest ``|target - rendered|`` over those frames (0 if none).
    """

    frames: int
    below_amplitude_range: int
    amplitude_minimum: float | None
    source: str
    below_speed_floor: int
    worst_speed_shortfall: float
    unreachable: int = 0
    worst_unreachable: float = 0.0

    @property
    def warnings(self) -> tuple[str, ...]:
        """One line per condition that holds (empty when the rendering is within range)."""
        lines = []
        if self.below_amplitude_range and self.amplitude_minimum is not None:
            lines.append(
                f"uv: {self.below_amplitude_range} of {self.frames} frames have an amplitude "
                f"below {self.amplitude_minimum * UM_PER_M:g} um, outside the UV model's range "
                f"({self.source}); their friction is extrapolated"
            )
        if self.below_speed_floor:
            lines.append(
                f"uv: {self.below_speed_floor} of {self.frames} frames are slower than the "
                f"speed floor; friction reported at the actual speed, worst shortfall "
                f"{self.worst_speed_shortfall:.3f} relative friction"
            )
        if self.unreachable:
            lines.append(
                f"uv: {self.unreachable} of {self.frames} frames ask for a friction the UV "
                f"model reaches at no amplitude; worst miss {self.worst_unreachable:.3f} "
                "relative friction"
            )
        return tuple(lines)


@dataclass(frozen=True)
class ActuatorCommands:
    """Actuator commands for a sequence of frames, and what they render.

    Attributes:
        amplitude: peak-to-peak plate vibration amplitude, m, at ``plate_frequency``.
        voltage: peak envelope of the EV carrier, V (see :meth:`voltage_waveform`).
        carrier_frequency: EV carrier frequency, Hz.
        plate_frequency: plate vibration frequency, Hz.
        uv: UV relative friction the profile's forward model predicts for ``amplitude``.
        ev: EV relative friction it predicts for ``voltage``.
        uv_clipping: clipping report of the UV channel.
        ev_clipping: clipping report of the EV channel.
        uv_out_of_range: per frame, True where the amplitude is below the UV model's stated
            range (see :class:`UVModelRange`).
        uv_range: the UV model's range report.
        uv_clipped: per frame, True where the UV command was held at its limit (or the profile
            has no UV channel and the target is below 1). Use it, not ``uv > target``, to flag
            clipping: below the speed floor the friction reported is that at the actual speed,
            which may lie below the target without any clipping.
        ev_clipped: per frame, the same for the EV channel.

    Commands made by :func:`actuate` compute the reports (``uv_clipping``, ``ev_clipping``,
    ``uv_out_of_range``, ``uv_range``, ``uv_clipped``, ``ev_clipped``) when one of them is
    first read, from copies of what they depend on: a real-time caller that only drives the
    actuators does not pay for them, and every reader sees the same values as if they had
    been computed with the commands.
    """

    amplitude: np.ndarray
    voltage: np.ndarray
    carrier_frequency: float
    plate_frequency: float
    uv: np.ndarray
    ev: np.ndarray
    uv_clipping: ChannelClipping
    ev_clipping: ChannelClipping
    uv_out_of_range: np.ndarray
    uv_range: UVModelRange
    uv_clipped: np.ndarray
    ev_clipped: np.ndarray

    @classmethod
    def _deferred(
        cls,
        amplitude: np.ndarray,
        voltage: np.ndarray,
        limits: DeviceLimits,
        uv: np.ndarray,
        ev: np.ndarray,
        basis: _ReportBasis,
    ) -> ActuatorCommands:
        """Commands whose reports are computed from ``basis`` on first access."""
        commands = object.__new__(cls)
        commands.__dict__.update(  # frozen: set as the dataclass __init__ would
            amplitude=amplitude, voltage=voltage, carrier_frequency=limits.carrier_frequency,
            plate_frequency=limits.plate_frequency, uv=uv, ev=ev, _basis=basis,
        )
        return commands

    def __getattr__(self, name: str) -> Any:
        # Called only for an attribute not set: a report of deferred commands.
        basis = self.__dict__.get("_basis")
        if basis is None or name not in _REPORTS:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.__dict__.update(basis.reports())
        del self.__dict__["_basis"]
        return self.__dict__[name]

    @property
    def friction(self) -> np.ndarray:
        """Rendered total relative friction ``uv * ev`` = ``F_t / (mu0 F_n)`` (Eq. 4.1)."""
        return self.uv * self.ev

    @property
    def clipped(self) -> bool:
        """True when any frame of either channel was clipped."""
        return bool(self.uv_clipping.clipped or self.ev_clipping.clipped)

    def voltage_waveform(self, t: Any) -> np.ndarray:
        """The EV drive ``V(t) sin(2 pi f_c t)``, V, at the frame times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        return self.voltage * np.sin(2.0 * math.pi * self.carrier_frequency * t)

    @property
    def warnings(self) -> tuple[str, ...]:
        """Lines about frames rendered outside the UV model's range or below the speed floor."""
        return self.uv_range.warnings

    def summary(self) -> str:
        """One line per channel (clipped frames, limit, worst shortfall), then one per
        :attr:`warnings` entry."""
        return "\n".join((str(self.uv_clipping), str(self.ev_clipping), *self.warnings))


def combined_clipping(parts: Sequence[ChannelClipping]) -> ChannelClipping:
    """The clipping of one channel over consecutive blocks of a rendering, as one report."""
    return ChannelClipping(
        parts[0].channel,
        sum(p.frames for p in parts),
        sum(p.clipped for p in parts),
        next((p.limit for p in parts if p.limit), ""),
        max(p.worst_shortfall for p in parts),
    )


def combined_range(parts: Sequence[UVModelRange]) -> UVModelRange:
    """The UV range report over consecutive blocks of a rendering, as one report."""
    return UVModelRange(
        sum(p.frames for p in parts),
        sum(p.below_amplitude_range for p in parts),
        parts[0].amplitude_minimum,
        parts[0].source,
        sum(p.below_speed_floor for p in parts),
        max(p.worst_speed_shortfall for p in parts),
        sum(p.unreachable for p in parts),
        max(p.worst_unreachable for p in parts),
    )


_REPORTS = ("uv_clipping", "ev_clipping", "uv_out_of_range", "uv_range", "uv_clipped",
            "ev_clipped")
"""The fields of :class:`ActuatorCommands` that :func:`actuate` defers."""


class _ReportBasis(NamedTuple):
    """What the reports of one :func:`actuate` call are made of (copies: the caller may
    change its arrays before the reports are read).

    Attributes:
        profile: the device profile.
        frames: number of frames.
        uv_target, ev_target: the checked targets.
        speed: finger speed, m/s.
        speed_floor: the speed floor of the rendering, m/s.
        normal_force: finger normal force, N.
        amplitude: plate amplitude commanded, m.
        uv, ev: relative friction rendered per channel.
        uv_clipped: frames whose UV command was held at its limit (or need a missing
            channel).
        ev_clipped: the same for EV; None without an EV channel (then every frame that asks
            for an EV force, ``(ev - 1) F_n > 0``).
        uv_limit, ev_limit: the limit (or missing channel) that clips each channel.
    """

    profile: DeviceProfile
    frames: int
    uv_target: np.ndarray
    ev_target: np.ndarray
    speed: np.ndarray
    speed_floor: float
    normal_force: np.ndarray
    amplitude: np.ndarray
    uv: np.ndarray
    ev: np.ndarray
    uv_clipped: np.ndarray
    ev_clipped: np.ndarray | None
    uv_limit: str
    ev_limit: str

    def reports(self) -> dict[str, Any]:
        """The deferred fields of :class:`ActuatorCommands` (:data:`_REPORTS`)."""
        ev_clipped = self.ev_clipped
        if ev_clipped is None:
            ev_clipped = (self.ev_target - 1.0) * self.normal_force > 0
        uv_shortfall = self.uv - self.uv_target
        uv_range, out_of_range = _uv_range(
            self.profile, self.amplitude, self.speed < self.speed_floor, uv_shortfall,
            self.uv_clipped | (self.normal_force == 0),
        )
        return {
            "uv_clipping": _report("uv", self.frames, self.uv_clipped, self.uv_limit,
                                   uv_shortfall),
            "ev_clipping": _report("ev", self.frames, ev_clipped, self.ev_limit,
                                   self.ev_target - self.ev),
            "uv_out_of_range": out_of_range,
            "uv_range": uv_range,
            "uv_clipped": np.array(self.uv_clipped, dtype=bool),
            "ev_clipped": np.array(ev_clipped, dtype=bool),
        }


def _checked_targets(
    uv: Any, ev: Any, speed: Any, normal_force: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """The four inputs of :func:`actuate` as float64 arrays of one shape, checked, with the
    targets clipped to their channel's range (the tolerance of :data:`TARGET_TOLERANCE`
    removed), and the smallest and largest UV target, the smallest EV target and the smallest
    speed before clipping (:func:`_ranges`); :class:`PredictorError` naming the first bad
    input."""
    arrays = [np.asarray(a, dtype=np.float64) for a in (uv, ev, speed, normal_force)]
    shape = arrays[0].shape
    if not arrays[1].shape == arrays[2].shape == arrays[3].shape == shape:
        try:
            arrays = list(np.broadcast_arrays(*arrays))
        except ValueError:
            shapes = ", ".join(str(a.shape) for a in arrays)
            raise PredictorError(
                f"uv, ev, speed and normal_force have shapes that do not broadcast: {shapes}"
            ) from None
    uv_a, ev_a, speed_a, fn_a = arrays
    ranges = _ranges(uv_a, ev_a, speed_a, fn_a)
    if ranges is None:
        _raise_bad_targets(uv_a, ev_a, speed_a, fn_a)
        ranges = (math.nan,) * 4  # nothing was wrong (an empty block): nothing is known
    uv_low, uv_high, ev_low, _ = ranges
    # Targets already inside their range are used as they are (clipping would copy them).
    if not (uv_low >= 0.0 and uv_high <= 1.0):
        uv_a = np.clip(uv_a, 0.0, 1.0)
    if not ev_low >= 1.0:
        ev_a = np.maximum(ev_a, 1.0)
    return uv_a, ev_a, speed_a, fn_a, ranges


def _ranges(
    uv: np.ndarray, ev: np.ndarray, speed: np.ndarray, normal_force: np.ndarray
) -> tuple[float, float, float, float] | None:
    """``(min uv, max uv, min ev, min speed)`` when all four arrays (of one shape) are valid
    inputs of
    :func:`actuate` (finite; ``uv`` in [0, 1] and ``ev`` >= 1 within :data:`TARGET_TOLERANCE`;
    speed and force >= 0), else None (and for empty arrays). A NaN makes a minimum and a
    maximum NaN, which fails its comparison, and an infinity fails one too."""
    if uv.size == 0:
        return None
    values = np.array((uv, ev, speed, normal_force)).reshape(4, -1)
    (uv_low, ev_low, speed_low, force_low) = np.minimum.reduce(values, axis=1).tolist()
    (uv_high, ev_high, speed_high, force_high) = np.maximum.reduce(values, axis=1).tolist()
    valid = (
        uv_low >= -TARGET_TOLERANCE and uv_high <= 1 + TARGET_TOLERANCE
        and ev_low >= 1 - TARGET_TOLERANCE and ev_high < math.inf
        and speed_low >= 0.0 and speed_high < math.inf
        and force_low >= 0.0 and force_high < math.inf
    )
    return (uv_low, uv_high, ev_low, speed_low) if valid else None


def _raise_bad_targets(
    uv: np.ndarray, ev: np.ndarray, speed: np.ndarray, normal_force: np.ndarray
) -> None:
    """:class:`PredictorError` naming the first input of :func:`actuate` that is not finite or
    outside its range (returns when there is none)."""
    for name, values in (("uv", uv), ("ev", ev), ("speed", speed),
                         ("normal_force", normal_force)):
        if not np.all(np.isfinite(values)):
            raise PredictorError(f"{name}: all values must be finite")
    if np.any(uv < -TARGET_TOLERANCE) or np.any(uv > 1 + TARGET_TOLERANCE):
        raise PredictorError(
            f"uv: UV target relative friction must lie in [0, 1] (UV only lowers friction), "
            f"got {uv.min():g}..{uv.max():g}"
        )
    if np.any(ev < 1 - TARGET_TOLERANCE):
        raise PredictorError(
            f"ev: EV target relative friction must be >= 1 (EV only raises friction), "
            f"got {ev.min():g}"
        )
    if np.any(speed < 0):
        raise PredictorError(f"speed: must be >= 0 m/s, got {speed.min():g}")
    if np.any(normal_force < 0):
        raise PredictorError(f"normal_force: must be >= 0 N, got {normal_force.min():g}")


def actuate(
    profile: DeviceProfile,
    uv: Any,
    ev: Any,
    speed: Any,
    normal_force: Any,
    *,
    speed_floor: float = DEFAULT_SPEED_FLOOR,
) -> ActuatorCommands:
    """Actuator commands rendering target relative friction with ``profile``.

    Args:
        profile: the device profile (predictor, leakage, limits).
        uv: UV target relative friction ``mu(w)/mu0`` in [0, 1] (``Frames.uv``).
        ev: EV target relative friction ``(F_n + F_e)/F_n`` >= 1 (``Frames.ev``).
        speed: finger speed, m/s.
        normal_force: finger normal force, N.
        speed_floor: the speed below which the amplitude is computed at ``speed_floor``, m/s
            (:data:`DEFAULT_SPEED_FLOOR`).

    All four broadcast together. Frames with ``uv = 1`` get no vibration and frames with
    ``ev = 1`` (or ``F_n = 0``) no voltage.

    The inputs are checked once, here; the profile's models then run without checking them
    again (``trusted``), which keeps the cost of a real-time block of a few frames low.

    Returns:
        The commands, the friction their forward model renders (at the same state) and the
        clipping report. A channel the profile cannot drive counts as clipped wherever its
        target differs from 1.

    Raises:
        PredictorError: targets outside their channel's range, negative or non-finite speed
            or force, or a model that returns no command for a valid target.
    """
    if not (math.isfinite(speed_floor) and speed_floor > 0):
        raise PredictorError(f"speed_floor: must be a finite number > 0 m/s, got {speed_floor}")
    uv_t, ev_t, speed_a, fn_a, (uv_low, uv_high, _, speed_low) = _checked_targets(
        uv, ev, speed, normal_force
    )
    limits = profile.rendering_limits()
    if profile.uv_model is None and profile.ev_model is None:
        raise PredictorError(
            f"profile {profile.name!r}: model {profile.predictor.name!r} renders neither "
            "channel; a device profile needs a UV relative-friction model with an amplitude "
            "inverse, an EV force model (N) with a voltage inverse, or 'coupled'"
        )
    frames = int(uv_t.size)

    # UV: plate amplitude from the inverse of the relative-friction model. The target range
    # tells when every frame, or none, wants vibration (uv < 1) without comparing each.
    wants_uv = None if uv_high < 1.0 or uv_low >= 1.0 else uv_t < 1.0
    if profile.uv_model is not None:
        uv_limit, uv_limit_name = limits.max_amplitude, "max_amplitude"
        if uv_low >= 1.0:
            raw = np.zeros(uv_t.shape)
        else:
            state_speed = speed_a if speed_low >= speed_floor else np.maximum(speed_a,
                                                                               speed_floor)
            raw = _uv_amplitude(profile, uv_t, wants_uv, state_speed, fn_a)
        uv_clipped = raw > uv_limit * (1.0 + _CLIP_SLACK)
        amplitude = np.minimum(np.maximum(raw, 0.0), uv_limit)  # clipped to [0, limit]
    else:
        amplitude = np.zeros(uv_t.shape)
        uv_limit_name = "no UV channel"
        uv_clipped = uv_t < 1.0

    # EV: voltage envelope from the inverse of the force model, F_e = (ev - 1) F_n.
    if profile.ev_model is not None:
        v_limit, ev_limit_name = profile.voltage_limit
        raw_v = profile.voltage_for((ev_t - 1.0) * fn_a, fn_a, trusted=True)
        ev_clipped = raw_v > v_limit * (1.0 + _CLIP_SLACK)
        voltage = np.minimum(raw_v, v_limit)
    else:
        voltage = np.zeros(ev_t.shape)
        ev_limit_name = "no EV channel"
        ev_clipped = None  # every frame that asks for EV force: made with the reports

    # The friction the commands give the finger at its actual speed (Eq. 2.30 has U in it).
    rendered_uv, rendered_ev = profile.forward(amplitude, voltage, speed_a, fn_a, trusted=True)
    # what the reports need, copied in one go (the caller may change these arrays later)
    saved = np.array((uv_t, ev_t, speed_a, fn_a, amplitude, rendered_uv, rendered_ev))
    basis = _ReportBasis(
        profile=profile,
        frames=frames,
        uv_target=saved[0],
        ev_target=saved[1],
        speed=saved[2],
        speed_floor=speed_floor,
        normal_force=saved[3],
        amplitude=saved[4],
        uv=saved[5],
        ev=saved[6],
        uv_clipped=uv_clipped,
        ev_clipped=ev_clipped,
        uv_limit=uv_limit_name,
        ev_limit=ev_limit_name,
    )
    return ActuatorCommands._deferred(amplitude, voltage, limits, rendered_uv, rendered_ev,
                                      basis)


def _uv_amplitude(
    profile: DeviceProfile,
    uv: np.ndarray,
    wants_uv: np.ndarray | None,
    state_speed: np.ndarray,
    normal_force: np.ndarray,
) -> np.ndarray:
    """Raw (unclipped) plate amplitude, m: the UV model's inverse for the frames that want
    vibration (``wants_uv``, None: every frame; targets floored at :data:`UV_TARGET_FLOOR`),
    0 elsewhere. ``state_speed``: the finger speed, floored (m/s)."""
    if wants_uv is not None and not np.logical_or.reduce(wants_uv, axis=None):
        return np.zeros(uv.shape)
    every = wants_uv is None or np.logical_and.reduce(wants_uv, axis=None)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        solved = profile.amplitude_for(
            np.maximum(uv if every else uv[wants_uv], UV_TARGET_FLOOR),
            state_speed if every else state_speed[wants_uv],
            normal_force if every else normal_force[wants_uv],
            trusted=True,
        )
    solved = np.asarray(solved, dtype=np.float64)
    if np.logical_or.reduce(np.isnan(solved), axis=None):
        raise PredictorError(
            f"UV model {profile.uv_model.name!r} gave no amplitude for some targets"  # type: ignore[union-attr]
        )
    if every and solved.shape == uv.shape:
        return solved  # read only: the caller clips it into a new array
    raw = np.zeros(uv.shape)
    if every:
        raw[...] = solved
    else:
        raw[wants_uv] = solved
    return raw


def _uv_range(
    profile: DeviceProfile,
    amplitude: np.ndarray,
    slow: np.ndarray,
    shortfall: np.ndarray,
    excused: np.ndarray,
) -> tuple[UVModelRange, np.ndarray]:
    """The :class:`UVModelRange` of a rendering and its per-frame out-of-range mask.

    ``excused`` frames (clipped, or without load: no friction to modulate) count neither as
    slow nor as unreachable."""
    clipped = excused
    vibrating = amplitude > 0
    model = profile.uv_model
    minimum = getattr(model, "valid_amplitude_min", None) if model is not None else None
    source = getattr(model, "valid_amplitude_source", "") if minimum is not None else ""
    if minimum is None:
        out_of_range = np.zeros(amplitude.shape, dtype=bool)
    else:
        out_of_range = vibrating & (amplitude < float(minimum))
    slow_vibrating = slow & vibrating & ~clipped
    count = int(np.count_nonzero(slow_vibrating))
    worst = float(np.max(np.abs(shortfall[slow_vibrating]))) if count else 0.0
    missed = ~slow & ~clipped & (np.abs(shortfall) > REACH_TOLERANCE)
    if model is None:
        missed = np.zeros(amplitude.shape, dtype=bool)
    unreachable = int(np.count_nonzero(missed))
    report = UVModelRange(
        frames=int(amplitude.size),
        below_amplitude_range=int(np.count_nonzero(out_of_range)),
        amplitude_minimum=None if minimum is None else float(minimum),
        source=source,
        below_speed_floor=count,
        worst_speed_shortfall=worst,
        unreachable=unreachable,
        worst_unreachable=float(np.max(np.abs(shortfall[missed]))) if unreachable else 0.0,
    )
    return report, out_of_range


def actuate_frames(
    profile: DeviceProfile,
    frames: Frames,
    speed: Any,
    normal_force: Any,
    **options: Any,
) -> ActuatorCommands:
    """:func:`actuate` for rendered :class:`~hcard.render.Frames` (``frames.uv``,
    ``frames.ev``); ``speed`` (m/s) and ``normal_force`` (N) are per frame or scalars."""
    return actuate(profile, frames.uv, frames.ev, speed, normal_force, **options)


def _report(
    channel: str, frames: int, clipped: np.ndarray, limit: str, shortfall: np.ndarray
) -> ChannelClipping:
    count = int(np.count_nonzero(clipped))
    worst = float(np.max(np.abs(shortfall[clipped]))) if count else 0.0
    return ChannelClipping(channel, frames, count, limit if count else "", worst)
