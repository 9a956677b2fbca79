"""``python -m hcard``: the same command line as the ``hcard`` console script."""

from __future__ import annotations

from hcard.cli.main import main

if __name__ == "__main__":
    main()
