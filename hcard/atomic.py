"""Atomic file replacement: a failed write never leaves a half-written or missing file.

The bytes go to a temporary file next to the target (``.NAME.PID.XXXXXXXX.tmp``), are flushed
to disk, replace the target with :func:`os.replace` (atomic on POSIX and Windows), and the
directory is flushed too, so that the rename itself survives a power cut. A writer killed
between the two steps (kill -9) leaves its temporary file behind; the next write to the same
target removes such files once their writer's process is gone and they are older than
:data:`STALE_AFTER_S`. A target that is a symbolic link is written through the link: the link
stays and the file it points to is replaced.

Files that belong together (a card and its preview, a recording's CSV and its sidecar) are
replaced together by :func:`atomic_outputs`: every new file is written and flushed before any
target is touched, so a full disk or a failed writer leaves all the old files; a rename that
fails after others succeeded puts those back from hard links kept for the purpose.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import time
from collections.abc import Iterator, Sequence
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
    remove_stale_temporaries(target)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp",
                                    dir=_directory_of(target))
    try:
        with os.fdopen(fd, "wb") as tmp:
            yield tmp
            tmp.flush()
            os.fsync(tmp.fileno())
        _set_mode(tmp_name, target)
        os.replace(tmp_name, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp_name)
        raise
    sync_directory(_directory_of(target))


@contextlib.contextmanager
def atomic_outputs(paths: Sequence[str | os.PathLike[str]]) -> Iterator[list[BinaryIO]]:
    """Binary files to write the new content of each of ``paths`` into; they replace their
    targets together when the block ends without an exception, and none does when one
    escapes (module docstring). Symbolic links are written through, as by
    :func:`atomic_output`."""
    targets = []
    for path in paths:
        target = Path(path)
        targets.append(Path(os.path.realpath(target)) if target.is_symlink() else target)
    staged: list[tuple[Path, str, BinaryIO]] = []
    try:
        for target in targets:
            remove_stale_temporaries(target)
            fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.",
                                            suffix=".tmp", dir=_directory_of(target))
            staged.append((target, tmp_name, os.fdopen(fd, "wb")))
        yield [file for _, _, file in staged]
        for target, tmp_name, file in staged:
            file.flush()
            os.fsync(file.fileno())
            file.close()
            _set_mode(tmp_name, target)
        _replace_all([(tmp_name, target) for target, tmp_name, _ in staged])
    except BaseException:
        for _, tmp_name, file in staged:
            with contextlib.suppress(OSError):
                file.close()
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
        raise
    for directory in {_directory_of(target) for target in targets}:
        sync_directory(directory)


def write_atomically_together(contents: Sequence[tuple[str | os.PathLike[str], bytes]]) -> None:
    """Write each ``(path, data)`` so that readers see all the old files or all the new ones
    (:func:`atomic_outputs`)."""
    with atomic_outputs([path for path, _ in contents]) as files:
        for file, (_, data) in zip(files, contents, strict=True):
            file.write(data)


def _directory_of(target: Path) -> Path:
    return target.parent if str(target.parent) else Path(".")


def _set_mode(tmp_name: str, target: Path) -> None:
    """Give the new file the mode of the one it replaces, or the umask's for a new file."""
    if target.exists():
        with contextlib.suppress(OSError):
            os.chmod(tmp_name, target.stat().st_mode & 0o7777)
    else:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_name, 0o666 & ~umask)


def _replace_all(moves: list[tuple[str, Path]]) -> None:
    """Rename each staged file onto its target; when one rename fails, the targets already
    replaced get their old files back (kept as hard links, named like a temporary file so that
    a killed writer's are cleaned, until all are in) and the error is raised. Where hard links
    are not to be had the new file stays: only the rename's own failure is then not undone."""
    kept: list[tuple[Path, Path | None, bool]] = []  # target, its old file's link, existed
    olds = [Path(tmp_name.removesuffix(".tmp") + "-old.tmp") for tmp_name, _ in moves]
    try:
        for (tmp_name, target), old_link in zip(moves, olds, strict=True):
            existed, old = target.exists(), None
            if existed and len(moves) > 1:
                try:
                    os.link(target, old_link)
                    old = old_link
                except OSError:
                    old = None
            os.replace(tmp_name, target)
            kept.append((target, old, existed))
    except BaseException:
        for target, old, existed in reversed(kept):
            with contextlib.suppress(OSError):
                if old is not None:
                    os.replace(old, target)
                elif not existed:
                    os.unlink(target)
        raise
    finally:
        for old_link in olds:
            with contextlib.suppress(OSError):
                os.unlink(old_link)


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
    now = time.time() if now is None else now
    removed: list[Path] = []
    for leftover in dead_writers_leftovers(target, ".tmp"):
        with contextlib.suppress(OSError):
            if now - leftover.lstat().st_mtime > STALE_AFTER_S:
                leftover.unlink()
                removed.append(leftover)
    return removed


def dead_writers_leftovers(target: Path, suffix: str) -> list[Path]:
    """The entries next to ``target`` named ``.NAME.PID.XXXXXXXX<suffix>`` (a writer's
    temporary file or folder) whose process ``PID`` no longer runs (empty when the folder
    cannot be read)."""
    directory = _directory_of(target)
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(\d+)\.[^.]+{re.escape(suffix)}")
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    return [directory / name for name in names
            if (match := pattern.fullmatch(name)) is not None
            and not process_runs(int(match[1]))]


def process_runs(pid: int) -> bool:
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
