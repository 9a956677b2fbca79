"""Every test file that runs a device on the wall clock is in the wall-clock lane of a parallel
run (tests/conftest.py), so that no two such tests ever run at once."""

from __future__ import annotations

import re

from tests.helpers.repository import REPO

WALL_CLOCK_USES = re.compile(r"served_device\(|open_no_ownership|control:no-ownership|"
                             r"RUN_GUEST|served_controls")
"""What starts a device on the wall clock: a USB/IP server process, the in-process server of
the no-ownership control, the QEMU guest."""
MARKED = re.compile(r"pytest\.mark\.wall_clock")


def unmarked(files: dict[str, str]) -> list[str]:
    """Names of the files (name -> source) that start a wall-clock device without the mark."""
    return [name for name, text in files.items()
            if WALL_CLOCK_USES.search(text) and not MARKED.search(text)]


def test_test_files_that_serve_devices_are_in_the_wall_clock_lane() -> None:
    files = {str(p.relative_to(REPO)): p.read_text(encoding="utf-8")
             for p in sorted((REPO / "tests").rglob("test_*.py"))}
    assert len(files) > 80
    assert not unmarked(files)
    assert sum(1 for text in files.values() if MARKED.search(text)) >= 10


def test_the_scan_catches_a_served_test_without_the_mark() -> None:
    served = "from tests.helpers.served_device import served_device\nwith served_device():\n"
    assert unmarked({"a.py": served, "b.py": served + "pytestmark = pytest.mark.wall_clock\n",
                     "c.py": "x = 1\n"}) == ["a.py"]
