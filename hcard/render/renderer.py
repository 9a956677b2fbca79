"""Batch and streaming rendering of a card along a finger track.

Both modes run the same code: touch samples go through :func:`extend_table`, frames through
:func:`render_block`, so a stream fed block by block gives the numbers of a batch rendering of
the whole track.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from hcard.errors import TrackError, UsageError
from hcard.render.clock import FrameClock
from hcard.render.compiled import CompiledCard, compile_card
from hcard.render.kernel import Block, Workspace, render_block
from hcard.render.options import RenderOptions
from hcard.render.touch import TouchTable, empty_table, extend_table
from hcard.track import FingerTrack, make_track
from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid

BATCH_CHUNK_FRAMES = 1 << 15
"""Frames per block of :meth:`Renderer.blocks` (output of any length in bounded memory)."""
RENDER_CHUNK_FRAMES = 1 << 17
"""Frames per kernel call of :meth:`Renderer.render`, which holds the whole output anyway:
fewer calls, each with the same per-call bookkeeping (20 s at 10 kHz: 12.7 -> 10.7 ms CPU
against 32768-frame calls). The frames do not depend on the cut."""
MAX_RENDER_FRAMES = 100_000_000
"""Most frames one batch rendering may have (2.8 hours at the default 10 kHz; ~6 GB of CSV):
checked before any work, so a track with a 100,000 s gap or ``--frame-rate 1e12`` is refused at
once instead of ending in a MemoryError (spec/README.md section 4)."""


class RenderTooLong(UsageError):
    """A rendering would exceed :data:`MAX_RENDER_FRAMES` frames."""


@dataclass(frozen=True)
class Frames:
    """Rendered frames.

    Attributes:
        t: frame times, s.
        uv: UV target relative friction, in [0, 1].
        ev: EV target relative friction, in [1, 4].
        contact: finger on the surface.
        texture: active palette index, -1 for a neutral frame.
        phase: optional (N, max components) unwrapped component phase, turns.
    """

    t: np.ndarray
    uv: np.ndarray
    ev: np.ndarray
    contact: np.ndarray
    texture: np.ndarray
    phase: np.ndarray | None = None

    @property
    def friction(self) -> np.ndarray:
        """Total target relative friction ``uv * ev`` (coupled model, thesis Eq. 4.1)."""
        return self.uv * self.ev

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def rows(self, start: int, end: int) -> Frames:
        """Frames ``start .. end - 1``, as views of these arrays."""
        return Frames(self.t[start:end], self.uv[start:end], self.ev[start:end],
                      self.contact[start:end], self.texture[start:end],
                      None if self.phase is None else self.phase[start:end])

    @staticmethod
    def concatenate(parts: list[Frames]) -> Frames:
        """Frames of ``parts`` one after another."""
        phase = None
        if parts and all(p.phase is not None for p in parts):
            phase = np.concatenate([p.phase for p in parts])
        return Frames(
            np.concatenate([p.t for p in parts]),
            np.concatenate([p.uv for p in parts]),
            np.concatenate([p.ev for p in parts]),
            np.concatenate([p.contact for p in parts]),
            np.concatenate([p.texture for p in parts]),
            phase,
        )


class Renderer:
    """Renders one card with fixed options; cheap to reuse for many tracks."""

    def __init__(self, card: pb.Card, options: RenderOptions | None = None, *,
                 check: bool = True) -> None:
        """A renderer of ``card`` with ``options`` (defaults when None). With ``check`` the card
        is validated first (:class:`~hcard.errors.CardValidationError` when invalid); a caller
        that validated it already (:func:`hcard.card_io.load`,
        :func:`hcard.validate.require_valid`) passes ``check=False``."""
        if check:
            require_valid(card)
        self.card = card
        self.options = options or RenderOptions()
        self.compiled: CompiledCard = compile_card(card, self.options)
        self._workspace = Workspace()

    @classmethod
    def from_compiled(cls, card: pb.Card, compiled: CompiledCard,
                      options: RenderOptions | None = None) -> Renderer:
        """A renderer of ``card`` from its compiled form, made elsewhere (another process) by
        :func:`~hcard.render.compiled.compile_card` with the same ``options`` from the card
        validated there: neither validated nor compiled again, so that a device can take a
        large card into force without spending that time on its real-time process."""
        renderer = cls.__new__(cls)
        renderer.card = card
        renderer.options = options or RenderOptions()
        renderer.compiled = compiled
        renderer._workspace = Workspace()
        return renderer

    def frame_times(self, t0: float, first: int, count: int) -> np.ndarray:
        """Times of frames ``first .. first+count-1`` of a rendering starting at ``t0``, s."""
        return FrameClock(t0, self.options.frame_rate_hz).times(first, count)

    def _block(self, table: TouchTable, clock: FrameClock, first: int, count: int,
               with_phase: bool, out: Frames | None = None) -> Frames:
        """Frames ``first .. first + count - 1`` of ``clock``, written into ``out`` when given
        (which has a phase if and only if ``with_phase``)."""
        if out is None:
            block = render_block(self.compiled, table, clock, first, count, self.options,
                                 self._workspace, with_phase=with_phase)
            return Frames(block.times, block.uv, block.ev, block.texture >= 0, block.texture,
                          block.phase)
        render_block(self.compiled, table, clock, first, count, self.options, self._workspace,
                     with_phase=with_phase,
                     out=Block(out.t, out.texture, out.uv, out.ev, out.phase))
        np.greater_equal(out.texture, 0, out=out.contact)
        return out

    def frame_count(self, track: FingerTrack) -> int:
        """Frames of a batch rendering of ``track``: from its first to its last sample.

        Raises:
            RenderTooLong: more than :data:`MAX_RENDER_FRAMES` (checked before any work).
        """
        frames = track.duration_s * self.options.frame_rate_hz + 1e-9
        # compared as a float first: a span of 1e305 s is an infinite number of frames, which
        # math.floor cannot turn into an int (an OverflowError, exit 3, before this check)
        if not frames < MAX_RENDER_FRAMES:
            raise RenderTooLong(
                f"the track spans {track.duration_s:.6g} s: {frames:.4g} frames at "
                f"{self.options.frame_rate_hz:g} Hz, over the limit of {MAX_RENDER_FRAMES:.0e} "
                "(render a shorter track, or at a lower frame rate; spec/track-format.md TK8)")
        return math.floor(frames) + 1

    def blocks(
        self,
        track: FingerTrack,
        *,
        with_phase: bool = False,
    ) -> Iterator[Frames]:
        """The batch rendering of ``track`` in consecutive blocks of at most
        :data:`BATCH_CHUNK_FRAMES` frames (each computed from the whole track, so the blocks
        joined are :meth:`render`'s frames exactly): output of any length in bounded memory.

        Raises:
            RenderTooLong: the track needs more than :data:`MAX_RENDER_FRAMES` frames.
        """
        yield from self._chunks(track, BATCH_CHUNK_FRAMES, with_phase)

    def _chunks(self, track: FingerTrack, chunk: int, with_phase: bool) -> Iterator[Frames]:
        """:meth:`blocks` of at most ``chunk`` frames."""
        total = self.frame_count(track)
        table, clock = self._table_and_clock(track)
        for first in range(0, total, chunk):
            yield self._block(table, clock, first, min(chunk, total - first), with_phase)

    def _table_and_clock(self, track: FingerTrack) -> tuple[TouchTable, FrameClock]:
        """The touch table of ``track`` and the frame clock of its batch rendering."""
        table = extend_table(
            empty_table(),
            track.t,
            np.column_stack((track.x, track.y)),
            track.contact,
            self.options.dead_reckoning_s,
        )
        return table, FrameClock(float(track.t[0]), self.options.frame_rate_hz)

    def render(
        self,
        track: FingerTrack,
        *,
        with_phase: bool = False,
        progress: Callable[[int, int], None] | None = None,
    ) -> Frames:
        """Render the whole track (batch mode): frames from its first to its last sample.

        Args:
            track: touch samples.
            with_phase: also return each component's unwrapped phase (diagnostics).
            progress: called as ``progress(frames_done, frames_total)`` after each chunk.

        Raises:
            RenderTooLong: the track needs more than :data:`MAX_RENDER_FRAMES` frames.
        """
        total = self.frame_count(track)
        out = _frame_columns(total, self.compiled.max_components if with_phase else None)
        table, clock = self._table_and_clock(track)
        for first in range(0, total, RENDER_CHUNK_FRAMES):
            end = min(first + RENDER_CHUNK_FRAMES, total)
            self._block(table, clock, first, end - first, with_phase, out=out.rows(first, end))
            if progress is not None:
                progress(end, total)
        return out

    def stream(self, t0: float | None = None) -> RenderStream:
        """A streaming renderer; frame 0 falls at ``t0`` (default: the first pushed sample)."""
        return RenderStream(self, t0)


class RenderStream:
    """Streaming mode: push touch samples as they arrive, pull blocks of frames.

    A frame uses the samples pushed before it is rendered; push every sample with time up to
    the end of a block before rendering that block to get batch-identical numbers.
    """

    def __init__(self, renderer: Renderer, t0: float | None = None) -> None:
        self.renderer = renderer
        self.t0 = t0
        self.next_frame = 0
        self._table = empty_table()

    @property
    def next_time(self) -> float:
        """Time of the next frame to be rendered, s (NaN before the first sample)."""
        if self.t0 is None:
            return math.nan
        return self.t0 + self.next_frame / self.renderer.options.frame_rate_hz  # as frame_times

    def push(
        self,
        t: np.ndarray | float,
        x: np.ndarray | float,
        y: np.ndarray | float,
        fn: np.ndarray | float | None = None,
        contact: np.ndarray | bool | None = None,
    ) -> None:
        """Append touch samples (scalars or arrays), later than every sample pushed so far."""
        samples = make_track(t, x, y, fn, contact, source="stream")
        if len(self._table) and samples.t[0] <= self._table.t[-1]:
            raise TrackError(
                f"stream: sample time {samples.t[0]} does not follow the last pushed sample "
                f"({self._table.t[-1]})"
            )
        if self.t0 is None:
            self.t0 = float(samples.t[0])
        new = extend_table(
            self._table,
            samples.t,
            np.column_stack((samples.x, samples.y)),
            samples.contact,
            self.renderer.options.dead_reckoning_s,
        )
        self._table = self._table.concat(new)

    def render(self, n_frames: int, *, with_phase: bool = False,
               time_shift_s: float = 0.0) -> Frames:
        """Render the next ``n_frames`` frames.

        ``time_shift_s``: the frames are rendered at their frame times plus this (s), on the
        time line of the pushed samples. A device that times the host's samples on the host's
        clock renders on that time line (spec/device-protocol.md PO2): when its estimate of
        the clock offset moves, the frames move with it, and velocity, odometer and the
        temporal phase stay those of the samples' own spacing. The returned frames carry the
        shifted times.
        """
        if self.t0 is None:
            raise TrackError("stream: push a touch sample before rendering")
        clock = FrameClock(self.t0, self.renderer.options.frame_rate_hz, time_shift_s)
        frames = self.renderer._block(self._table, clock, self.next_frame, n_frames, with_phase)
        self.next_frame += n_frames
        # Keep only the samples later frames can still use: the last one at or before the
        # next frame time (less one dead-reckoning horizon, for a shift that moves back) and
        # everything after it.
        if len(self._table):
            horizon = self.renderer.options.dead_reckoning_s
            earliest = self.next_time + time_shift_s - horizon
            keep = max(int(self._table.t.searchsorted(earliest, side="right")) - 1, 0)
            if keep:
                self._table = self._table.tail(keep)
        return frames


def _frame_columns(total: int, components: int | None) -> Frames:
    """Uninitialised :class:`Frames` of ``total`` frames (with a phase of ``components``
    columns, or none), every column a view of one allocation: NumPy asks the kernel for huge
    pages for an allocation of 4 MiB or more, where five separate columns (up to 1.6 MB for
    200,000 frames) fault in every 4 KiB page on first write (2300 faults, about 3 ms of a
    20 s rendering on the machine of bench/bench_renderer.py)."""
    float_columns = 3 + (components or 0)
    memory = np.empty(total * (8 * float_columns + 4 + 1), dtype=np.uint8)
    floats = memory[:8 * float_columns * total].view(np.float64)
    rest = memory[8 * float_columns * total:]
    phase = floats[3 * total:].reshape(total, components) if components is not None else None
    return Frames(floats[:total], floats[total:2 * total], floats[2 * total:3 * total],
                  rest[4 * total:].view(bool), rest[:4 * total].view(np.int32), phase)


def render(
    card: pb.Card, track: FingerTrack, options: RenderOptions | None = None, *,
    check: bool = True,
) -> Frames:
    """Render ``card`` along ``track`` (batch mode); ``check``: validate the card first (see
    :class:`Renderer`)."""
    return Renderer(card, options, check=check).render(track)
