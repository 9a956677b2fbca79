"""The frame kernel: phase, band-limit gain and channel split for a block of frames.

Frames are grouped by active texture so each texture's components are evaluated as dense
(frames x components) arrays. The phase is formed in float64 turns and reduced to one turn
before the cosine, which is evaluated in float32 (error < 1e-6 relative friction, spec 6).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hcard.render.compiled import (
    GROUP_BIPOLAR,
    GROUP_EV,
    GROUP_UV,
    PHASE_INPUTS,
    CompiledCard,
    CompiledTexture,
    TextureColumns,
)
from hcard.render.options import PASSBAND_FRACTION, RenderMode, RenderOptions
from hcard.render.touch import TouchTable

MAX_RELATIVE_FRICTION = 4.0
RUN_MODE_MIN_FRAMES = 256
"""Evaluate runs of frames in time order when texture runs average at least this many frames;
below, sort the frames by texture first (fewer, larger kernel calls)."""
TWO_PI_F32 = np.float32(2.0 * np.pi)


@dataclass(frozen=True)
class FrameState:
    """Per-frame inputs of the kernel for a block of N frames.

    Attributes:
        texture: (N,) active palette index, -1 where the frame is neutral.
        phase_inputs: (N, 5) dead-reckoned x, y (mm), odometer x, y (mm), time since
            touch-down (s).
        sample: (N,) index of each frame's touch sample in ``sample_velocity``.
        sample_velocity: (M, 2) velocity estimate of each touch sample, mm/s.
        speed: (N,) magnitude of the frame's velocity, mm/s.
        uniform: every frame has the same texture (known without comparing them).
    """

    texture: np.ndarray
    phase_inputs: np.ndarray
    sample: np.ndarray
    sample_velocity: np.ndarray
    speed: np.ndarray
    uniform: bool = False


class Workspace:
    """Scratch arrays reused from block to block.

    Fresh multi-megabyte temporaries cost more in page faults than the arithmetic done in
    them; reusing these buffers makes the kernel several times faster.
    """

    def __init__(self, frames: int = 0, components: int = 0) -> None:
        self.frames = -1
        self.components = -1
        self.reserve(frames, components)

    def reserve(self, frames: int, components: int) -> None:
        """Make room for ``frames`` frames of up to ``components`` components."""
        if frames <= self.frames and components <= self.components:
            return
        self.frames = max(frames, self.frames)
        self.components = max(components, self.components, 1)
        size = self.frames * self.components
        self.inputs = np.empty((self.frames, PHASE_INPUTS))
        self.rate = np.empty((self.frames, PHASE_INPUTS))
        self.sorted_inputs = np.empty((self.frames, PHASE_INPUTS))
        self.turns = np.empty(size)
        self.rounded = np.empty(size)
        self.wave = np.empty(size, dtype=np.float32)
        self.deviation = np.empty(self.frames * 3)
        self._views: dict[tuple[str, int, int], np.ndarray] = {}

    def matrix(self, name: str, rows: int, cols: int) -> np.ndarray:
        """A (rows, cols) C-contiguous view of the flat buffer ``name`` (the same view object
        for the same request, until :meth:`reserve` makes new buffers)."""
        key = (name, rows, cols)
        view = self._views.get(key)
        if view is None:
            if len(self._views) > 64:  # blocks of many sizes (batch tails): start afresh
                self._views.clear()
            view = self._views[key] = getattr(self, name)[: rows * cols].reshape(rows, cols)
        return view

    def sample_state(
        self, table: TouchTable, options: RenderOptions
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``start``, ``rate`` (:func:`_sample_coefficients`) and speed (mm/s) of the samples
        of ``table``, kept until another table comes: a stream renders many blocks on one
        table between two touch samples."""
        cached = getattr(self, "_sample_state", None)
        if cached is not None and cached[0] is table and cached[1] is options.mode:
            return cached[2]
        start, rate = _sample_coefficients(table, options)
        speed = np.hypot(table.velocity[:, 0], table.velocity[:, 1])
        self._sample_state = (table, options.mode, (start, rate, speed))
        return start, rate, speed


def frame_state(
    card: CompiledCard,
    table: TouchTable,
    times: np.ndarray,
    options: RenderOptions,
    workspace: Workspace,
) -> FrameState:
    """Look up the touch sample, dead-reckon and find the taxtel of each frame time.

    The returned ``phase_inputs`` live in ``workspace`` until its next use.
    """
    n = times.shape[0]
    workspace.reserve(n, card.max_components)
    if len(table) == 0:
        return FrameState(
            np.full(n, -1, np.int32),
            np.zeros((n, PHASE_INPUTS)),
            np.zeros(n, dtype=np.intp),
            np.zeros((1, 2)),
            np.zeros(n),
        )
    sample = _frame_samples(table.t, times)
    i = np.maximum(sample, 0)
    # Every phase input is affine in the time since the sample: gather both coefficients once.
    start, rate, sample_speed = workspace.sample_state(table, options)
    if n and sample.item(0) == sample.item(-1):
        return _one_sample_state(card, table, times, options, workspace, sample.item(0), i,
                                 (start, rate, sample_speed))
    contact = (sample >= 0) & table.contact.take(i)
    reckon = np.minimum(times - table.t.take(i), options.dead_reckoning_s)
    # take is several times faster than fancy indexing for row gathers; with ``out`` it
    # needs mode="clip" (the indices are in range) to avoid a buffered slow path.
    inputs = start.take(i, axis=0, out=workspace.inputs[:n], mode="clip")
    travel = rate.take(i, axis=0, out=workspace.rate[:n], mode="clip")
    np.multiply(travel, reckon[:, None], out=travel)
    np.add(inputs, travel, out=inputs)
    inputs[:, 4] += times
    texture = _frame_textures(card, inputs[:, 0:2], contact)
    return FrameState(texture, inputs, i, table.velocity, sample_speed.take(i))


def _one_sample_state(
    card: CompiledCard,
    table: TouchTable,
    times: np.ndarray,
    options: RenderOptions,
    workspace: Workspace,
    sample: int,
    i: np.ndarray,
    coefficients: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> FrameState:
    """:func:`frame_state` of a block whose frames all hold touch sample ``sample`` (-1: all
    before the first one), with ``i`` its index per frame: the most common block in streaming,
    whose per-frame gathers are one row (``coefficients``: :meth:`Workspace.sample_state`). The
    numbers are those of the gathers (``a + b`` is ``b + a``)."""
    n = times.shape[0]
    row = max(sample, 0)
    start, rate, sample_speed = coefficients
    reckon = np.minimum(times - table.t.item(row), options.dead_reckoning_s)
    inputs = workspace.inputs[:n]
    np.multiply(rate[row], reckon[:, None], out=inputs)
    np.add(inputs, start[row], out=inputs)
    inputs[:, 4] += times
    index = -1  # no contact: every frame is neutral
    if sample >= 0 and table.contact.item(row):
        index = _one_taxtel(card, inputs[0, 0:2].tolist(), inputs[-1, 0:2].tolist())
        if index is None:
            texture = _frame_textures(card, inputs[:, 0:2], True)
            return FrameState(texture, inputs, i, table.velocity,
                              _filled(n, sample_speed.item(row)))
    return FrameState(_filled(n, index, np.int32), inputs, i, table.velocity,
                      _filled(n, sample_speed.item(row)), uniform=True)


def _filled(n: int, value: float, dtype: type = np.float64) -> np.ndarray:
    """``np.full(n, value, dtype)`` without its Python-level wrapper."""
    out = np.empty(n, dtype=dtype)
    out.fill(value)
    return out


def _one_taxtel(card: CompiledCard, first: list[float], last: list[float]) -> int | None:
    """The palette index of the taxtel that holds both the first and the last dead-reckoned
    position (x, y mm) of a block with one touch sample, None when they are not both on the
    card in one taxtel. With one sample the positions move monotonically along each axis
    (``start + rate min(t - t_i, H)`` rounds monotonically), and the card and each taxtel are
    intervals per axis, so then every frame of the block is in that taxtel: the numbers of
    :func:`_frame_textures`, from two points."""
    (x0, y0), (x1, y1) = first, last
    width, height = card.width_mm, card.height_mm
    if not (0 <= x0 < width and 0 <= y0 < height and 0 <= x1 < width and 0 <= y1 < height):
        return None
    column = math.floor(x0 / card.taxtel_width_mm)
    row = math.floor(y0 / card.taxtel_height_mm)
    if column != math.floor(x1 / card.taxtel_width_mm) or \
            row != math.floor(y1 / card.taxtel_height_mm):
        return None
    rows, cols = card.grid.shape
    return int(card.grid[min(max(row, 0), rows - 1), min(max(column, 0), cols - 1)])


SEARCH_MAX_FRAMES = 256
"""Blocks of at most this many frames find each frame's touch sample by binary search; longer
ones (batch rendering) by one search per sample and a repeat."""


def _frame_samples(sample_t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Index of the latest touch sample at or before each frame time (-1 before the first);
    both time arrays are sorted."""
    n = times.shape[0]
    if n <= SEARCH_MAX_FRAMES:
        return sample_t.searchsorted(times, side="right") - 1
    # Each sample owns the run of frames from the first one at or after it, so a repeat
    # replaces a per-frame binary search.
    first_frame = np.searchsorted(times, sample_t, side="left")
    run = np.diff(np.concatenate(([0], first_frame, [n])))
    return np.repeat(np.arange(-1, sample_t.shape[0]), run)


def _frame_textures(card: CompiledCard, xy: np.ndarray, contact: np.ndarray | bool) -> np.ndarray:
    """Palette index of the taxtel under each dead-reckoned position ``xy`` (N, 2) mm; -1
    without contact (per frame, or for all) or off the card."""
    inside = contact & np.logical_and.reduce((xy >= 0) & (xy < card.size_mm), axis=1)
    cell = np.divide(xy, card.taxtel_mm)
    np.floor(cell, out=cell)
    np.maximum(cell, 0.0, out=cell)  # clipped to the grid (a zero's sign goes with the cast)
    np.minimum(cell, card.last_cell, out=cell)
    flat = np.dot(cell.astype(np.intp), card.cell_strides)  # row * cols + column
    return np.where(inside, card.grid.ravel().take(flat), -1).astype(np.int32, copy=False)


def _sample_coefficients(
    table: TouchTable, options: RenderOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample ``start`` and ``rate`` (M, 6) so that a frame's phase inputs are
    ``start[i] + rate[i] * min(tau - t_i, H)`` (plus ``tau`` in column 4)."""
    m = len(table)
    start = np.empty((m, PHASE_INPUTS))
    start[:, 0:2] = table.position
    start[:, 2:4] = table.odometer
    start[:, 4] = -table.contact_start
    start[:, 5] = 1.0
    rate = np.zeros((m, PHASE_INPUTS))
    if options.mode is not RenderMode.POSITION_ONLY:
        rate[:, 0:2] = table.velocity
    rate[:, 2:4] = table.velocity
    return start, rate


def band_limit_gain(frequency_hz: np.ndarray, band_limit_hz: float) -> np.ndarray:
    """Gain of a component at ``frequency_hz``: 1 below 0.8 B, 0 from B on, smoothstep between."""
    edge = PASSBAND_FRACTION * band_limit_hz
    x = np.clip((frequency_hz - edge) / (band_limit_hz - edge), 0.0, 1.0)
    return 1.0 - x * x * (3.0 - 2.0 * x)


def _texture_deviation(
    texture: CompiledTexture,
    selected: TextureColumns,
    inputs: np.ndarray,
    velocity: Callable[[], np.ndarray],
    speed: np.ndarray,
    options: RenderOptions,
    workspace: Workspace,
    out: np.ndarray,
    phase_out: np.ndarray | None,
) -> None:
    """Write into ``out`` (n, len(columns)) the deviation from 1 in the card's channel groups
    (``selected``: the texture's arrays restricted to them) for n frames of one texture;
    ``velocity()`` gathers the frames' velocities when the band limit needs them."""
    n, c = inputs.shape[0], texture.n_components
    baseline = selected.baseline
    if c == 0:
        out[:] = baseline
        return
    turns = np.matmul(inputs, texture.phase_weights, out=workspace.matrix("turns", n, c))
    if phase_out is not None:
        phase_out[:, :c] = turns
    within = workspace.matrix("rounded", n, c)
    np.rint(turns, out=within)
    np.subtract(turns, within, out=within)  # one turn, in [-1/2, 1/2]
    wave = workspace.matrix("wave", n, c)
    np.multiply(within, 2.0 * np.pi, out=wave, casting="same_kind")
    np.cos(wave, out=wave)
    edge = PASSBAND_FRACTION * options.band_limit_hz
    fastest = float(np.maximum.reduce(speed, initial=0.0))
    if fastest * texture.max_wave_number <= edge and texture.max_temporal_hz <= edge:
        # Every component is in the passband: unit gain, exactly.
        np.add(wave @ selected.weighted_groups, baseline, out=out)
        return
    frequency = np.abs(velocity() @ texture.wave_vectors) + texture.temporal_hz
    gain = band_limit_gain(frequency, options.band_limit_hz)
    gain[:, ~texture.band_limited] = 1.0
    gain *= texture.amplitude
    np.add((wave * gain) @ selected.group_matrix, baseline, out=out)


def evaluate_frames(
    card: CompiledCard,
    state: FrameState,
    options: RenderOptions,
    workspace: Workspace,
    *,
    with_phase: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """UV and EV targets of each frame (and, on request, each component's phase in turns).

    Returns:
        ``(uv, ev, phase)``: uv in [0, 1], ev in [1, 4]; ``phase`` is (N, max components)
        unwrapped turns (NaN where a frame has no such component) or None.
    """
    n = state.texture.shape[0]
    columns = list(card.channel_groups)
    textures = state.texture
    change = None if state.uniform else (textures[1:] != textures[:-1]).nonzero()[0] + 1
    if change is None or change.size * RUN_MODE_MIN_FRAMES <= n:
        # Few texture changes: evaluate each run of frames in place, in time order.
        order = None
        inputs, speed = state.phase_inputs, state.speed
        starts = np.concatenate(([0], change)) if change is not None and change.size else (0,)
    else:
        # Many changes: sort the frames by texture so each texture is one contiguous slice.
        order = np.argsort(textures, kind="stable")
        textures = np.take(textures, order)
        starts = np.flatnonzero(np.concatenate(([True], textures[1:] != textures[:-1])))
        inputs = np.take(
            state.phase_inputs, order, axis=0, out=workspace.sorted_inputs[:n], mode="clip"
        )
        speed = np.take(state.speed, order)
    deviation = workspace.matrix("deviation", n, len(columns))
    bounds = (*(int(k) for k in starts), n)
    if len(bounds) != 2 or textures[0] < 0:  # else one texture writes every frame
        deviation.fill(0.0)
    phase = np.full((n, card.max_components), np.nan) if with_phase else None
    for start, end in itertools.pairwise(bounds):
        index = int(textures[start])
        if index < 0:
            continue
        rows = slice(start, end) if order is None else order[start:end]
        samples = state.sample[rows]
        _texture_deviation(
            card.textures[index],
            card.texture_columns[index],
            inputs[start:end],
            lambda samples=samples: np.take(state.sample_velocity, samples, axis=0),
            speed[start:end],
            options,
            workspace,
            deviation[start:end],
            None if phase is None else phase[start:end],
        )
    if order is not None:
        inverse = np.empty_like(order)
        inverse[order] = np.arange(n)
        deviation = np.take(deviation, inverse, axis=0)
        phase = None if phase is None else np.take(phase, inverse, axis=0)
    return (*split_channels(deviation, columns), phase)


def split_channels(deviation: np.ndarray, columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """UV and EV targets from the group deviations (spec rule R-split; thesis Eq. 4.1).

    ``1 + deviation`` is never -0.0, so clipping with ``maximum`` then ``minimum`` gives
    ``np.clip``'s numbers; a channel without its own group starts from exactly 1, and
    ``1 * x = x``, so the bipolar group alone sets it."""

    def group(g: int) -> np.ndarray | None:
        return 1.0 + deviation[:, columns.index(g)] if g in columns else None

    uv_group, ev_group, bipolar = group(GROUP_UV), group(GROUP_EV), group(GROUP_BIPOLAR)
    if uv_group is not None:
        uv_group = np.minimum(np.maximum(uv_group, 0.0, out=uv_group), 1.0, out=uv_group)
    if ev_group is not None:
        ev_group = np.minimum(np.maximum(ev_group, 1.0, out=ev_group), MAX_RELATIVE_FRICTION,
                              out=ev_group)
    if bipolar is None:
        ones = np.ones(deviation.shape[0])
        return (ones.copy() if uv_group is None else uv_group,
                ones if ev_group is None else ev_group)
    np.maximum(bipolar, 0.0, out=bipolar)
    np.minimum(bipolar, MAX_RELATIVE_FRICTION, out=bipolar)
    lowering, raising = np.minimum(bipolar, 1.0), np.maximum(bipolar, 1.0)
    if uv_group is None:
        uv = lowering
    else:
        uv = uv_group
        uv *= lowering
    if ev_group is None:
        ev = raising  # at most MAX_RELATIVE_FRICTION already
    else:
        ev = ev_group
        ev *= raising
        np.minimum(ev, MAX_RELATIVE_FRICTION, out=ev)
    return uv, ev
