"""Dependencies a downstream project can live with: no runtime dependency is pinned to one
version, and every declared minimum is the version .ci/lowest.txt installs for the run at the
lowest versions (so each minimum is a tested one)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
_REQUIREMENT = re.compile(r"^\s*([A-Za-z0-9_.-]+)\s*(.*)$")


def _declared() -> dict[str, str]:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = [*project["dependencies"], *project["optional-dependencies"]["dev"]]
    return {match[1].lower(): match[2].replace(" ", "")
            for match in map(_REQUIREMENT.match, requirements) if match}


def _lowest() -> dict[str, str]:
    pins = {}
    for line in (ROOT / ".ci" / "lowest.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, version = line.split("==")
            pins[name.lower()] = version
    return pins


def test_no_runtime_dependency_is_pinned_to_one_version() -> None:
    tomllib = pytest.importorskip("tomllib")
    runtime = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    for requirement in runtime:
        assert "==" not in requirement, requirement
        assert ">=" in requirement, f"{requirement}: state the lowest version it works with"


def test_the_lowest_versions_run_installs_every_declared_minimum() -> None:
    declared, lowest = _declared(), _lowest()
    for name, spec in declared.items():
        if name in ("ruff", "mypy", "grpcio-tools"):  # tools of the checkout, not the library
            continue
        minimum = re.search(r">=([0-9][^,]*)", spec)
        assert minimum, f"{name}{spec}: no lower bound"
        assert name in lowest, f"{name} is missing from .ci/lowest.txt"
        assert Version(lowest[name]) == Version(minimum[1]), (name, spec, lowest[name])
    assert set(lowest) <= set(declared)
