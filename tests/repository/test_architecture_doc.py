"""ARCHITECTURE.md names files, modules and hooks: each name must exist, so the map cannot drift
from the code it describes without a test failing."""

from __future__ import annotations

import functools
import importlib.util
import re
from collections.abc import Sequence

import pytest

from tests.helpers.repository import REPO as ROOT
from tests.repository.test_spec_rule_ids import SKIPPED_DIRS

DOC = ROOT / "ARCHITECTURE.md"
PATH_LIKE = re.compile(r"^[\w./-]+\.(py|md|proto|toml)$|^[\w-]+(/[\w-]+)+/$")
MODULE_LIKE = re.compile(r"^hcard(_builtins|_device|_conformance)?(\.\w+)*$")
HOOK_LIKE = re.compile(r"^hcard_[a-z_]+s$")


def _names(text: str) -> list[str]:
    """The code spans of ``text`` (``...``), outside fenced blocks, less the entry-point groups
    of pyproject.toml (``hcard.plugins`` is a group and a module; ``hcard.commands`` a group)."""
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    groups = set(re.findall(r'^\[project\.entry-points\."([^"]+)"\]', pyproject, flags=re.M))
    return [n for n in re.findall(r"`([^`\n]+)`", prose) if n not in groups]


@functools.cache
def _repository_files() -> tuple[str, ...]:
    """Every file and folder of the repository (POSIX paths from its root), less the tools'
    caches and build output (:data:`test_spec_rule_ids.SKIPPED_DIRS`, ``*.egg-info``); walked
    once per run."""
    found = []
    for path in ROOT.rglob("*"):
        parts = path.relative_to(ROOT).parts
        if SKIPPED_DIRS.intersection(parts) or any(p.endswith(".egg-info") for p in parts):
            continue
        found.append(path.relative_to(ROOT).as_posix())
    return tuple(found)


def missing_paths(names: list[str], files: Sequence[str]) -> list[str]:
    """Path-like names that no file or folder of the repository ends with."""
    candidates = [n for n in names if PATH_LIKE.match(n)]
    return [n for n in candidates
            if not any(f == n.rstrip("/") or f.endswith("/" + n.rstrip("/")) for f in files)]


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:  # a parent is a module, not a package
        return False


def missing_modules(names: list[str]) -> list[str]:
    """Dotted names of the packages that are neither a module nor an attribute of one."""
    missing = []
    for name in (n for n in names if MODULE_LIKE.match(n)):
        module, attribute = name, ""
        while module and not _is_module(module):
            module, _, attribute = module.rpartition(".")  # the last name is an attribute
        if not module or (attribute and not hasattr(importlib.import_module(module), attribute)):
            missing.append(name)
    return missing


def test_every_named_file_exists() -> None:
    names = _names(DOC.read_text(encoding="utf-8"))
    assert len([n for n in names if PATH_LIKE.match(n)]) >= 30  # the scan found the map's paths
    assert missing_paths(names, _repository_files()) == []


def test_every_named_module_exists() -> None:
    names = _names(DOC.read_text(encoding="utf-8"))
    assert len([n for n in names if MODULE_LIKE.match(n)]) >= 10  # ... and its modules
    assert missing_modules(names) == []


def test_every_named_hook_is_a_hookspec() -> None:
    from hcard.plugins import hookspecs

    names = _names(DOC.read_text(encoding="utf-8"))
    hooks = {n for n in names if HOOK_LIKE.match(n) and not _is_module(n)}
    assert len(hooks) >= 5  # ... and its hooks
    assert sorted(h for h in hooks if not hasattr(hookspecs, h)) == []


@pytest.mark.parametrize(
    ("name", "found"),
    [("hcard/render/touch.py", True), ("render/touch.py", True), ("render/tuch.py", False),
     ("spec/vectors/", True), ("spec/vector/", False)],
)
def test_the_path_check_can_fail(name: str, found: bool) -> None:
    assert (missing_paths([name], _repository_files()) == []) is found


def test_the_module_check_can_fail() -> None:
    assert missing_modules(["hcard.render.touch", "hcard.render.touch.speed_estimate"]) == []
    assert missing_modules(["hcard.render.tuch", "hcard.render.touch.no_such_rule"]) == [
        "hcard.render.tuch", "hcard.render.touch.no_such_rule"]
