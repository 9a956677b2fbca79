"""Regenerate hcard/v1/card_pb2.py and card_pb2.pyi from spec/hcard/v1/card.proto.

Run: ``python scripts/generate_proto.py [--out DIR]`` (needs the dev extra: grpcio-tools).
Without ``--out`` the committed files in the repository are rewritten.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROTO = Path("hcard/v1/card.proto")


def generate(out_dir: Path) -> list[Path]:
    """Run protoc (from grpcio-tools) into ``out_dir``; return the generated files."""
    from grpc_tools import protoc

    out_dir.mkdir(parents=True, exist_ok=True)
    spec = ROOT / "spec"
    args = ["protoc", f"-I{spec}", f"--python_out={out_dir}", f"--pyi_out={out_dir}"]
    status = protoc.main([*args, str(spec / PROTO)])
    if status != 0:
        raise SystemExit(f"protoc failed with status {status}")
    return [out_dir / "hcard/v1/card_pb2.py", out_dir / "hcard/v1/card_pb2.pyi"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT, help="output root (default: repo)")
    args = parser.parse_args()
    for path in generate(args.out):
        print(path, file=sys.stderr)


if __name__ == "__main__":
    main()
