"""Model-based rendering: target relative friction per channel to actuator commands.

The renderer gives, per frame, the UV target ``uv`` in [0, 1] and the EV target ``ev`` >= 1
(``Frames.uv``, ``Frames.ev``); the total is ``uv * ev`` (Eq. 4.1). With the finger state
(speed, normal force) a :class:`~hcard.physics.profile.DeviceProfile` turns them into

- the peak-to-peak plate amplitude ``w`` (m): the UV model's inverse at the finger speed, so the
  amplitude follows the speed and the same card feels the same at 20 and 100 mm/s (velocity
  compensation through the dimensionless group, Eqs. 2.30-2.33);
- the peak voltage envelope ``V`` (V) of the sinusoidal EV carrier: the EV force needed is
  ``F_e = (ev - 1) F_n`` (Eq. 4.1); a carrier ``V sin(2 pi f_c t)`` through the leakage gain
  ``g`` (Eq. 3.22) gives the mean force ``F(g V / sqrt 2)`` for a force going as ``v^2``
  (Eqs. 3.12, 3.23), so ``V = sqrt(2) F^-1(F_e) / g``;

clipped to the device limits (plate amplitude, amplifier voltage, user current), with a report
of what was clipped and by how much friction the rendering falls short.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from hcard.physics.predictor import PredictorError

if TYPE_CHECKING:
    from hcard.physics.profile import DeviceProfile
    from hcard.render import Frames

DEFAULT_SPEED_FLOOR = 5e-3
"""Slowest finger speed used for velocity compensation, m/s (the low end of the 5-100 mm/s
exploration range of Fig. 2.24). A slower or resting finger gets the amplitude for this speed:
the dimensionless group (Eq. 2.30) has no finite amplitude for U = 0."""

UV_TARGET_FLOOR = 1e-6
"""Smallest UV target handed to the inverse: ``mu' = 0`` needs an infinite amplitude in the
dimensionless group (Eq. 2.33), so lower targets are solved at this value (and then clipped to
the device's largest amplitude, with the shortfall reported)."""

TARGET_TOLERANCE = 1e-9
"""Slack on the channel ranges: ``uv`` may be up to this much above 1, ``ev`` below 1."""

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
    """

    amplitude: np.ndarray
    voltage: np.ndarray
    carrier_frequency: float
    plate_frequency: float
    uv: np.ndarray
    ev: np.ndarray
    uv_clipping: ChannelClipping
    ev_clipping: ChannelClipping

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

    def summary(self) -> str:
        """One line per channel: clipped frames, limit, worst shortfall."""
        return f"{self.uv_clipping}\n{self.ev_clipping}"


def _checked_targets(
    uv: Any, ev: Any, speed: Any, normal_force: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    arrays = [np.asarray(a, dtype=np.float64) for a in (uv, ev, speed, normal_force)]
    try:
        uv_a, ev_a, speed_a, fn_a = np.broadcast_arrays(*arrays)
    except ValueError:
        shapes = ", ".join(str(a.shape) for a in arrays)
        raise PredictorError(
            f"uv, ev, speed and normal_force have shapes that do not broadcast: {shapes}"
        ) from None
    for name, values in (("uv", uv_a), ("ev", ev_a), ("speed", speed_a),
                         ("normal_force", fn_a)):
        if not np.all(np.isfinite(values)):
            raise PredictorError(f"{name}: all values must be finite")
    if np.any(uv_a < -TARGET_TOLERANCE) or np.any(uv_a > 1 + TARGET_TOLERANCE):
        raise PredictorError(
            f"uv: UV target relative friction must lie in [0, 1] (UV only lowers friction), "
            f"got {uv_a.min():g}..{uv_a.max():g}"
        )
    if np.any(ev_a < 1 - TARGET_TOLERANCE):
        raise PredictorError(
            f"ev: EV target relative friction must be >= 1 (EV only raises friction), "
            f"got {ev_a.min():g}"
        )
    if np.any(speed_a < 0):
        raise PredictorError(f"speed: must be >= 0 m/s, got {speed_a.min():g}")
    if np.any(fn_a < 0):
        raise PredictorError(f"normal_force: must be >= 0 N, got {fn_a.min():g}")
    return np.clip(uv_a, 0.0, 1.0), np.maximum(ev_a, 1.0), speed_a, fn_a


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
    uv_t, ev_t, speed_a, fn_a = _checked_targets(uv, ev, speed, normal_force)
    limits = profile.rendering_limits()
    if profile.uv_model is None and profile.ev_model is None:
        raise PredictorError(
            f"profile {profile.name!r}: model {profile.predictor.name!r} renders neither "
            "channel; a device profile needs a UV relative-friction model with an amplitude "
            "inverse, an EV force model (N) with a voltage inverse, or 'coupled'"
        )
    state_speed = np.maximum(speed_a, speed_floor)
    frames = int(uv_t.size)

    # UV: plate amplitude from the inverse of the relative-friction model.
    amplitude = np.zeros(uv_t.shape)
    wants_uv = uv_t < 1.0
    if profile.uv_model is not None:
        uv_limit, uv_limit_name = limits.max_amplitude, "max_amplitude"
        raw = np.zeros(uv_t.shape)
        if np.any(wants_uv):
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                solved = profile.amplitude_for(
                    np.maximum(uv_t[wants_uv], UV_TARGET_FLOOR),
                    state_speed[wants_uv],
                    fn_a[wants_uv],
                )
            solved = np.asarray(solved, dtype=np.float64)
            if np.any(np.isnan(solved)):
                raise PredictorError(
                    f"UV model {profile.uv_model.name!r} gave no amplitude for some targets"
                )
            raw[wants_uv] = solved
        uv_clipped = raw > uv_limit * (1.0 + _CLIP_SLACK)
        amplitude = np.clip(raw, 0.0, uv_limit)
    else:
        uv_limit_name = "no UV channel"
        uv_clipped = wants_uv

    # EV: voltage envelope from the inverse of the force model, F_e = (ev - 1) F_n.
    voltage = np.zeros(ev_t.shape)
    force = (ev_t - 1.0) * fn_a
    if profile.ev_model is not None:
        v_limit, ev_limit_name = profile.voltage_limit
        raw_v = profile.voltage_for(force, fn_a)
        ev_clipped = raw_v > v_limit * (1.0 + _CLIP_SLACK)
        voltage = np.minimum(raw_v, v_limit)
    else:
        ev_limit_name = "no EV channel"
        ev_clipped = force > 0

    rendered_uv, rendered_ev = profile.forward(amplitude, voltage, state_speed, fn_a)
    return ActuatorCommands(
        amplitude=amplitude,
        voltage=voltage,
        carrier_frequency=limits.carrier_frequency,
        plate_frequency=limits.plate_frequency,
        uv=rendered_uv,
        ev=rendered_ev,
        uv_clipping=_report("uv", frames, uv_clipped, uv_limit_name, rendered_uv - uv_t),
        ev_clipping=_report("ev", frames, ev_clipped, ev_limit_name, ev_t - rendered_ev),
    )


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
