"""The repository the tests run in: its root, and its scripts imported as modules.

A script (``scripts/generate_proto.py``, an example's ``calibrate_table_3_3.py``) is not in a
package: :func:`import_script` imports it from its file, under its own name, without putting
its folder on ``sys.path``."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[2]
"""The repository's root (this file is ``tests/helpers/repository.py``)."""


def import_script(relative: str) -> ModuleType:
    """The script at ``relative`` (a path from :data:`REPO`) imported as a module named after its
    file; imported once, later calls return the same module."""
    path = REPO / relative
    name = path.stem
    module = sys.modules.get(name)
    if module is not None and Path(getattr(module, "__file__", "")).resolve() == path:
        return module
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # a dataclass of the script looks its module up by name
    spec.loader.exec_module(module)
    return module
