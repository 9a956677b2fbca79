"""Shared fixtures, import path for the test helpers, and the order of the test files."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

FIRST = ("test_guest.py",)
"""Test files run before the others: the QEMU guest tier emulates a whole machine in software,
and its timing bounds are the first to go on a machine that has been busy for minutes (the
real-time device tests before it)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the files of :data:`FIRST` first, keeping the order within each group."""
    items.sort(key=lambda item: item.path.name not in FIRST)
