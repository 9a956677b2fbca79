"""The data rows of a CSV text with ``#`` comment lines and blank lines skipped.

Shared by the finger-track reader (spec/track-format.md) and the tribometer measurement reader
(spec/measurement-format.md), which both keep line numbers for their error messages.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

from hcard.bounded_read import MAX_TEXT_FILE_BYTES, InputTooLarge, read_bounded
from hcard.errors import HcardError


def data_rows(text: str) -> list[tuple[int, list[str]]]:
    """``(line number, cells)`` of every row that is neither blank nor a ``#`` comment."""
    return [
        (number, row)
        for number, row in enumerate(csv.reader(io.StringIO(text)), start=1)
        if row and not row[0].lstrip().startswith("#") and any(cell.strip() for cell in row)
    ]


def read_csv_text(path: str | os.PathLike[str], error: type[HcardError]) -> str:
    """The text of the CSV file ``path`` (UTF-8, a leading byte-order mark dropped); a missing,
    unreadable or too large file (:data:`~hcard.bounded_read.MAX_TEXT_FILE_BYTES`, whatever
    kind of file it is) raises ``error`` naming it."""
    file = Path(path)
    try:
        return read_bounded(file, MAX_TEXT_FILE_BYTES).decode("utf-8-sig")
    except FileNotFoundError:
        raise error(f"{file}: no such file") from None
    except IsADirectoryError:
        raise error(f"{file}: is a directory, not a CSV file") from None
    except InputTooLarge as exc:
        raise error(f"{file}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{file}: cannot read (not UTF-8: {exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise error(f"{file}: cannot read ({exc.strerror or exc})") from None
