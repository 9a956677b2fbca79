"""``python -m hcard.device.protocol``: print the HID report descriptor item by item
(``--hex``: as a hex dump; ``--table``: the report table; ``--update-spec FILE``: rewrite the
generated blocks of the spec)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from hcard.device.protocol.descriptor import REPORT_DESCRIPTOR, dump, hex_dump
from hcard.device.protocol.reports import REPORT_CLASSES


def report_table() -> str:
    """Markdown table of every report: ID, name, kind, size with the ID, access."""
    lines = ["| ID | Report | Kind | Bytes (with ID) | Access |", "|---|---|---|---|---|"]
    for cls in REPORT_CLASSES:
        if cls.KIND.name == "FEATURE":
            access = "/".join(a for a, ok in (("GET", cls.GET), ("SET", cls.SET)) if ok)
        else:
            access = "interrupt IN" if cls.KIND.name == "INPUT" else "interrupt OUT / SET_REPORT"
        lines.append(
            f"| 0x{cls.REPORT_ID:02X} | {cls.name()} | {cls.KIND.name.lower()} | {cls.size()} "
            f"| {access} |"
        )
    return "\n".join(lines) + "\n"


GENERATED_BLOCK = re.compile(
    r"(<!-- BEGIN GENERATED: python -m hcard\.device\.protocol(?P<args>[^>]*?) -->\n```text\n)"
    r"(?P<body>.*?)"
    r"(```\n<!-- END GENERATED -->)",
    re.DOTALL,
)
"""A generated block of spec/device-protocol.md: the command that makes it, then its output."""


def output_for(args: str) -> str:
    """What ``python -m hcard.device.protocol ARGS`` prints (ARGS: "", "--hex" or "--table")."""
    options = args.split()
    if options == ["--hex"]:
        return hex_dump(REPORT_DESCRIPTOR)
    if options == ["--table"]:
        return report_table()
    if not options:
        return dump(REPORT_DESCRIPTOR)
    raise ValueError(f"no generated output for arguments {args!r}")


def generated_blocks(text: str) -> list[tuple[str, str]]:
    """(arguments, body) of every generated block in a spec text."""
    return [(m.group("args").strip(), m.group("body")) for m in GENERATED_BLOCK.finditer(text)]


def update_spec(text: str) -> str:
    """The spec text with every generated block replaced by the current output."""
    return GENERATED_BLOCK.sub(
        lambda m: m.group(1) + output_for(m.group("args")) + m.group(4), text
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m hcard.device.protocol", description=__doc__)
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--hex", action="store_true", help="hex dump of the descriptor bytes")
    group.add_argument("--table", action="store_true", help="the report table (markdown)")
    group.add_argument("--update-spec", metavar="FILE", type=Path,
                       help="rewrite the generated blocks of spec/device-protocol.md")
    args = parser.parse_args(argv)
    if args.update_spec is not None:
        path: Path = args.update_spec
        path.write_text(update_spec(path.read_text(encoding="utf-8")), encoding="utf-8")
    elif args.hex:
        sys.stdout.write(hex_dump(REPORT_DESCRIPTOR))
    elif args.table:
        sys.stdout.write(report_table())
    else:
        sys.stdout.write(dump(REPORT_DESCRIPTOR))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
