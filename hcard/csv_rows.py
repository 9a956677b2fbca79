"""CSV rows: reading the data rows of a text with ``#`` comment lines and blank lines skipped,
and writing columns as rows.

The reading is shared by the finger-track reader (spec/track-format.md) and the tribometer
measurement reader (spec/measurement-format.md), which both keep line numbers for their error
messages; the writing (:func:`format_rows`) by the rendered-frame writers and the measurement
writer.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from hcard.bounded_read import MAX_TEXT_FILE_BYTES, InputTooLarge, read_bounded, utf8_text
from hcard.errors import HcardError
from hcard.file_errors import reading

MAX_FIELD_CHARS = csv.field_size_limit()
"""Longest cell a CSV file may hold, characters (the csv module's limit, 131,072)."""

_NUMBER = re.compile(
    r"\s*[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)\s*",
    re.IGNORECASE)
"""A number cell: ASCII decimal digits, or nan/inf (which the readers then refuse by name).
``float()`` also takes ``"0.0_2"``, Arabic-Indic and full-width digits; the readers do not."""


def data_rows(text: str, source: str = "CSV", error: type[HcardError] = HcardError,
              first_line: int = 1) -> list[tuple[int, list[str]]]:
    """``(line number, cells)`` of every row that is neither blank nor a ``#`` comment, the
    text's first line being ``first_line``; a cell longer than :data:`MAX_FIELD_CHARS` raises
    ``error`` naming ``source`` and its line."""
    reader = csv.reader(io.StringIO(text))
    offset = first_line - 1
    rows = []
    try:
        for row in reader:
            if row and not row[0].lstrip().startswith("#") and any(c.strip() for c in row):
                rows.append((offset + reader.line_num, row))
    except csv.Error as exc:
        raise error(f"{source}:{offset + reader.line_num + 1}: cannot read the row ({exc}; a "
                    f"cell may hold at most {MAX_FIELD_CHARS} characters)") from None
    return rows


def header_names(header: list[str], line: int, source: str,
                 error: type[HcardError]) -> list[str]:
    """The column names of a header row, stripped; a header that is one cell holding ``;`` or
    a tab (a file from a locale whose separator is not the comma), or that names a column
    twice, raises ``error``."""
    names = [cell.strip() for cell in header]
    if len(names) == 1:
        for separator, label in ((";", "semicolons"), ("\t", "tabs")):
            if separator in names[0]:
                raise error(f"{source}:{line}: the columns are separated by {label}; hcard "
                            "CSV files separate them by commas")
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise error(f"{source}:{line}: column {name!r} appears twice in the header")
        seen.add(name)
    return names


CHUNK_CHARS = 1 << 20
"""Characters of data rows parsed at a time (:func:`numeric_table`): the parser's temporaries
are bounded by this, not by the file."""


def numeric_table(text: str, source: str, error: type[HcardError],
                  header_check: Callable[[list[str], int], None] | None = None,
                  max_rows: tuple[int, str] | None = None,
                  ) -> tuple[int, list[str], np.ndarray, np.ndarray]:
    """A CSV of numbers under one header row: the header's line, its names
    (:func:`header_names`), the data as an ``(n, columns)`` float array (an empty cell is NaN:
    the readers decide what that means) and the line number of each row. ``header_check``
    sees the names and the header line before the data are read (a reader's missing column is
    reported before a bad cell). ``max_rows``: the most data rows the reader takes and the
    rule that says so; the reading stops with an error as soon as there are more.

    The rows are parsed :data:`CHUNK_CHARS` at a time. Fast path: a piece that holds no
    quote, comment or blank line is parsed by ``numpy.loadtxt`` (1e6 rows: 0.5 s and 70 MB,
    where the row-by-row reader took 5-6 s and 0.9 GB). Anything it refuses is read again row
    by row, which names the line and the cell at fault: a row of another width, or a cell that
    is not an ASCII decimal number. Parsing the whole text at once held it five times over (a
    copy of the body, and ``StringIO``'s four bytes a character), 1.3 GB for a 10^7-row track,
    and a single comment line sent all of it through the row-by-row reader.
    """
    header_line, header, position = _split_header(text, source, error)
    names = header_names(header, header_line, source, error)
    if header_check is not None:
        header_check(names, header_line)
    values: list[np.ndarray] = []
    lines: list[np.ndarray] = []
    line, rows = header_line + 1, 0
    for start, end in _pieces(text, position):
        piece = text[start:end]
        piece_values, piece_lines = _piece_rows(piece, line, names, source, error)
        rows += len(piece_lines)
        if max_rows is not None and rows > max_rows[0]:
            raise error(f"{source}:{piece_lines[max_rows[0] - rows]}: more than {max_rows[0]} "
                        f"rows of data ({max_rows[1]})")
        values.append(piece_values)
        lines.append(piece_lines)
        line += piece.count("\n")
    if not values:
        return header_line, names, np.empty((0, len(names))), np.empty(0, dtype=np.int64)
    if len(values) == 1:
        return header_line, names, values[0], lines[0]
    return header_line, names, np.concatenate(values), np.concatenate(lines)


def _pieces(text: str, position: int) -> Iterator[tuple[int, int]]:
    """``(start, end)`` of consecutive pieces of ``text`` from ``position``, each about
    :data:`CHUNK_CHARS` long and ending after a line end. A piece that would end inside a
    quoted cell (an odd number of quotes: a quoted cell may span lines, RFC 4180) is carried
    past the next quote, at most :data:`MAX_FIELD_CHARS` further."""
    while position < len(text):
        end = text.find("\n", position + CHUNK_CHARS)
        if end >= 0 and text.count('"', position, end) % 2:
            closing = text.find('"', end, end + MAX_FIELD_CHARS)
            end = text.find("\n", closing) if closing >= 0 else end
        end = len(text) if end < 0 else end + 1
        yield position, end
        position = end


def _piece_rows(piece: str, first_line: int, names: list[str], source: str,
                error: type[HcardError]) -> tuple[np.ndarray, np.ndarray]:
    """The values and line numbers of the rows of one piece of the data (its first line is
    ``first_line``): by ``numpy.loadtxt`` when it can, else row by row (:func:`numeric_table`)."""
    plain = not any(mark in piece for mark in ('"', "#", "\n\n", "\n\r\n"))
    if plain and piece.strip() and not piece.startswith(("\n", "\r\n")):
        try:
            values = np.loadtxt(io.StringIO(piece, newline=None), delimiter=",",
                                dtype=np.float64, ndmin=2, comments=None)
        except ValueError:
            values = None
        rows = piece.count("\n") + (not piece.endswith("\n"))
        if values is not None and values.shape == (rows, len(names)):
            return values, np.arange(first_line, first_line + rows)
    return _slow_body(data_rows(piece, source, error, first_line), names, source, error)


def _split_header(text: str, source: str,
                  error: type[HcardError]) -> tuple[int, list[str], int]:
    """The first row that is neither blank nor a comment (its line and cells) and where the
    text after it starts."""
    position, line = 0, 0
    while position < len(text):
        end = text.find("\n", position)
        end = len(text) if end < 0 else end
        line += 1
        candidate = text[position:end]
        position = end + 1
        stripped = candidate.strip()
        if stripped and not stripped.startswith("#") and stripped.strip(","):
            (row,) = data_rows(candidate + "\n", source, error) or [(line, [candidate])]
            return line, row[1], min(position, len(text))
    raise error(f"{source}: empty file (no header row)")


def _slow_body(body: list[tuple[int, list[str]]], names: list[str], source: str,
               error: type[HcardError]) -> tuple[np.ndarray, np.ndarray]:
    """Row by row, each cell checked (:data:`_NUMBER`)."""
    width = len(names)
    values = np.empty((len(body), width))
    for i, (number, row) in enumerate(body):
        if len(row) != width:
            raise error(f"{source}:{number}: row has {len(row)} fields, the header has {width}")
        for j, cell in enumerate(row):
            if not cell.strip():
                values[i, j] = math.nan
            elif _NUMBER.fullmatch(cell):
                values[i, j] = float(cell)
            else:
                shown = cell.strip() if len(cell) <= 40 else cell.strip()[:37] + "..."
                raise error(f"{source}:{number}: column {names[j]}: {shown!r} is not a "
                            "number")
    return values, np.array([number for number, _ in body], dtype=np.int64)


def read_csv_text(path: str | os.PathLike[str], error: type[HcardError]) -> str:
    """The text of the CSV file ``path`` (UTF-8, a leading byte-order mark dropped); a missing,
    unreadable or too large file (:data:`~hcard.bounded_read.MAX_TEXT_FILE_BYTES`, whatever
    kind of file it is) raises ``error`` naming it."""
    file = Path(path)
    try:
        with reading(file, error, "a CSV file"):
            return utf8_text(read_bounded(file, MAX_TEXT_FILE_BYTES))
    except InputTooLarge as exc:
        raise error(f"{file}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{file}: cannot read (not UTF-8: {exc.reason} at byte {exc.start})") from None


def format_rows(columns: Sequence[tuple[str, np.ndarray]]) -> str:
    """The CSV rows of named columns of equal length, each ending in a newline: integers (and
    booleans) by ``str``, floats in their shortest round-trip form (``repr``), so reading them
    back gives the same numbers exactly (spec/track-format.md rule TO1, spec/measurement-format.md
    rule MF11)."""
    cells = [map(str, values.tolist()) if values.dtype.kind in "iub"
             else map(repr, values.tolist()) for _, values in columns]
    return "".join(",".join(row) + "\n" for row in zip(*cells, strict=True))
