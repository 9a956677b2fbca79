"""Closing the loop with measured data: measurement files, fits, residual analysis
(spec/calibration.md)."""
