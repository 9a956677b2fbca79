"""Installed distributions written by the plugin tests: a ``.dist-info`` directory with its
metadata and entry points, and the modules it names, in a folder on ``sys.path``."""

from __future__ import annotations

import textwrap
from pathlib import Path


def install_distribution(site: Path, name: str, entry_points: str, modules: dict[str, str],
                         version: str = "1.0") -> None:
    """Write distribution ``name`` ``version`` into ``site``: ``entry_points`` is the text of
    its ``entry_points.txt`` (``[group]`` sections), ``modules`` the source of each module by
    name (dedented), written beside it."""
    dist_info = site / f"{name.replace('-', '_')}-{version}.dist-info"
    dist_info.mkdir(parents=True)
    (dist_info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n", encoding="utf-8")
    (dist_info / "entry_points.txt").write_text(entry_points, encoding="utf-8")
    for module, source in modules.items():
        (site / f"{module}.py").write_text(textwrap.dedent(source), encoding="utf-8")
