"""Hooks of the whole run: its own cache directory, the order of the test files, and the
helpers' asserts rewritten like a test's. The helpers themselves are modules of
:mod:`tests.helpers`, imported by name."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest

# A failing assert in a helper (tests/helpers/cli.py's one-line error, realtime.py's verdicts)
# shows its values as a failing assert in a test does.
pytest.register_assert_rewrite("tests.helpers")

FIRST = ("test_guest.py",)
"""Test files run before the others: the QEMU guest tier emulates a whole machine in software,
and its timing bounds are the first to go on a machine that has been busy for minutes (the
real-time device tests before it)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the files of :data:`FIRST` first, keeping the order within each group."""
    items.sort(key=lambda item: item.path.name not in FIRST)


_CACHE_DIRECTORY = pytest.StashKey[tuple[pytest.MonkeyPatch, Path]]()


def pytest_configure(config: pytest.Config) -> None:
    """Point ``XDG_CACHE_HOME`` at a fresh directory of the run's own.

    Plugin discovery remembers the entry points and contributed commands it found in the
    user's cache directory (:mod:`hcard.plugins.command_cache`): the test run, and the commands it
    starts, keep theirs in a directory of their own instead of the user's. This must precede
    collection, since test modules call ``get_registry()`` at import (a session fixture would
    come too late). Each pytest-xdist worker runs this hook as well and gets a directory of its
    own."""
    patch = pytest.MonkeyPatch()
    directory = Path(tempfile.mkdtemp(prefix="hcard-xdg-"))
    patch.setenv("XDG_CACHE_HOME", str(directory))
    config.stash[_CACHE_DIRECTORY] = (patch, directory)


def pytest_unconfigure(config: pytest.Config) -> None:
    """Restore ``XDG_CACHE_HOME`` and remove the run's cache directory."""
    patch, directory = config.stash[_CACHE_DIRECTORY]
    patch.undo()
    shutil.rmtree(directory, ignore_errors=True)
