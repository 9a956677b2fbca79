"""A small JSON file (a recording's sidecar, a column map) read within the size limit and
parsed, every failure one line naming the file (and the line and column of bad JSON)."""

from __future__ import annotations

import os
from typing import Any

from hcard.bounded_read import MAX_JSON_FILE_BYTES, InputTooLarge, read_bounded
from hcard.file_errors import ErrorFactory, reading
from hcard.json_text import JsonInputError, parse_json


def read_json_file(path: str | os.PathLike[str], error: ErrorFactory, *, what: str,
                   named: str, label: str, missing: str = "") -> Any:
    """The JSON value in ``path``, at most :data:`MAX_JSON_FILE_BYTES`; ``error(message)``
    raised when it cannot be read (``what``: the file in words, ``"a column map"``; ``missing``:
    the words for an absent one), is too large (``named``: ``"the conditions sidecar"``) or is
    not JSON (``"PATH:LINE:COL: bad LABEL JSON (reason)"``)."""
    source = str(path)
    try:
        with reading(path, error, what, missing=missing):
            raw = read_bounded(path, MAX_JSON_FILE_BYTES)
    except InputTooLarge as exc:
        raise error(f"{source}: {exc} ({named})") from None
    try:
        return parse_json(raw)
    except JsonInputError as exc:
        where = source if exc.line is None else f"{source}:{exc.line}:{exc.column}"
        raise error(f"{where}: bad {label} JSON ({exc.reason})") from None
