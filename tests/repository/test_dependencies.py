"""Dependencies a downstream project can live with: no runtime dependency is pinned to one
version, and every declared minimum is the version .ci/lowest.txt installs for the run at the
lowest versions (so each minimum is a tested one)."""

from __future__ import annotations

import re
import warnings

import pytest
from packaging.version import Version

from tests.helpers.repository import REPO as ROOT

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


@pytest.mark.parametrize("category", [DeprecationWarning, PendingDeprecationWarning,
                                      FutureWarning])
@pytest.mark.parametrize("module", ["hcard.cli.encode_cmd", "hcard_builtins.image.loading",
                                    "hcard_device.firmware", "hcard_conformance.runner"])
def test_a_deprecation_met_in_hcard_code_fails_the_test(category: type[Warning],
                                                        module: str) -> None:
    """pyproject.toml's ``filterwarnings``: a deprecation whose warning is attributed to a
    module of the four packages (a dependency's ``stacklevel=2`` names its caller) is an
    error, so a dependency's next deprecation shows in CI while it is still a warning."""
    with pytest.raises(category, match="moved"):
        warnings.warn_explicit("the API moved", category, "caller.py", 1, module=module)


def test_a_deprecation_inside_a_dependency_stays_a_warning() -> None:
    with pytest.warns(DeprecationWarning, match="moved"):
        warnings.warn_explicit("the API moved", DeprecationWarning, "x.py", 1,
                               module="click.utils")
