"""The finger speed actuation is given: one estimate for every host and device.

Velocity compensation (:func:`hcard.physics.actuation.actuate`) needs the finger's sliding speed
at each frame. Every user of it takes that speed from here: the simulated device's firmware
(``hcard_device.sim.simulation``) from its touch sensor's samples, and ``hcard render
--profile`` from the track it renders (the renderer's touch samples), so a card rendered with
a profile gets the commands a device with that profile computes from the same samples.

Each touch sample's speed is rule R4's two-sample estimate (:func:`hcard.render.touch.
speed_estimate`, mm/s); :func:`predicted_speed` extrapolates it to the frame times (s) over at
most the dead-reckoning horizon, as the renderer dead-reckons the position. It only looks back:
a device has no later sample.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hcard.render.touch import has_velocity, speed_estimate
from hcard.track import FingerTrack


@dataclass(frozen=True)
class TouchSamples:
    """Touch samples (M of them): time (s), position (mm) and contact, as a touch panel gives
    them to a device or a finger track to the renderer (:meth:`of_track`)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    contact: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @staticmethod
    def of_track(track: FingerTrack) -> TouchSamples:
        """The samples of a finger track (its normal force left out)."""
        return TouchSamples(track.t, track.x, track.y, np.asarray(track.contact, dtype=bool))

    @staticmethod
    def empty() -> TouchSamples:
        """No samples (one shared instance: its arrays are never written to)."""
        return _NO_SAMPLES

    def concat(self, other: TouchSamples) -> TouchSamples:
        """These samples followed by ``other`` (``self`` itself when ``other`` is empty: the
        arrays are never written to)."""
        if len(other) == 0:
            return self
        return TouchSamples(
            np.concatenate((self.t, other.t)),
            np.concatenate((self.x, other.x)),
            np.concatenate((self.y, other.y)),
            np.concatenate((self.contact, other.contact)),
        )

    @functools.cached_property
    def kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per sample (at least two): its two-sample speed (mm/s), the slope of the speed over
        two sensor periods (mm/s^2), and half the interval since the previous sample (s; 0 for
        the first), as :func:`predicted_speed` describes them. Worked out once: a device steps
        many times between two touch samples, on the same samples (do not modify them)."""
        m = len(self)
        t = self.t
        speed = speed_estimate(t, self.x, self.y, self.contact)  # spec rule R4
        dt = t[1:] - t[:-1]
        slope = np.zeros(m)
        if m > 2:
            moving = has_velocity(self.contact[1:], self.contact[:-1]) & (dt > 0)
            valid = np.concatenate(([False], moving))
            both = valid[2:] & valid[1:-1] & valid[:-2]
            np.divide(speed[2:] - speed[:-2], t[2:] - t[:-2], out=slope[2:], where=both)
        return speed, slope, np.concatenate(([0.0], dt / 2))

    def tail(self, count: int) -> TouchSamples:
        """The last ``count`` samples (``self`` itself when it has no more); their
        :attr:`kinematics` from these samples' when known (the same numbers, but for the first
        sample's speed and interval and the first three slopes, which have no samples before
        them in the tail)."""
        start = max(len(self) - count, 0)
        if start == 0:
            return self
        part = TouchSamples(self.t[start:], self.x[start:], self.y[start:], self.contact[start:])
        known = self.__dict__.get("kinematics")
        if known is not None:
            speed, slope, half = (values[start:].copy() for values in known)
            speed[0] = half[0] = 0.0
            slope[:3] = 0.0
            part.__dict__["kinematics"] = (speed, slope, half)  # as the cached property stores it
        return part


_NO_SAMPLES = TouchSamples(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool))


def hold(samples: TouchSamples, times: np.ndarray) -> np.ndarray:
    """Index of the latest sample at or before each time (-1 before the first)."""
    return samples.t.searchsorted(times, side="right") - 1


def predicted_speed(samples: TouchSamples, times: np.ndarray, horizon_s: float) -> np.ndarray:
    """Finger speed at each of the rising ``times`` (s), mm/s, predicted from the touch samples
    for velocity compensation.

    Each sample's speed is the renderer's two-sample estimate ``|p_i - p_(i-1)| / (t_i -
    t_(i-1))`` (both in contact, else 0), which describes the middle of the interval, half a
    sensor period (10 ms on a 50 Hz panel) before the sample, and is held for another period:
    a finger that speeds up is compensated ~20 ms late. The prediction extrapolates it linearly,
    ``s(t) = s_i + a_i (t - t_i + (t_i - t_(i-1)) / 2)`` over at most ``horizon_s``, with the slope
    ``a_i = (s_i - s_(i-2)) / (t_i - t_(i-2))`` taken over two sensor periods (half the noise of
    a one-period slope), and is never negative; ``a_i = 0`` until a contact has four samples.
    Times before the first sample get 0.
    """
    out = np.zeros(times.shape[0])
    if len(samples) < 2:
        return out
    speed, slope, half = samples.kinematics
    index = hold(samples, times)
    if index.shape[0] and index[0] == index[-1]:  # the index never falls
        # Every time holds one sample (the common block between two touch samples).
        i = index.item(0)
        if i < 0:
            return out
        ahead = np.minimum(times - samples.t.item(i) + half.item(i), horizon_s)
        return np.maximum(speed.item(i) + slope.item(i) * ahead, 0.0, out=out)
    known = index >= 0
    everywhere = bool(known.all())
    i = index if everywhere else index[known]
    ahead = np.minimum((times if everywhere else times[known]) - samples.t[i] + half[i], horizon_s)
    out[known] = np.maximum(speed[i] + slope[i] * ahead, 0.0)
    return out
