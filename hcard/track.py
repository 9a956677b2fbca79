"""Finger tracks: touch samples (t, x, y, Fn, contact) as arrays, and their CSV form.

The CSV format is normative in spec/track-format.md: a header row naming the columns ``t_s``
(s), ``x_mm``, ``y_mm`` (required), ``fn_n`` (N, default 0.5) and ``contact`` (0/1, default 1);
``#`` comment lines; strictly increasing time; finite numbers.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hcard.csv_rows import numeric_table, read_csv_text
from hcard.errors import TrackError
from hcard.rates import TOUCH_RATE_HZ

MAX_TRACK_SAMPLES = 1 << 22
"""Most samples a track file may hold (spec/track-format.md TK8): 4,194,304, 70 minutes at
1 kHz, 23 hours at a 50 Hz touch screen. ``hcard render`` holds about 270 bytes a sample
(the track, and the renderer's touch table and its temporaries: 2.67 GB for 10^7 samples),
so the limit bounds it near 1.1 GB (bench/bench_hostile_inputs.py)."""
DEFAULT_NORMAL_FORCE_N = 0.5
REQUIRED_COLUMNS = ("t_s", "x_mm", "y_mm")
OPTIONAL_COLUMNS = ("fn_n", "contact")


@dataclass(frozen=True)
class FingerTrack:
    """Touch samples of one finger.

    Attributes:
        t: sample times, s, strictly increasing, shape (M,).
        x, y: positions on the surface, mm (origin top-left, +y down), shape (M,).
        normal_force: normal force, N, shape (M,) (CSV column ``fn_n``).
        contact: True while the finger touches the surface, shape (M,).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    normal_force: np.ndarray
    contact: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0


def make_track(
    t: np.ndarray | float,
    x: np.ndarray | float,
    y: np.ndarray | float,
    normal_force: np.ndarray | float | None = None,
    contact: np.ndarray | bool | None = None,
    *,
    source: str = "track",
) -> FingerTrack:
    """Build a checked :class:`FingerTrack` from array-likes; raise :class:`TrackError`.

    ``normal_force`` (N) defaults to :data:`DEFAULT_NORMAL_FORCE_N` and ``contact`` to True;
    errors name the CSV columns (``fn_n`` for the normal force, spec/track-format.md).
    """
    t_arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
    n = t_arr.shape[0]
    if n == 0:
        raise TrackError(f"{source}: no samples")

    def column(values: object, name: str, default: float) -> np.ndarray:
        if values is None:
            return np.full(n, default, dtype=np.float64)
        arr = np.asarray(values, dtype=np.float64)
        if arr.ndim == 0:
            return np.full(n, float(arr))
        arr = arr.ravel()
        if arr.shape[0] != n:
            raise TrackError(f"{source}: column {name} has {arr.shape[0]} values, t has {n}")
        return arr

    x_arr = column(x, "x_mm", math.nan)
    y_arr = column(y, "y_mm", math.nan)
    fn_arr = column(normal_force, "fn_n", DEFAULT_NORMAL_FORCE_N)
    contact_arr = column(contact, "contact", 1.0)
    # each check is one pass that finds nothing in a valid track (a stream pushes one sample
    # at a time); only a failed one looks for the sample to name
    for name, arr in (("t_s", t_arr), ("x_mm", x_arr), ("y_mm", y_arr), ("fn_n", fn_arr)):
        if not np.logical_and.reduce(np.isfinite(arr)):
            bad = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise TrackError(f"{source}: column {name} has a non-finite value at sample {bad}")
    if n > 1 and not np.logical_and.reduce(t_arr[1:] > t_arr[:-1]):
        i = int(np.flatnonzero(t_arr[1:] <= t_arr[:-1])[0]) + 1
        raise TrackError(
            f"{source}: time must increase strictly, but t_s[{i}] = {t_arr[i]} follows "
            f"{t_arr[i - 1]}"
        )
    if not np.logical_and.reduce((contact_arr == 0.0) | (contact_arr == 1.0)):
        raise TrackError(f"{source}: column contact must hold only 0 or 1")
    return FingerTrack(t_arr, x_arr, y_arr, fn_arr, contact_arr.astype(bool))


def read_track_csv(path: str | os.PathLike[str]) -> FingerTrack:
    """Read a track CSV (spec/track-format.md); raise :class:`TrackError` naming file and line."""
    return parse_track_csv(read_csv_text(path, TrackError), source=str(Path(path)))


def parse_track_csv(text: str, *, source: str = "track") -> FingerTrack:
    """Parse the CSV text of a track (:func:`hcard.csv_rows.numeric_table`)."""

    def check_header(names: list[str], line: int) -> None:
        missing = [name for name in REQUIRED_COLUMNS if name not in names]
        if missing:
            raise TrackError(
                f"{source}:{line}: header lacks column(s) {', '.join(missing)} "
                f"(found {', '.join(names) or 'nothing'})"
            )

    _, names, values, _ = numeric_table(
        text, source, TrackError, check_header,
        max_rows=(MAX_TRACK_SAMPLES, "the most a track may hold, spec/track-format.md TK8"))
    wanted = [name for name in (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS) if name in names]
    data = {name: values[:, names.index(name)] for name in wanted}
    if not data["t_s"].size:
        raise TrackError(f"{source}: no samples after the header")
    return make_track(
        data["t_s"],
        data["x_mm"],
        data["y_mm"],
        data.get("fn_n"),
        data.get("contact"),
        source=source,
    )


def track_to_csv(track: FingerTrack) -> str:
    """The CSV text of ``track`` (full float precision)."""
    lines = ["t_s,x_mm,y_mm,fn_n,contact"]
    for t, x, y, fn, c in zip(
        track.t, track.x, track.y, track.normal_force, track.contact, strict=True
    ):
        lines.append(f"{float(t)!r},{float(x)!r},{float(y)!r},{float(fn)!r},{int(c)}")
    return "\n".join(lines) + "\n"


def straight_stroke(
    start_mm: tuple[float, float],
    velocity_mm_s: tuple[float, float],
    duration_s: float,
    *,
    rate_hz: float = TOUCH_RATE_HZ,
    normal_force_n: float = DEFAULT_NORMAL_FORCE_N,
    t0: float = 0.0,
) -> FingerTrack:
    """A constant-velocity stroke sampled at ``rate_hz`` (a capacitive touch screen: 50 Hz)
    at the normal force ``normal_force_n``, N."""
    n = math.floor(duration_s * rate_hz + 1e-9) + 1
    t = t0 + np.arange(n) / rate_hz
    x = start_mm[0] + velocity_mm_s[0] * (t - t0)
    y = start_mm[1] + velocity_mm_s[1] * (t - t0)
    return make_track(t, x, y, normal_force_n)
