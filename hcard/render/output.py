"""Rendered frames to a file block by block: output of any length in bounded memory.

A rendering of a long track at 10 kHz is millions of frames; building the whole CSV in memory
took 2.06 GB for a 10-minute track. The writers here take the frames a block at a time (the
batch renderer's chunks) and write them as they come, into a temporary file that replaces the
output only when the last block is in (:func:`hcard.atomic.atomic_output`): an interrupted
rendering leaves the previous file as it was.

- :class:`CsvFrameWriter`: the CSV of spec/track-format.md, floats in their shortest round-trip
  form (rule TO1), so reading it back gives the rendered numbers exactly.
- :class:`NpzFrameWriter`: a NumPy ``.npz`` archive (deflated). Each column is spilled to its own
  temporary file while the blocks come, and the archive is assembled from those files at the
  end, member by member, through a fixed-size buffer. The spill folder, next to the output,
  is named ``.NAME.PID.XXXXXXXX.spill``: a writer killed with ``kill -9`` cannot remove it
  (212 MB for 10^7 frames), so every NPZ writer first removes the spill folders of its
  output whose process no longer runs and whose files have not changed for
  :data:`~hcard.atomic.STALE_AFTER_S` (:func:`remove_stale_spills`), as the atomic writer does
  with its temporary files.
"""

from __future__ import annotations

import abc
import contextlib
import os
import shutil
import tempfile
import time
import zipfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, BinaryIO

if TYPE_CHECKING:
    from typing_extensions import Self

import numpy as np

from hcard.atomic import STALE_AFTER_S, atomic_output, dead_writers_leftovers
from hcard.csv_rows import format_rows

Column = tuple[str, np.ndarray]
"""A named column of one block of frames."""


class _FrameWriter(abc.ABC):
    """A writer used as a context manager: :meth:`close` when the block ends, :meth:`abandon`
    (the output stays as it was) when an exception escapes it."""

    @abc.abstractmethod
    def close(self) -> None:
        """Finish the output: it replaces the file at the writer's path."""

    @abc.abstractmethod
    def abandon(self) -> None:
        """Drop what was written: the file at the writer's path stays as it was."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        if kind is not None:
            self.abandon()
        else:
            self.close()


class CsvFrameWriter(_FrameWriter):
    """Writes blocks of columns as CSV rows to ``path`` (atomically, at :meth:`close`)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self._output = atomic_output(path)
        self._file: BinaryIO = self._output.__enter__()
        self._names: list[str] | None = None

    def write(self, columns: Sequence[Column]) -> None:
        """Append one block's rows; the first block fixes the header."""
        names = [name for name, _ in columns]
        if self._names is None:
            self._names = names
            self._file.write((",".join(names) + "\n").encode())
        elif names != self._names:
            raise ValueError(f"block columns {names} differ from the header {self._names}")
        self._file.write(format_rows(columns).encode())

    def close(self) -> None:
        """Replace the output with what was written."""
        self._output.__exit__(None, None, None)

    def abandon(self) -> None:
        """Drop what was written; the output stays as it was."""
        dropped = RuntimeError("the rendering was abandoned")
        self._output.__exit__(RuntimeError, dropped, None)


class NpzFrameWriter(_FrameWriter):
    """Writes blocks of columns into a deflated ``.npz`` at ``path`` (module docstring)."""

    COPY_BUFFER_BYTES = 1 << 20
    """Bytes copied at a time from a spilled column into the archive."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self._path = Path(path)
        directory = self._path.parent if str(self._path.parent) else Path(".")
        remove_stale_spills(self._path)
        self._spill = tempfile.TemporaryDirectory(prefix=f".{self._path.name}.{os.getpid()}.",
                                                  suffix=SPILL_SUFFIX, dir=directory)
        self._columns: dict[str, tuple[np.dtype, BinaryIO]] = {}
        self._frames = 0

    def write(self, columns: Sequence[Column]) -> None:
        """Append one block of each column to its spill file."""
        if not self._columns:
            for name, values in columns:
                spill_path = Path(self._spill.name) / f"{name}.raw"
                self._columns[name] = (values.dtype, spill_path.open("wb"))
        lengths = {values.shape[0] for _, values in columns}
        if len(lengths) != 1 or [n for n, _ in columns] != list(self._columns):
            raise ValueError("every block must hold the same columns, of one length")
        for name, values in columns:
            dtype, spill = self._columns[name]
            np.ascontiguousarray(values, dtype=dtype).tofile(spill)
        self._frames += lengths.pop()

    def close(self) -> None:
        """Assemble the archive from the spilled columns and replace the output with it."""
        try:
            for _, spill in self._columns.values():
                spill.close()
            with atomic_output(self._path) as out, zipfile.ZipFile(
                    out, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
                for name, (dtype, _) in self._columns.items():
                    self._add_member(archive, name, dtype)
        finally:
            self._spill.cleanup()

    def _add_member(self, archive: zipfile.ZipFile, name: str, dtype: np.dtype) -> None:
        header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                  "shape": (self._frames,)}
        with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
            np.lib.format.write_array_header_2_0(member, header)
            with (Path(self._spill.name) / f"{name}.raw").open("rb") as raw:
                shutil.copyfileobj(raw, member, self.COPY_BUFFER_BYTES)

    def abandon(self) -> None:
        """Drop everything written; the output stays as it was."""
        for _, spill in self._columns.values():
            with contextlib.suppress(OSError):
                spill.close()
        self._spill.cleanup()


SPILL_SUFFIX = ".spill"
"""The end of a spill folder's name (``.NAME.PID.XXXXXXXX.spill``)."""


def remove_stale_spills(target: Path, *, now: float | None = None) -> list[Path]:
    """Remove the spill folders left next to ``target`` by NPZ writers that were killed: those
    named ``.NAME.PID.*.spill`` whose process ``PID`` no longer runs and in which nothing has
    changed for :data:`~hcard.atomic.STALE_AFTER_S`. Returns the folders removed."""
    now = time.time() if now is None else now
    removed: list[Path] = []
    for folder in dead_writers_leftovers(target, SPILL_SUFFIX):
        try:
            changed = max([folder.lstat().st_mtime]
                          + [entry.stat(follow_symlinks=False).st_mtime
                             for entry in os.scandir(folder)])
        except OSError:
            continue
        if now - changed > STALE_AFTER_S:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


def frame_writer(path: str | os.PathLike[str]) -> CsvFrameWriter | NpzFrameWriter:
    """The writer for ``path`` by its suffix: ``.npz`` archives, anything else CSV."""
    return NpzFrameWriter(path) if str(path).lower().endswith(".npz") else CsvFrameWriter(path)
