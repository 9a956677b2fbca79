"""The frame kernel: a block of frames from the touch samples (spec/README.md section 6).

Per segment of frames (one touch sample), dead reckoning and the taxtel under the finger, a
segment that crosses taxtels cut at its crossings (:mod:`hcard.render.frame_touch`,
:mod:`hcard.render.crossings`); per run of frames, the phase at the run's anchor, its step,
the band-limit gain and amplitude (:mod:`hcard.render.runs`); per frame, the components'
cosines summed per channel group and split into UV and EV, in passes that stay in the core's
cache (:mod:`hcard.render.synthesis`). Nothing per frame depends on the palette size or the
stroke speed. A batch rendering's blocks write into its output columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.render.clock import FrameClock
from hcard.render.compiled import CompiledCard
from hcard.render.frame_touch import SampleColumns, sample_columns, touch_frames
from hcard.render.options import RenderOptions
from hcard.render.runs import ANCHOR_FRAMES, RunParameters, Runs, find_runs, run_parameters
from hcard.render.synthesis import frame_targets
from hcard.render.touch import TouchTable


@dataclass(frozen=True)
class Block:
    """A block of rendered frames.

    Attributes:
        times: (N,) frame times, s.
        texture: (N,) active palette index, -1 for a neutral frame.
        uv: (N,) UV target, relative friction in [0, 1].
        ev: (N,) EV target, relative friction in [1, 4].
        phase: (N, max components) unwrapped phase of each component, turns (NaN where the
            frame has no such component), or None.
    """

    times: np.ndarray
    texture: np.ndarray
    uv: np.ndarray
    ev: np.ndarray
    phase: np.ndarray | None


RUN_TABLE_MAX_FRAMES = ANCHOR_FRAMES
"""Blocks of at most this many frames (streaming) and :data:`RUN_TABLE_MAX_RUNS` runs take
their frames from the runs' tables."""
RUN_TABLE_MAX_RUNS = 2
"""A block's first run usually continues from the block before and its last one into the
next; a block of more runs (texture changes every few frames) is computed directly."""
RUN_TABLES_KEPT = 8
"""Run tables a workspace keeps."""


@dataclass(frozen=True)
class RunTable:
    """Every frame a run can hold, computed at once: UV and EV targets of the ANCHOR_FRAMES
    frames from its anchor."""

    uv: np.ndarray
    ev: np.ndarray


class Workspace:
    """What a renderer keeps from block to block: the sample columns of the latest touch table
    and the tables of the latest runs. A stream renders several blocks on one table between two
    touch samples, and several blocks along one run: a run's frames are computed once, and each
    block copies its part (the numbers of a batch rendering: the same operations per frame)."""

    def __init__(self) -> None:
        self._columns: tuple[TouchTable, RenderOptions, SampleColumns] | None = None
        self._tables: dict[tuple, RunTable] = {}

    def sample_columns(self, table: TouchTable, options: RenderOptions) -> SampleColumns:
        """The :class:`SampleColumns` of ``table``, computed once per table."""
        cached = self._columns
        if cached is not None and cached[0] is table and cached[1] is options:
            return cached[2]
        columns = sample_columns(table, options)
        self._columns = (table, options, columns)
        return columns

    def run_table(self, card: CompiledCard, table: TouchTable, columns: SampleColumns,
                  runs: Runs, run: int, options: RenderOptions) -> RunTable:
        """The :class:`RunTable` of run ``run`` of ``runs``."""
        row = max(runs.sample[run], 0)
        # everything the table depends on besides the card and the options (fixed per
        # renderer): the sample's state, the texture, the side of H, the anchor time
        key = (runs.texture[run], runs.capped[run], runs.time[run], table.t.item(row),
               columns.start[row].tobytes(), columns.rate[row].tobytes())
        found = self._tables.get(key)
        if found is None:
            parameters = run_parameters(card, table, columns, runs.single(run), options)
            uv, ev = np.empty(ANCHOR_FRAMES), np.empty(ANCHOR_FRAMES)
            _frame_targets(card, parameters, None, np.arange(ANCHOR_FRAMES, dtype=np.uint32),
                           uv, ev)
            if len(self._tables) >= RUN_TABLES_KEPT:
                del self._tables[next(iter(self._tables))]  # the oldest
            found = self._tables[key] = RunTable(uv, ev)
        return found


def render_block(
    card: CompiledCard,
    table: TouchTable,
    clock: FrameClock,
    first: int,
    count: int,
    options: RenderOptions,
    workspace: Workspace,
    *,
    with_phase: bool = False,
    out: Block | None = None,
) -> Block:
    """Frames ``first .. first + count - 1`` of ``clock`` rendered from the touch samples of
    ``table`` (spec rules R5-R11), written into the arrays of ``out`` when given (which has a
    phase array if and only if ``with_phase``; a batch rendering's output columns), else
    returned in new ones."""
    times = clock.times(first, count, out=None if out is None else out.times)
    if len(table) == 0:
        return _neutral_block(card, times, with_phase, out)
    columns = workspace.sample_columns(table, options)
    frames = touch_frames(card, table, columns, times, options)
    if frames.neutral:
        return _neutral_block(card, times, with_phase, out)
    runs = find_runs(table, clock, first, frames, options.dead_reckoning_s)
    parameters = None
    if count <= RUN_TABLE_MAX_FRAMES and len(runs) <= RUN_TABLE_MAX_RUNS:
        uv, ev = _from_run_tables(card, table, columns, runs, options, workspace)
    else:
        parameters = run_parameters(card, table, columns, runs, options)
        offset = np.arange(count, dtype=np.uint32)  # frames since the anchor (wraps from < 0)
        offset -= np.repeat(np.asarray(runs.anchors).astype(np.uint32), runs.lengths)
        uv, ev = (np.empty(count), np.empty(count)) if out is None else (out.uv, out.ev)
        _frame_targets(card, parameters, np.asarray(runs.lengths), offset, uv, ev)
    phase = None
    if with_phase:
        if parameters is None:
            runs = Runs(*(np.asarray(getattr(runs, name)) for name in (
                "starts", "lengths", "anchors", "sample", "texture", "capped", "time")))
            parameters = run_parameters(card, table, columns, runs, options)
        phase = _unwrapped_phase(card, parameters, runs, times, frames.texture)
    block = Block(times, frames.texture, uv, ev, phase)
    return block if out is None else _copy_into(block, out)


def _frame_targets(card: CompiledCard, parameters: RunParameters, lengths: np.ndarray | None,
                   offset: np.ndarray, uv: np.ndarray, ev: np.ndarray) -> None:
    """UV and EV targets of frames ``offset`` frames after their runs' anchors (R9-R11),
    written into ``uv`` and ``ev``."""
    frame_targets(parameters.anchor, parameters.step, parameters.weights, parameters.baseline,
                  lengths, offset, list(card.channel_groups), uv, ev)


def _from_run_tables(card: CompiledCard, table: TouchTable, columns: SampleColumns,
                     runs: Runs, options: RenderOptions,
                     workspace: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """UV and EV targets of a short block, copied from its runs' tables."""
    parts = []
    for run in range(len(runs)):
        found = workspace.run_table(card, table, columns, runs, run, options)
        k = runs.starts[run] - runs.anchors[run]
        parts.append((found.uv[k:k + runs.lengths[run]], found.ev[k:k + runs.lengths[run]]))
    if len(parts) == 1:
        return parts[0][0].copy(), parts[0][1].copy()
    return np.concatenate([uv for uv, _ in parts]), np.concatenate([ev for _, ev in parts])


def _neutral_block(card: CompiledCard, times: np.ndarray, with_phase: bool,
                   out: Block | None) -> Block:
    n = times.shape[0]
    if out is None:
        phase = np.full((n, card.max_components), np.nan) if with_phase else None
        return Block(times, np.full(n, -1, np.int32), np.ones(n), np.ones(n), phase)
    out.texture.fill(-1)
    out.uv.fill(1.0)
    out.ev.fill(1.0)
    if out.phase is not None:
        out.phase.fill(np.nan)
    return out


def _copy_into(block: Block, out: Block) -> Block:
    """``out`` holding the arrays of ``block`` (the ones not written there already)."""
    for name in ("times", "texture", "uv", "ev", "phase"):
        source, target = getattr(block, name), getattr(out, name)
        if target is not None and source is not target:
            target[:] = source
    return out


def _unwrapped_phase(card: CompiledCard, parameters: RunParameters, runs: Runs,
                     times: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """(N, C) unwrapped phase of each frame's components, turns (R9, in double precision);
    NaN where the frame's texture has no such component or the frame is neutral."""
    unwrapped = np.repeat(parameters.rate, runs.lengths, axis=0)
    unwrapped *= (times - np.repeat(runs.time, runs.lengths))[:, None]
    unwrapped += np.repeat(parameters.phase, runs.lengths, axis=0)
    components = card.palette.n_components.take(texture)
    unwrapped[np.arange(card.max_components)[None, :] >= components[:, None]] = np.nan
    return unwrapped
