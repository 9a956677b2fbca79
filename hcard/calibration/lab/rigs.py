"""Which column map reads which recording, when a study was recorded on several rigs
(spec/lab-recordings.md LR14): ``--map RIG.json`` for every file, or ``--map 'GLOB=RIG.json'``
per rig, the first pattern that matches a file's path choosing its map."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

from hcard.calibration.lab.column_map import read_column_map
from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.reading import read_recording
from hcard.calibration.measurement import Measurement


@dataclass(frozen=True)
class RecordingFile:
    """A recording named by its file and the column map that reads it (None: the project's
    own CSV and sidecar); small and picklable, so that a task reads it where it runs."""

    path: str
    column_map: str | None = None

    def read(self) -> Measurement:
        """The measurement (the map read again here: a worker has only the file names)."""
        column_map = read_column_map(self.column_map) if self.column_map else None
        return read_recording(self.path, column_map)


@dataclass(frozen=True)
class RigMaps:
    """The ``--map`` values of a command: ``(pattern, map file)`` pairs in the order given
    (pattern ``*`` when a value has none)."""

    rules: tuple[tuple[str, str], ...] = ()

    @classmethod
    def parse(cls, values: tuple[str, ...] | list[str]) -> RigMaps:
        """``RIG.json`` or ``GLOB=RIG.json`` each; a map file that does not exist, or a
        value with an empty side, is an error naming it."""
        rules = []
        for value in values:
            pattern, _, map_file = value.rpartition("=") if "=" in value else ("*", "", value)
            if not pattern or not map_file:
                raise LabRecordingError(f"--map {value!r}: give RIG.json or GLOB=RIG.json")
            if not Path(map_file).is_file():
                raise LabRecordingError(f"--map {value!r}: {map_file}: no such file")
            rules.append((pattern, map_file))
        return cls(tuple(rules))

    def __bool__(self) -> bool:
        return bool(self.rules)

    def file(self, path: str | Path) -> RecordingFile:
        """``path`` with the map of the first pattern its path matches; a file no pattern
        matches, when there are patterns, is an error naming it."""
        text = str(path)
        for pattern, map_file in self.rules:
            if fnmatch.fnmatch(text, pattern) or fnmatch.fnmatch(Path(text).name, pattern):
                return RecordingFile(text, map_file)
        if self.rules:
            raise LabRecordingError(f"{text}: no --map pattern matches this file (patterns: "
                                    f"{', '.join(p for p, _ in self.rules)})")
        return RecordingFile(text)
