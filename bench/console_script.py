"""What the ``hcard`` console script runs, for benches that time it as a fresh process.

``python -c ENTRY args...`` runs the console script's own code (``[project.scripts]`` in
pyproject.toml), not a shell shim, so a pyenv or conda wrapper does not count.
"""

from __future__ import annotations

ENTRY = "from hcard.cli.main import main; main()"
"""The ``hcard`` command: :func:`hcard.cli.main.main`."""

WITHOUT_FAST_EXIT = "import sys; from hcard.cli.main import cli; sys.exit(cli())"
"""The same command line through the bare click group, whose process exit runs the
interpreter's full garbage-collection passes (what :func:`hcard.cli.main.main` skips)."""
