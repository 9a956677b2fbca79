"""pytest with the conformance plugin, run as a vendor's CI runs it (a subprocess in a folder of
its own), and its JUnit XML read as CI dashboards read it (Jenkins, GitLab and GitHub's test
reporters): a case is red when it has a <failure> or an <error> child, skipped when it has
<skipped>, green otherwise."""

from __future__ import annotations

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

PROGRESS = re.compile(r"^hcard conformance: (\S+): (\d+) cases? in [0-9.]+ s$", re.M)
"""The plugin's line per check run (hcard_conformance.pytest_plugin, not printed with -q)."""


NOT_THE_VENDORS = ("-p", "no:hypothesispytest")
"""pytest plugins of this repository's dev environment that a vendor's run need not have:
Hypothesis's imports Hypothesis for its terminal summary, ~1-2 s of every run."""


def dashboard(xml: bytes) -> dict[str, list[str]]:
    """Each case's colour as a dashboard shows it, by ``classname.name``."""
    colours: dict[str, list[str]] = {"red": [], "skipped": [], "green": []}
    for case in ET.fromstring(xml).iter("testcase"):
        name = f"{case.get('classname')}.{case.get('name')}"
        if case.find("failure") is not None or case.find("error") is not None:
            colours["red"].append(name)
        elif case.find("skipped") is not None:
            colours["skipped"].append(name)
        else:
            colours["green"].append(name)
    return colours


def junit_cases(xml: bytes) -> list[str]:
    """The cases of the JUnit XML in order, as ``classname::name`` (a case's node ID)."""
    return [f"{c.get('classname')}::{c.get('name')}" for c in ET.fromstring(xml).iter("testcase")]


def checks_run(stdout: str) -> list[tuple[str, int]]:
    """The checks the suite ran, each with the number of cases it measured, from the plugin's
    progress lines."""
    return [(check, int(n)) for check, n in PROGRESS.findall(stdout)]


def pytest_run(folder: Path, *args: str, quiet: bool = True, in_folder: bool = True,
               ) -> tuple[subprocess.CompletedProcess[str], bytes]:
    """pytest with the conformance plugin in ``folder`` (the only file argument when
    ``in_folder``); its output and JUnit XML (empty when none was written)."""
    junit = folder / "plugin.xml"
    junit.unlink(missing_ok=True)
    run = subprocess.run([sys.executable, "-m", "pytest", "-p", "hcard_conformance.pytest_plugin",
                          "-p", "no:cacheprovider", *NOT_THE_VENDORS, *(["-q"] if quiet else []),
                          f"--junitxml={junit}", *args, *([str(folder)] if in_folder else [])],
                         capture_output=True, text=True, cwd=folder, timeout=600)
    return run, junit.read_bytes() if junit.exists() else b""


def collected(stdout: str) -> list[str]:
    """The node IDs ``pytest --collect-only -q`` listed."""
    return [line for line in stdout.splitlines() if "::" in line and " " not in line]
