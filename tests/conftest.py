"""Shared fixtures, import path for the test helpers, and the order of the test files."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
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


@pytest.fixture(scope="session", autouse=True)
def _own_cache_directory(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Plugin discovery remembers the entry points and contributed commands it found in the
    user's cache directory (:mod:`hcard.plugins.command_cache`): the test run, and the commands it
    starts, keep theirs in a directory of their own instead of the user's."""
    previous = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("xdg-cache"))
    yield
    if previous is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = previous
