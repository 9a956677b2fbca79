"""CSV and TSV files with the lab's own column names (spec/lab-recordings.md LR9): a header
row naming the columns, then rows of numbers; ``#`` comment rows and blank rows skipped as in
spec/measurement-format.md MF2."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from hcard.bounded_read import MAX_TEXT_FILE_BYTES, InputTooLarge, read_bounded, utf8_text
from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.source import MAX_SAMPLES, MAX_VARIABLES, missing
from hcard.file_errors import reading

TAB_SUFFIXES = (".tsv", ".tab")


def delimiter_of(path: Path, header_line: str, given: str | None) -> str:
    """The separator: ``given`` (the map's ``delimiter``), else a tab for ``.tsv``/``.tab``
    or a header with tabs and no comma, else a comma (LR9)."""
    if given is not None:
        return given
    if path.suffix.lower() in TAB_SUFFIXES or ("\t" in header_line and "," not in header_line):
        return "\t"
    return ","


class DelimitedFile:
    """A CSV/TSV file: columns by header name, each read as numbers on demand."""

    def __init__(self, path: str | os.PathLike[str], delimiter: str | None = None) -> None:
        self.path = str(path)
        try:
            with reading(path, LabRecordingError, "a recording"):
                text = utf8_text(read_bounded(path, MAX_TEXT_FILE_BYTES))
        except InputTooLarge as exc:
            raise LabRecordingError(f"{self.path}: {exc}") from None
        except UnicodeDecodeError as exc:
            raise LabRecordingError(f"{self.path}: not UTF-8 text ({exc.reason} at byte "
                                    f"{exc.start})") from None
        first = next((line for line in text.splitlines()
                      if line.strip() and not line.lstrip().startswith("#")), "")
        sep = delimiter_of(Path(path), first, delimiter)
        reader = csv.reader(io.StringIO(text), delimiter=sep)
        self._header: list[str] | None = None
        self._rows: list[list[str]] = []
        self._lines: list[int] = []
        try:
            for row in reader:
                if not row or row[0].lstrip().startswith("#") or not any(c.strip() for c in row):
                    continue
                if self._header is None:
                    self._header = [c.strip() for c in row]
                    self._header_line = reader.line_num
                    continue
                if len(self._rows) >= MAX_SAMPLES:
                    raise LabRecordingError(f"{self.path}: more than {MAX_SAMPLES} rows")
                if len(row) != len(self._header):
                    raise LabRecordingError(f"{self.path}:{reader.line_num}: {len(row)} "
                                            f"fields, the header has {len(self._header)}")
                self._rows.append(row)
                self._lines.append(reader.line_num)
        except csv.Error as exc:
            raise LabRecordingError(f"{self.path}:{reader.line_num}: cannot read the row "
                                    f"({exc})") from None
        if self._header is None:
            raise LabRecordingError(f"{self.path}: no header row")
        if len(self._header) > MAX_VARIABLES:
            raise LabRecordingError(f"{self.path}: {len(self._header)} columns, more than "
                                    f"{MAX_VARIABLES}")
        if len(set(self._header)) != len(self._header):
            twice = next(n for n in self._header if self._header.count(n) > 1)
            raise LabRecordingError(f"{self.path}:{self._header_line}: column {twice!r} "
                                    "appears twice in the header")

    def variables(self) -> dict[str, tuple[int, ...]]:
        assert self._header is not None
        return {name: (len(self._rows),) for name in self._header}

    def array(self, name: str) -> np.ndarray:
        assert self._header is not None
        if name not in self._header:
            raise missing(self.path, name, self.variables())
        position = self._header.index(name)
        values = np.empty(len(self._rows))
        for i, row in enumerate(self._rows):
            cell = row[position].strip()
            try:
                values[i] = float(cell) if cell else np.nan
            except ValueError:
                raise LabRecordingError(f"{self.path}:{self._lines[i]}: column {name!r}: "
                                        f"{cell[:40]!r} is not a number") from None
        return values

    def line(self, index: int) -> int:
        """The file line of data row ``index`` (0-based), for messages."""
        return self._lines[index]

    def text(self, name: str) -> str:
        raise LabRecordingError(f"{self.path}: variable {name!r}: a CSV/TSV file holds no "
                                "text variables; take the label from a value or the file name")

    def close(self) -> None:
        self._rows.clear()
