"""``python -m hcard_conformance.vectors [--out DIR] [--check]``: regenerate or verify."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hcard_conformance.vectors.generate import differences, generate
from hcard_conformance.vectors.manifest import default_root


def main(argv: list[str] | None = None) -> int:
    """Regenerate the vectors into ``--out`` or, with ``--check``, compare; exit status."""
    parser = argparse.ArgumentParser(prog="python -m hcard_conformance.vectors",
                                     description=__doc__)
    parser.add_argument("--out", type=Path, default=None,
                        help="vectors directory (default: spec/vectors of the repository)")
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 when the files differ from a fresh generation")
    args = parser.parse_args(argv)
    root = args.out if args.out is not None else default_root()
    if args.check:
        problems = differences(root)
        for line in problems:
            print(line, file=sys.stderr)
        print(f"{root}: {'up to date' if not problems else f'{len(problems)} difference(s)'}")
        return 1 if problems else 0
    written = generate(root)
    size = sum(path.stat().st_size for path in written)
    print(f"{root}: wrote {len(written)} files, {size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
