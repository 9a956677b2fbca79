"""The sampling rates of the thesis devices, which the renderer and the tools default to.

A module of its own, importing nothing, so that a host that only reads a device's configuration
does not load the renderer to learn them.
"""

from __future__ import annotations

TOUCH_RATE_HZ = 50.0
"""Sampling rate of the capacitive touch screen, Hz (thesis 5.1.1)."""
DEFAULT_FRAME_RATE_HZ = 10_000.0
"""E-ViTa synthesis rate: 500 Hz with 20 points a period (thesis 5.1.1); the renderer's default
frame rate (spec/README.md section 6)."""
