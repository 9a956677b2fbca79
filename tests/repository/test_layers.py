"""The layers of ARCHITECTURE.md are the imports of the code: every import (at module level,
inside a function or for type checking) of a module of the four packages runs down the layer
table or stays in its row, and no module-level imports go round in a cycle.

The table is read from ARCHITECTURE.md (section "Layers"), so the map and this test cannot
drift apart; the import graph is walked with :mod:`ast`, without importing anything.
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tests.helpers.repository import REPO as ROOT

DOC = ROOT / "ARCHITECTURE.md"
PACKAGE_DIRS = {
    "hcard": ROOT / "hcard",
    "hcard_builtins": ROOT / "builtin_plugins" / "hcard_builtins",
    "hcard_device": ROOT / "reference_device" / "hcard_device",
    "hcard_conformance": ROOT / "conformance" / "hcard_conformance",
}
ROW = re.compile(r"^\|\s*(\d+)\s*\|([^|]*)\|([^|]*)\|")


@dataclass(frozen=True)
class Row:
    """One row of the layer table: its layer number, name and module prefixes."""

    layer: int
    name: str
    prefixes: tuple[str, ...]


@dataclass(frozen=True)
class Arrow:
    """``source`` imports ``target`` (both dotted module names) at ``line`` of ``path``."""

    source: str
    target: str
    path: str
    line: int
    module_level: bool


def layer_table(text: str) -> list[Row]:
    """The rows of the table under "## Layers" (``| layer | name | `module` ... |``)."""
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        match = ROW.match(line)
        if match:
            prefixes = tuple(re.findall(r"`([\w.]+)`", match[3]))
            rows.append(Row(int(match[1]), match[2].strip(), prefixes))
    return rows


@functools.cache
def modules() -> dict[str, Path]:
    """Every module of the four packages by dotted name."""
    found = {}
    for package, folder in PACKAGE_DIRS.items():
        for path in folder.rglob("*.py"):
            parts = [package, *path.relative_to(folder).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _target(name: str, known: dict[str, Path]) -> str | None:
    """The module of the four packages ``name`` is or lies in (None: another library's)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def arrows(source: str, path: Path, known: dict[str, Path]) -> Iterator[Arrow]:
    """The imports of the module ``source`` (at ``path``) of modules of the four packages."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    top = {id(node) for node in tree.body}
    package = source if path.name == "__init__.py" else source.rpartition(".")[0]
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # `from package import module` imports the module; `from module import name` the module
            names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base
                     for alias in node.names]
        for name in names:
            target = _target(name, known)
            if target is not None and target != source:
                yield Arrow(source, target, str(path.relative_to(ROOT)), node.lineno,
                            id(node) in top)


@functools.cache
def all_arrows() -> tuple[Arrow, ...]:
    known = modules()
    return tuple(a for name, path in known.items() for a in arrows(name, path, known))


def row_of(module: str, rows: list[Row]) -> Row | None:
    """The row whose longest prefix names ``module`` (None: no row does)."""
    best: tuple[int, Row] | None = None
    for row in rows:
        for prefix in row.prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (
                    best is None or len(prefix) > best[0]):
                best = (len(prefix), row)
    return best[1] if best else None


def upward(arrow_list: tuple[Arrow, ...], rows: list[Row]) -> list[str]:
    """The arrows that run up the table, or sideways into another row of the same layer."""
    found = []
    for arrow in arrow_list:
        source, target = row_of(arrow.source, rows), row_of(arrow.target, rows)
        assert source is not None and target is not None
        if target.layer > source.layer or (target.layer == source.layer and target != source):
            found.append(f"{arrow.path}:{arrow.line}: {arrow.source} ({source.name}) imports "
                         f"{arrow.target} ({target.name})")
    return found


def cycles(arrow_list: tuple[Arrow, ...]) -> list[list[str]]:
    """The groups of modules whose module-level imports go round in a cycle (Tarjan)."""
    graph: dict[str, set[str]] = {}
    for arrow in arrow_list:
        if arrow.module_level:
            graph.setdefault(arrow.source, set()).add(arrow.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return groups


def test_the_table_names_every_module_once() -> None:
    rows = layer_table(DOC.read_text(encoding="utf-8"))
    assert len(rows) >= 8  # the table was found
    prefixes = [p for row in rows for p in row.prefixes]
    assert len(prefixes) == len(set(prefixes)), "a module prefix is in two rows"
    assert [m for m in modules() if row_of(m, rows) is None] == []
    assert [p for p in prefixes if not any(m == p or m.startswith(p + ".") for m in modules())] \
        == [], "a row names a module that does not exist"


def test_no_import_runs_up_the_layers() -> None:
    rows = layer_table(DOC.read_text(encoding="utf-8"))
    assert len(all_arrows()) > 1000  # the walk found the imports
    assert upward(all_arrows(), rows) == []


def test_no_module_level_import_cycle() -> None:
    assert cycles(all_arrows()) == []


def test_the_checks_bite() -> None:
    """An upward arrow and a cycle made up here are found (the checks above can fail)."""
    rows = [Row(0, "low", ("a",)), Row(1, "high", ("b",)), Row(1, "side", ("c",))]
    made = (Arrow("a.x", "b.y", "a/x.py", 3, True), Arrow("b.y", "a.x", "b/y.py", 1, True),
            Arrow("b.y", "c.z", "b/y.py", 2, False))
    assert upward(made, rows) == [
        "a/x.py:3: a.x (low) imports b.y (high)", "b/y.py:2: b.y (high) imports c.z (side)"]
    assert cycles(made) == [["a.x", "b.y"]]
    text = "## Layers\n\n| layer | name | modules |\n|---|---|---|\n| 0 | low | `a` `a2` |\n"
    assert layer_table(text) == [Row(0, "low", ("a", "a2"))]
