"""The names of the files in a calibration report's directory (:mod:`hcard.calibration.report`)."""

from __future__ import annotations

MARKDOWN = "report.md"
JSON = "report.json"
PROFILE = "profile.json"
RESIDUALS_PNG = "residuals.png"
FIT_PNG = "fit.png"
