"""Linear filters with state carried from one simulation step to the next (vectorised per step
with :func:`scipy.signal.lfilter` and its ``zi``): the numbers do not depend on how the frames
are cut into steps.

Every input is held over its frame (a zero-order hold from the frame's instant on), and each
filter is the exact discrete form of its continuous system for such an input, sampled at the
frame instants.
"""

from __future__ import annotations

import math

import numpy as np


class FirstOrderLag:
    """``1 / (1 + tau s)`` from rest: ``y_k = a y_{k-1} + (1 - a) x_{k-1}``, ``a =
    exp(-dt / tau)`` (the output at a frame's instant has not yet seen that frame's input).

    Args:
        time_constant_s: ``tau``, s (> 0).
        frame_s: frame interval ``dt``, s.
    """

    def __init__(self, time_constant_s: float, frame_s: float) -> None:
        a = math.exp(-frame_s / time_constant_s)
        self._b, self._a = np.array([0.0, 1.0 - a]), np.array([1.0, -a])
        self._zi = np.zeros(1)

    def run(self, x: np.ndarray) -> np.ndarray:
        """The output at the frames of ``x`` (the state moves on past them)."""
        from scipy.signal import lfilter

        y, self._zi = lfilter(self._b, self._a, x, zi=self._zi)
        return np.asarray(y, dtype=np.float64)


class SecondOrderSensor:
    """A force sensor of unit static gain, ``w0^2 / (s^2 + 2 zeta w0 s + w0^2)``, from rest,
    discretised exactly for the held input (zero-order hold,
    :func:`scipy.signal.cont2discrete`): at the frame instants its step response is the
    continuous one, ``1 - exp(-zeta w0 t) (cos w_d t + zeta w0 / w_d sin w_d t)`` for zeta < 1.

    Args:
        natural_frequency_hz: ``f0 = w0 / 2 pi``, Hz.
        damping_ratio: ``zeta``.
        frame_s: frame interval, s.
    """

    def __init__(self, natural_frequency_hz: float, damping_ratio: float, frame_s: float) -> None:
        from scipy.signal import cont2discrete

        w0 = 2.0 * math.pi * natural_frequency_hz
        num, den, _ = cont2discrete(([w0 * w0], [1.0, 2.0 * damping_ratio * w0, w0 * w0]),
                                    frame_s, method="zoh")
        self._b = np.asarray(num, dtype=np.float64).ravel()
        self._a = np.asarray(den, dtype=np.float64).ravel()
        self._zi = np.zeros(max(self._a.shape[0], self._b.shape[0]) - 1)

    def run(self, x: np.ndarray) -> np.ndarray:
        """The sensor's output at the frames of ``x`` (the true force, N)."""
        from scipy.signal import lfilter

        y, self._zi = lfilter(self._b, self._a, x, zi=self._zi)
        return np.asarray(y, dtype=np.float64)
