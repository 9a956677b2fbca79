"""A file that cannot be read or written, as the one-line user error every command gives.

Readers and writers of every format (cards, tracks, measurements and their sidecars, device
profiles, images, recordings, reports) wrap their file operations in :func:`reading` or
:func:`writing`, which turn an :class:`OSError` into an error of the caller's type whose
message names the file and says why, in one line (README "Exit status": invalid input is one
line and status 1, never a traceback)::

    card.hcard: no such file
    tracks/: is a directory, not a CSV file
    card.hcard: cannot read (Permission denied)
    out.csv: cannot write (No space left on device)

An error type that keeps the file apart from the reason (:class:`~hcard.errors.CardError`'s
``source`` and ``reason``) takes :func:`read_reason` or :func:`write_reason` instead.

Errors that are not about the file system (a file too large for its format, bytes that are not
UTF-8) are the caller's to describe; they pass through unchanged.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator

ErrorFactory = Callable[[str], Exception]
"""Makes the error raised from its one-line message (an error class such as
:class:`~hcard.errors.CardError` or :class:`~hcard.errors.TrackError`)."""


def os_reason(exc: OSError) -> str:
    """Why an operating-system call failed, in a few words: its ``strerror`` ("Permission
    denied"), else its text, else the name of its type."""
    return exc.strerror or str(exc) or type(exc).__name__


def read_reason(exc: OSError, what: str = "a file", *, missing: str = "") -> str:
    """Why a file could not be read, for a message that names it: ``"no such file"``
    (followed by `` (MISSING)`` when ``missing`` says more, e.g. which file of several it is),
    ``"is a directory, not WHAT"`` (``what``: the kind of file expected, e.g. ``"a card
    file"``) or ``"cannot read (REASON)"``."""
    if isinstance(exc, FileNotFoundError):
        return "no such file" + (f" ({missing})" if missing else "")
    if isinstance(exc, IsADirectoryError):
        return f"is a directory, not {what}"
    return f"cannot read ({os_reason(exc)})"


def write_reason(exc: OSError, doing: str = "write") -> str:
    """Why a file could not be written, for a message that names it: ``"cannot DOING
    (REASON)"`` (``doing``: ``"write"``, ``"create"``, ``"write the card and its preview"``)."""
    return f"cannot {doing} ({os_reason(exc)})"


def read_failure(path: str | os.PathLike[str], exc: OSError, what: str = "a file", *,
                 missing: str = "") -> str:
    """The one-line message for ``path`` that could not be read: ``"PATH: "`` and
    :func:`read_reason`."""
    return f"{path}: {read_reason(exc, what, missing=missing)}"


def write_failure(path: str | os.PathLike[str], exc: OSError, doing: str = "write") -> str:
    """The one-line message for ``path`` that could not be written: ``"PATH: "`` and
    :func:`write_reason`."""
    return f"{path}: {write_reason(exc, doing)}"


@contextlib.contextmanager
def reading(path: str | os.PathLike[str], error: ErrorFactory, what: str = "a file", *,
            missing: str = "") -> Iterator[None]:
    """Within the block, an :class:`OSError` becomes ``error(read_failure(path, exc, what,
    missing=missing))`` (raised without the chained ``OSError``: the message says all of
    it)."""
    try:
        yield
    except OSError as exc:
        raise error(read_failure(path, exc, what, missing=missing)) from None


@contextlib.contextmanager
def writing(path: str | os.PathLike[str], error: ErrorFactory,
            doing: str = "write") -> Iterator[None]:
    """Within the block, an :class:`OSError` becomes ``error(write_failure(path, exc,
    doing))``."""
    try:
        yield
    except OSError as exc:
        raise error(write_failure(path, exc, doing)) from None
