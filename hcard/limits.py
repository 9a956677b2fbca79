"""Normative limits of card format v1 (spec/README.md, section "Limits").

Firmware sizes its buffers from these; validators enforce them.
"""

from __future__ import annotations

FORMAT_MAJOR = 1
"""Major format version this implementation reads and writes."""
FORMAT_MINOR = 0
"""Minor format version this implementation writes."""

MAX_COMPONENTS_PER_TEXTURE = 16
MAX_TEXTURES = 256
MAX_GRID_COLS = 1024
MAX_GRID_ROWS = 1024
MAX_TAXTELS = 65536
MAX_SURFACE_MM = 10_000.0
"""Largest surface side, millimetres (10 m)."""
MIN_TAXTEL_MM = 0.05
"""Smallest taxtel side, millimetres."""
MAX_RELATIVE_FRICTION = 4.0
"""Upper bound of baselines and amplitudes, relative friction units."""
MAX_SPATIAL_FREQUENCY = 50.0
"""Highest spatial frequency, cycles/mm (a 20 um period, below fingerprint-ridge scale)."""
MAX_TEMPORAL_FREQUENCY = 20_000.0
"""Highest temporal frequency, Hz."""
MAX_TEXT_LENGTH = 1024
"""Longest metadata or texture-name string, characters."""
MAX_CARD_BYTES = 16 * 1024 * 1024
"""Largest card file a reader must accept, bytes."""

RELATIVE_FRICTION_JND = 0.08
"""Just-noticeable difference of relative friction (thesis appendix B.1, Fig. B.2;
spec/README.md section 10)."""
AUTO_LOCKING_PERIOD_MM = 10.0
"""LOCKING_AUTO threshold: spatial periods below this are velocity-locked (thesis 5.3.3-5.5.3:
position and texture control rate equal at a 1 cm grating; the hybrid boundary lies between the
5 mm and 25 mm periods)."""
