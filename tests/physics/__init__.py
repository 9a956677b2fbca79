"""Tests of hcard.physics: device limits, device profiles and model-based rendering (actuation,
velocity compensation)."""
