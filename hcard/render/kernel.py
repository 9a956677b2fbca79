"""The frame kernel: phase, band-limit gain and channel split for a block of frames.

Frames are grouped by active texture so each texture's components are evaluated as dense
(frames x components) arrays. The phase is formed in float64 turns and reduced to one turn
before the cosine, which is evaluated in float32 (error < 1e-6 relative friction, spec 6).
"""

from __future__ import annotations

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
    """

    texture: np.ndarray
    phase_inputs: np.ndarray
    sample: np.ndarray
    sample_velocity: np.ndarray
    speed: np.ndarray


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

    def matrix(self, name: str, rows: int, cols: int) -> np.ndarray:
        """A (rows, cols) C-contiguous view of the flat buffer ``name``."""
        return getattr(self, name)[: rows * cols].reshape(rows, cols)


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
    # Frame times and sample times are both sorted: each sample owns the run of frames from
    # the first one at or after it, so a repeat replaces a per-frame binary search.
    first_frame = np.searchsorted(times, table.t, side="left")
    run = np.diff(np.concatenate(([0], first_frame, [n])))
    sample = np.repeat(np.arange(-1, len(table)), run)
    has_sample = sample >= 0
    i = np.maximum(sample, 0)
    contact = has_sample & np.take(table.contact, i)
    # Every phase input is affine in the time since the sample: gather both coefficients once.
    start, rate = _sample_coefficients(table, options)
    reckon = np.minimum(times - np.take(table.t, i), options.dead_reckoning_s)
    # np.take is several times faster than fancy indexing for row gathers; with ``out`` it
    # needs mode="clip" (the indices are in range) to avoid a buffered slow path.
    inputs = np.take(start, i, axis=0, out=workspace.inputs[:n], mode="clip")
    travel = np.take(rate, i, axis=0, out=workspace.rate[:n], mode="clip")
    np.multiply(travel, reckon[:, None], out=travel)
    np.add(inputs, travel, out=inputs)
    inputs[:, 4] += times
    x, y = inputs[:, 0], inputs[:, 1]
    inside = contact & (x >= 0) & (x < card.width_mm) & (y >= 0) & (y < card.height_mm)
    rows, cols = card.grid.shape
    col = np.clip(np.floor(x / card.taxtel_width_mm), 0, cols - 1).astype(np.intp)
    row = np.clip(np.floor(y / card.taxtel_height_mm), 0, rows - 1).astype(np.intp)
    texture = np.where(inside, np.take(card.grid.ravel(), row * cols + col), -1).astype(np.int32)
    speed = np.take(np.hypot(table.velocity[:, 0], table.velocity[:, 1]), i)
    return FrameState(texture, inputs, i, table.velocity, speed)


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
    columns: list[int],
    inputs: np.ndarray,
    velocity: Callable[[], np.ndarray],
    speed: np.ndarray,
    options: RenderOptions,
    workspace: Workspace,
    out: np.ndarray,
    phase_out: np.ndarray | None,
) -> None:
    """Write into ``out`` (n, len(columns)) the deviation from 1 in the given channel groups
    for n frames of one texture; ``velocity()`` gathers the frames' velocities when the band
    limit needs them."""
    n, c = inputs.shape[0], texture.n_components
    baseline = texture.baseline_deviation[columns]
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
    fastest = float(np.max(speed, initial=0.0))
    if fastest * texture.max_wave_number <= edge and texture.max_temporal_hz <= edge:
        # Every component is in the passband: unit gain, exactly.
        np.add(wave @ texture.weighted_groups[:, columns], baseline, out=out)
        return
    frequency = np.abs(velocity() @ texture.wave_vectors) + texture.temporal_hz
    gain = band_limit_gain(frequency, options.band_limit_hz)
    gain[:, ~texture.band_limited] = 1.0
    gain *= texture.amplitude
    np.add((wave * gain) @ texture.group_matrix[:, columns], baseline, out=out)


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
    change = np.flatnonzero(np.diff(state.texture)) + 1
    if change.size * RUN_MODE_MIN_FRAMES <= n:
        # Few texture changes: evaluate each run of frames in place, in time order.
        order = None
        inputs, speed, textures = state.phase_inputs, state.speed, state.texture
        starts = np.concatenate(([0], change))
    else:
        # Many changes: sort the frames by texture so each texture is one contiguous slice.
        order = np.argsort(state.texture, kind="stable")
        textures = np.take(state.texture, order)
        starts = np.flatnonzero(np.diff(textures, prepend=-2))
        inputs = np.take(
            state.phase_inputs, order, axis=0, out=workspace.sorted_inputs[:n], mode="clip"
        )
        speed = np.take(state.speed, order)
    ends = np.append(starts[1:], n)
    deviation = workspace.matrix("deviation", n, len(columns))
    deviation.fill(0.0)
    phase = np.full((n, card.max_components), np.nan) if with_phase else None
    for start, end in zip(starts, ends, strict=True):
        index = int(textures[start])
        if index < 0:
            continue
        rows = slice(start, end) if order is None else order[start:end]
        samples = state.sample[rows]
        _texture_deviation(
            card.textures[index],
            columns,
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
    """UV and EV targets from the group deviations (spec rule R-split; thesis Eq. 4.1)."""
    ones = np.ones(deviation.shape[0])

    def group(g: int) -> np.ndarray | None:
        return 1.0 + deviation[:, columns.index(g)] if g in columns else None

    uv_group, ev_group, bipolar = group(GROUP_UV), group(GROUP_EV), group(GROUP_BIPOLAR)
    uv = ones.copy() if uv_group is None else np.clip(uv_group, 0.0, 1.0)
    ev = ones.copy() if ev_group is None else np.clip(ev_group, 1.0, MAX_RELATIVE_FRICTION)
    if bipolar is not None:
        np.clip(bipolar, 0.0, MAX_RELATIVE_FRICTION, out=bipolar)
        uv *= np.minimum(bipolar, 1.0)
        ev *= np.maximum(bipolar, 1.0)
        np.minimum(ev, MAX_RELATIVE_FRICTION, out=ev)
    return uv, ev
