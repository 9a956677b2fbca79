"""Atomic file replacement: a failed write never leaves a half-written or missing file.

The bytes go to a temporary file next to the target (``.NAME.PID.XXXXXXXX.tmp``), are flushed
to disk, replace the target with :func:`os.replace` (atomic on POSIX and Windows), and the
directory is flushed too, so that the rename itself survives a power cut. A writer killed
between the two steps (kill -9) leaves its temporary file behind; the next write to the same
target removes such files once their writer's process is gone and they are older than
:data:`STALE_AFTER_S`. A target that is a symbolic link is written through the link: the link
stays and the file it points to is replaced.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

STALE_AFTER_S = 60.0
"""Age after which a temporary file of a writer that no longer runs is removed, s."""


def write_atomically(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the new one.

    On any failure the temporary file is removed and the previous content of ``path`` is left
    untouched (module docstring). A symbolic link at ``path`` is kept and its target written.
    """
    with atomic_output(path) as out:
        out.write(data)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """A binary file to write ``path``'s new content into, piece by piece (output of any
    length in bounded memory); it replaces ``path`` when the block ends without an exception,
    and is removed, leaving ``path`` as it was, when one escapes (module docstring)."""
    target = Path(path)
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    directory = target.parent if str(target.parent) else Path(".")
    remove_stale_temporaries(target)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp",
                                    dir=directory)
    try:
        with os.fdopen(fd, "wb") as tmp:
            yield tmp
            tmp.flush()
            os.fsync(tmp.fileno())
        if target.exists():
            with contextlib.suppress(OSError):
                os.chmod(tmp_name, target.stat().st_mode & 0o7777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_name, 0o666 & ~umask)
        os.replace(tmp_name, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp_name)
        raise
    sync_directory(directory)


def sync_directory(directory: Path) -> None:
    """Flush ``directory``'s entries to disk (a rename is durable only then); a no-op where
    directories cannot be opened (Windows)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def remove_stale_temporaries(target: Path, *, now: float | None = None) -> list[Path]:
    """Remove the temporary files left next to ``target`` by writers that were killed: those
    named ``.NAME.PID.*.tmp`` whose process ``PID`` no longer runs and that are older than
    :data:`STALE_AFTER_S`. Returns the files removed."""
    directory = target.parent if str(target.parent) else Path(".")
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(\d+)\.[^.]+\.tmp")
    now = time.time() if now is None else now
    removed: list[Path] = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        match = pattern.fullmatch(name)
        if match is None or _process_runs(int(match[1])):
            continue
        leftover = directory / name
        with contextlib.suppress(OSError):
            if now - leftover.lstat().st_mtime > STALE_AFTER_S:
                leftover.unlink()
                removed.append(leftover)
    return removed


def _process_runs(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (always assumed on Windows, where
    ``os.kill`` would end the process instead of probing it)."""
    if pid == os.getpid() or os.name == "nt":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # another user's process, or a number this system cannot hold
    return True
