"""The STATE reports of a session, kept as packed rows at their wire widths.

A play at the input rate (1 kHz) receives 3.6 million reports an hour. As :class:`State`
objects they cost about 1.5 kB each in CPython; :class:`StateLog` keeps each one as the 58
bytes it was sent in (spec/device-protocol.md section 6, without the report ID), in a NumPy
structured array whose field names are those of :class:`State`, so that a recording is built
column by column without a Python loop over the reports. Indexing and iteration still give
:class:`State` objects for code that reads a few reports.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import fields
from typing import overload

import numpy as np

from hcard.device.protocol import State

_NUMPY_CODE = {"B": "u1", "H": "<u2", "I": "<u4", "h": "<i2", "i": "<i4"}


def _row_layout() -> tuple[struct.Struct, np.dtype]:
    """The STATE layout without its report ID byte, as a ``struct`` and as a NumPy dtype with
    one field per :class:`State` field (``corner_forces_mn`` a field of 4), both read from
    ``State.STRUCT`` so the two cannot drift apart."""
    codes = State.STRUCT.format.lstrip("<")[1:]  # drop the report ID
    names = iter(f.name for f in fields(State))
    layout: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    count = ""
    for code in codes:
        if code.isdigit():
            count += code
            continue
        name = next(names)
        if count:
            layout.append((name, _NUMPY_CODE[code], (int(count),)))
            count = ""
        else:
            layout.append((name, _NUMPY_CODE[code]))
    row = np.dtype(layout)
    packer = struct.Struct("<" + codes)
    if row.itemsize != packer.size:
        raise AssertionError(f"STATE row layout: {row.itemsize} != {packer.size} bytes")
    return packer, row


ROW_STRUCT, STATE_ROW = _row_layout()
"""One STATE report without its ID byte: the ``struct`` that packs it and the NumPy dtype that
reads it (58 bytes)."""


class StateLog(Sequence[State]):
    """STATE reports in arrival order, packed (module docstring).

    ``append``/``extend`` pack reports as they arrive; :meth:`rows` gives them all as one
    structured array (fields named as in :class:`State`, wire units); :attr:`faults_seen` is the
    OR of every report's fault bits.
    """

    CHUNK_REPORTS = 4096
    """Reports packed into one bytes buffer before it becomes an array."""

    def __init__(self, states: Iterable[State] = ()) -> None:
        self._chunks: list[np.ndarray] = []
        self._pending = bytearray()
        self._pending_count = 0
        self._length = 0
        self._rows: np.ndarray | None = None
        self.faults_seen = 0
        self.extend(states)

    def append(self, state: State) -> None:
        """Keep one report."""
        self._pending += ROW_STRUCT.pack(*state._values())
        self._pending_count += 1
        self._length += 1
        self.faults_seen |= state.faults
        self._rows = None
        if self._pending_count >= self.CHUNK_REPORTS:
            self._seal()

    def extend(self, states: Iterable[State]) -> None:
        """Keep reports in order."""
        for state in states:
            self.append(state)

    def _seal(self) -> None:
        if self._pending_count:
            self._chunks.append(np.frombuffer(bytes(self._pending), dtype=STATE_ROW))
            self._pending.clear()
            self._pending_count = 0

    def rows(self) -> np.ndarray:
        """Every report as one structured array of :data:`STATE_ROW` (wire units)."""
        if self._rows is None:
            self._seal()
            if not self._chunks:
                self._rows = np.zeros(0, dtype=STATE_ROW)
            elif len(self._chunks) == 1:
                self._rows = self._chunks[0]
            else:
                self._rows = np.concatenate(self._chunks)
                self._chunks = [self._rows]
        return self._rows

    def field(self, name: str) -> np.ndarray:
        """One field of every report (a :class:`State` field name, wire units)."""
        return self.rows()[name]

    @property
    def nbytes(self) -> int:
        """Bytes the packed reports take."""
        return self._length * STATE_ROW.itemsize

    def __len__(self) -> int:
        return self._length

    @overload
    def __getitem__(self, index: int) -> State: ...

    @overload
    def __getitem__(self, index: slice) -> list[State]: ...

    def __getitem__(self, index: int | slice) -> State | list[State]:
        rows = self.rows()
        if isinstance(index, slice):
            return [_state(row) for row in rows[index]]
        return _state(rows[index])

    def __iter__(self) -> Iterator[State]:
        for row in self.rows():
            yield _state(row)

    def __repr__(self) -> str:
        return f"StateLog({self._length} reports, {self.nbytes} bytes)"


def state_field(states: Sequence[State], name: str) -> np.ndarray:
    """One field of every report (a :class:`State` field name, wire units): read from the
    packed rows of a :class:`StateLog`, gathered from the objects of any other sequence."""
    if isinstance(states, StateLog):
        return states.field(name)
    return np.array([getattr(state, name) for state in states], dtype=STATE_ROW[name].base)


def _state(row: np.void) -> State:
    """The report of one packed row."""
    return State.decode(bytes([State.REPORT_ID]) + row.tobytes())
