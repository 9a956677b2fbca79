"""The error of device profiles: an invalid profile, its limits or its file."""

from __future__ import annotations

from hcard.physics.predictor import PredictorError


class ProfileError(PredictorError):
    """A device profile is invalid, or its file cannot be read; the message names file and field."""
