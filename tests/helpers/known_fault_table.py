"""The known-fault table block of conformance/README.md (spec/conformance.md QN2): the table
made from the faulty device's rows (:mod:`hcard_conformance.faulty.known_faults`) and the
reference device's negative controls (``hcard_device.controls.CATCHES``), between its two
marker lines. Here, not in the conformance package, because that package imports no reference
device (the layer map). After a row or a control changes::

    python -m tests.helpers.known_fault_table     # rewrites the block, atomically
"""

from __future__ import annotations

import re

from hcard.atomic import write_atomically
from hcard_conformance.faulty.known_faults import markdown_table
from hcard_device.controls import CATCHES
from tests.helpers.repository import REPO

README = REPO / "conformance" / "README.md"
BEGIN = "<!-- known-faults: generated from hcard_conformance/faulty/known_faults.py -->\n"
END = "<!-- known-faults: end -->"
_BLOCK = re.compile(re.escape(BEGIN) + r"(.*?)" + re.escape(END), flags=re.S)


def expected_block() -> str:
    """The table as conformance/README.md must hold it."""
    return markdown_table(CATCHES)


def readme_block(text: str) -> str | None:
    """The block between the markers of ``text`` (None: no markers)."""
    found = _BLOCK.search(text)
    return found.group(1) if found else None


def main() -> None:
    """Rewrite the block of conformance/README.md (the rest of the file kept)."""
    text = README.read_text(encoding="utf-8")
    if readme_block(text) is None:
        raise SystemExit(f"{README}: no {BEGIN.strip()} ... {END} block")
    new = _BLOCK.sub(lambda _: BEGIN + expected_block() + END, text)
    write_atomically(README, new.encode("utf-8"))


if __name__ == "__main__":
    main()
