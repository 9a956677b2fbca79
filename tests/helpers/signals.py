"""Measuring rendered signals against analytic ones (shared by the renderer tests)."""

from __future__ import annotations

import numpy as np


def tone(t: np.ndarray, signal: np.ndarray, frequency_hz: float) -> tuple[float, float, float]:
    """Least-squares fit of ``c + A cos(2 pi f t + phi)`` at a known frequency.

    Returns:
        ``(A, phi, rms_residual)`` with ``phi`` in (-pi, pi] relative to ``t = 0``.
    """
    w = 2.0 * np.pi * frequency_hz * t
    basis = np.column_stack((np.ones_like(t), np.cos(w), np.sin(w)))
    coef, *_ = np.linalg.lstsq(basis, signal, rcond=None)
    residual = signal - basis @ coef
    amplitude = float(np.hypot(coef[1], coef[2]))
    phase = float(np.arctan2(-coef[2], coef[1]))
    return amplitude, phase, float(np.sqrt(np.mean(residual**2)))


def wrap(angle: float) -> float:
    """``angle`` wrapped into (-pi, pi]."""
    return float(np.angle(np.exp(1j * angle)))
