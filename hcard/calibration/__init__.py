"""Closing the loop with measured data: measurement files, fits, residual analysis
(DESIGN.md section 8)."""
