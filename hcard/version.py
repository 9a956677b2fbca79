"""The version of hcard (the ``version`` of pyproject.toml), which cards and reports name as
their generator."""

from __future__ import annotations

__version__ = "0.1.0"
