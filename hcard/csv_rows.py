"""The data rows of a CSV text with ``#`` comment lines and blank lines skipped.

Shared by the finger-track reader (spec/track-format.md) and the tribometer measurement reader
(spec/measurement-format.md), which both keep line numbers for their error messages.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

from hcard.errors import HcardError


def data_rows(text: str) -> list[tuple[int, list[str]]]:
    """``(line number, cells)`` of every row that is neither blank nor a ``#`` comment."""
    return [
        (number, row)
        for number, row in enumerate(csv.reader(io.StringIO(text)), start=1)
        if row and not row[0].lstrip().startswith("#") and any(cell.strip() for cell in row)
    ]


def read_csv_text(path: str | os.PathLike[str], error: type[HcardError]) -> str:
    """The text of the CSV file ``path`` (UTF-8, a leading byte-order mark dropped); a missing
    or unreadable file raises ``error`` naming it."""
    file = Path(path)
    try:
        return file.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise error(f"{file}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{file}: cannot read ({exc})") from None
