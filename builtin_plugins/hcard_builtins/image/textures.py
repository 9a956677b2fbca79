"""Sets of textures as arrays: baseline, wave vectors and complex amplitudes per slot.

A texture is ``baseline + sum_c Re(C_c exp(2j*pi*(kx_c*x + ky_c*y)))`` with ``C = A exp(i phase)``
(amplitude ``A`` in relative friction, phase at the surface origin) and ``(kx, ky)`` in cycles/mm;
this is the card's ``A cos(2 pi k (cos(th) x + sin(th) y) + phase)`` with ``k = |(kx, ky)|`` and
``th = atan2(ky, kx)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Textures:
    """A set of textures in surface units (one per taxtel, or a palette).

    Attributes:
        baseline: ``(n,)`` baseline relative friction.
        k: ``(n, m, 2)`` wave vectors (kx, ky), cycles/mm.
        coef: ``(n, m)`` complex amplitudes ``A * exp(i * phase)``, phase at the surface origin;
            the component is ``Re(coef * exp(2j*pi*(kx*x + ky*y)))``.
        valid: ``(n, m)`` which slots hold a component.
    """

    baseline: np.ndarray
    k: np.ndarray
    coef: np.ndarray
    valid: np.ndarray

    @property
    def energy(self) -> np.ndarray:
        """``(n,)`` sum of squared amplitudes of the valid components."""
        return np.sum(np.where(self.valid, np.abs(self.coef) ** 2, 0.0), axis=1)

    def trimmed(self) -> Textures:
        """The same textures with slots beyond the largest component count removed."""
        width = int(self.valid.sum(axis=1).max(initial=0))
        return Textures(
            self.baseline, self.k[:, :width], self.coef[:, :width], self.valid[:, :width]
        )

    def take(self, index: np.ndarray) -> Textures:
        """The textures at ``index``."""
        return Textures(self.baseline[index], self.k[index], self.coef[index], self.valid[index])


def canonical(textures: Textures) -> Textures:
    """Write every wave vector with its orientation in (-pi/2, pi/2].

    ``(k, C)`` and ``(-k, conj C)`` are the same grating; the one whose orientation
    ``atan2(ky, kx)`` falls in (-pi/2, pi/2] is kept (decided on the angle as computed, so that
    a wave vector a rounding error away from the axis is not left at -pi/2).
    """
    angle = np.arctan2(textures.k[..., 1], textures.k[..., 0])
    flip = (angle <= -np.pi / 2) | (angle > np.pi / 2)
    k = np.where(flip[..., None], -textures.k, textures.k)
    coef = np.where(flip, np.conj(textures.coef), textures.coef)
    return Textures(textures.baseline, k, coef, textures.valid)


def orientation_and_phase(textures: Textures) -> tuple[np.ndarray, np.ndarray]:
    """Orientation in (-pi/2, pi/2] and phase in (-pi, pi] of every slot, radians.

    The orientation is folded once more after ``atan2`` so that rounding can never leave it
    at -pi/2 or above pi/2 (folding negates the phase).
    """
    orientation = np.arctan2(textures.k[..., 1], textures.k[..., 0])
    phase = np.angle(textures.coef)
    low, high = orientation <= -np.pi / 2, orientation > np.pi / 2
    orientation = np.where(
        low, orientation + np.pi, np.where(high, orientation - np.pi, orientation)
    )
    phase = np.where(low | high, -phase, phase)
    phase = np.where(phase <= -np.pi, phase + 2 * np.pi, phase)
    return orientation, phase


def strongest_first(textures: Textures) -> Textures:
    """Valid components first, strongest first."""
    key = np.where(textures.valid, -np.abs(textures.coef), np.inf)
    order = np.argsort(key, axis=1, kind="stable")
    rows = np.arange(order.shape[0])[:, None]
    return Textures(
        textures.baseline,
        textures.k[rows, order],
        textures.coef[rows, order],
        textures.valid[rows, order],
    )
