"""The click type of a file argument that a command reads."""

from __future__ import annotations

from pathlib import Path

import click

INPUT_FILE = click.Path(path_type=Path)
"""The type of a file argument that a command reads. A directory passes it and is refused by
the reader, one line naming it, with exit status 1 (invalid input: a file that cannot be read,
README "Exit status") like every input file that cannot be read; click's own
``dir_okay=False`` made it a usage error (exit 2) in every command but ``encode``."""
INPUT_FILE_OR_STDIN = click.Path(allow_dash=True, path_type=Path)
""":data:`INPUT_FILE`, or ``-`` for standard input."""
