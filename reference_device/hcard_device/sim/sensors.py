"""The E-ViTa's sensors (thesis section 5.1.1): a 50 Hz capacitive touch screen and four
resistive force sensors under the corners of the plate.

Touch: the panel samples the finger at its own clock (``k / f_touch``) with a small position
jitter and reports contact; the device holds the latest sample until the next one
(sample-and-hold), and the renderer derives the finger velocity from the last two samples of a
contact.

Forces: a rigid plate on four corner supports. The finger's normal force at ``(x, y)`` on a
``W x H`` surface splits by the lever rule along each axis (bilinear weights)::

    F_tl = Fn (1 - x/W)(1 - y/H),  F_tr = Fn (x/W)(1 - y/H),
    F_bl = Fn (1 - x/W)(y/H),      F_br = Fn (x/W)(y/H),

(origin top-left, +y down) which sum to ``Fn`` and balance its moments, so the finger is located
by ``x = W (F_tr + F_br) / sum F``, ``y = H (F_bl + F_br) / sum F`` (:func:`locate`). Each sensor
adds independent Gaussian noise.
"""

from __future__ import annotations

import math

import numpy as np

from hcard.render.finger_speed import TouchSamples

CORNERS = ("top-left", "top-right", "bottom-left", "bottom-right")
"""Order of the four corner sensors in every (N, 4) force array."""

NOISE_BATCH = 8192
"""Standard normal numbers a :class:`NormalDraws` takes from its generator at a time."""


class NormalDraws:
    """Standard normal numbers from one generator, handed out in order.

    A :class:`numpy.random.Generator` gives the same sequence however its normal draws are
    batched, so drawing :data:`NOISE_BATCH` numbers at a time and handing them out in order
    gives a sensor exactly the numbers it would draw itself on every call, without the cost of
    a small draw per simulation step.

    Args:
        rng: the generator (used by nothing else).
    """

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._buffer = np.zeros(0)
        self._next = 0

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` numbers (read-only)."""
        start, end = self._next, self._next + count
        if end <= self._buffer.shape[0]:
            self._next = end
            return self._buffer[start:end]
        rest = self._buffer[start:]
        self._buffer = self.rng.normal(0.0, 1.0, size=max(NOISE_BATCH, count - rest.shape[0]))
        self._buffer.flags.writeable = False
        self._next = count - rest.shape[0]
        if not rest.shape[0]:
            return self._buffer[: self._next]
        return np.concatenate((rest, self._buffer[: self._next]))


class TouchSensor:
    """A touch panel sampling at ``rate_hz`` with Gaussian jitter ``noise_mm`` (mm, per axis).

    Args:
        rate_hz: sampling rate, Hz (its clock ticks at whole multiples of ``1 / rate_hz``).
        noise_mm: standard deviation of the position jitter, mm.
        rng: random generator of the jitter.
    """

    def __init__(self, rate_hz: float, noise_mm: float, rng: np.random.Generator) -> None:
        self.rate_hz = rate_hz
        self.noise_mm = noise_mm
        self._draws = NormalDraws(rng)

    @property
    def rng(self) -> np.random.Generator:
        """The random generator of the jitter."""
        return self._draws.rng

    def sample_times(self, t0: float, t1: float) -> np.ndarray:
        """The sensor's sample times in ``[t0, t1)``, s."""
        first = math.ceil(t0 * self.rate_hz - 1e-9)
        last = math.ceil(t1 * self.rate_hz - 1e-9)
        return np.arange(first, last, dtype=np.float64) / self.rate_hz

    def measure(
        self, t: np.ndarray, x: np.ndarray, y: np.ndarray, contact: np.ndarray
    ) -> TouchSamples:
        """Samples of the finger at ``(x, y)`` mm with ``contact`` at times ``t``; the position
        gets the jitter (where there is no contact the panel still reports the last place, with
        jitter, as capacitive panels do while hovering ends)."""
        m = t.shape[0]
        jitter = self._draws.take(2 * m).reshape(m, 2) * self.noise_mm
        return TouchSamples(
            t.copy(), x + jitter[:, 0], y + jitter[:, 1], np.asarray(contact, dtype=bool).copy()
        )


class CornerForceSensors:
    """Four force sensors under the corners of a ``width_mm x height_mm`` surface.

    Args:
        width_mm, height_mm: the surface, mm (sensors at its corners).
        noise_n: standard deviation of each sensor, N.
        rng: random generator of the noise.
    """

    def __init__(
        self, width_mm: float, height_mm: float, noise_n: float, rng: np.random.Generator
    ) -> None:
        self.width_mm = width_mm
        self.height_mm = height_mm
        self.noise_n = noise_n
        self._draws = NormalDraws(rng)

    @property
    def rng(self) -> np.random.Generator:
        """The random generator of the noise."""
        return self._draws.rng

    def split(self, force_n: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """(N, 4) noiseless corner forces (order :data:`CORNERS`) of a force at ``(x, y)``;
        positions outside the surface are taken at its edge."""
        x = np.asarray(x_mm, dtype=np.float64)
        y = np.asarray(y_mm, dtype=np.float64)
        f = np.asarray(force_n, dtype=np.float64)
        if not (f.ndim == 1 and f.shape == x.shape == y.shape):
            u = (x / self.width_mm).clip(0.0, 1.0)
            v = (y / self.height_mm).clip(0.0, 1.0)
            return np.column_stack(
                (f * (1 - u) * (1 - v), f * u * (1 - v), f * (1 - u) * v, f * u * v)
            )
        # One frame per row, u and v side by side: (f (1 - u)) (1 - v), (f u) (1 - v),
        # (f (1 - u)) v, (f u) v.
        n = f.shape[0]
        uv = np.empty((n, 2))
        np.divide(x, self.width_mm, uv[:, 0])
        np.divide(y, self.height_mm, uv[:, 1])
        uv.clip(0.0, 1.0, out=uv)
        rest = np.subtract(1.0, uv)  # (1 - u, 1 - v)
        by_x = np.empty((n, 4))
        np.multiply(f, rest[:, 0], by_x[:, 0])
        np.multiply(f, uv[:, 0], by_x[:, 1])
        by_x[:, 2:] = by_x[:, :2]
        by_y = np.empty((n, 4))
        by_y[:, :2] = rest[:, 1:]
        by_y[:, 2:] = uv[:, 1:]
        return np.multiply(by_x, by_y, by_x)

    def measure(self, force_n: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """(N, 4) measured corner forces, N: :meth:`split` plus each sensor's noise."""
        return self.add_noise(self.split(force_n, x_mm, y_mm))

    def add_noise(self, forces_n: np.ndarray) -> np.ndarray:
        """(N, 4) corner forces ``forces_n`` (N, noiseless; not modified) plus each sensor's
        noise, a new array."""
        n = forces_n.shape[0]
        noise = np.multiply(self._draws.take(4 * n).reshape(n, 4), self.noise_n)
        return np.add(forces_n, noise, out=noise)


def locate(
    forces_n: np.ndarray, width_mm: float, height_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total force (N) and the position (x, y in mm) where it acts, from (N, 4) corner forces
    (moment balance; NaN where the total is not positive)."""
    f = np.asarray(forces_n, dtype=np.float64)
    total = f.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(total > 0, width_mm * (f[:, 1] + f[:, 3]) / total, np.nan)
        y = np.where(total > 0, height_mm * (f[:, 2] + f[:, 3]) / total, np.nan)
    return total, x, y
