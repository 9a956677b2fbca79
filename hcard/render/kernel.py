"""The frame kernel: phase, band-limit gain and channel split for a block of frames.

Frames are grouped by active texture so each texture's components are evaluated as dense
(frames x components) arrays. The phase is formed in float64 turns and reduced to one turn
before the cosine, which is evaluated in float32 (error < 1e-6 relative friction, spec 6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcard.render.compiled import PHASE_INPUTS, CompiledCard, CompiledTexture
from hcard.render.options import PASSBAND_FRACTION, RenderMode, RenderOptions
from hcard.render.touch import TouchTable

MAX_RELATIVE_FRICTION = 4.0
TWO_PI_F32 = np.float32(2.0 * np.pi)


@dataclass(frozen=True)
class FrameState:
    """Per-frame inputs of the kernel for a block of N frames.

    Attributes:
        texture: (N,) active palette index, -1 where the frame is neutral.
        phase_inputs: (N, 5) dead-reckoned x, y (mm), odometer x, y (mm), time since
            touch-down (s).
        velocity: (N, 2) velocity estimate, mm/s.
        speed: (N,) magnitude of ``velocity``, mm/s.
    """

    texture: np.ndarray
    phase_inputs: np.ndarray
    velocity: np.ndarray
    speed: np.ndarray


def frame_state(
    card: CompiledCard, table: TouchTable, times: np.ndarray, options: RenderOptions
) -> FrameState:
    """Look up the touch sample, dead-reckon and find the taxtel of each frame time."""
    n = times.shape[0]
    if len(table) == 0:
        return FrameState(
            np.full(n, -1, np.int32), np.zeros((n, PHASE_INPUTS)), np.zeros((n, 2)), np.zeros(n)
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
    # np.take is several times faster than fancy indexing for row gathers.
    inputs = np.take(start, i, axis=0)
    sample_rate = np.take(rate, i, axis=0)
    inputs += sample_rate * reckon[:, None]
    inputs[:, 4] += times
    velocity = sample_rate[:, 2:4]
    x, y = inputs[:, 0], inputs[:, 1]
    inside = contact & (x >= 0) & (x < card.width_mm) & (y >= 0) & (y < card.height_mm)
    rows, cols = card.grid.shape
    col = np.clip(np.floor(x / card.taxtel_width_mm), 0, cols - 1).astype(np.intp)
    row = np.clip(np.floor(y / card.taxtel_height_mm), 0, rows - 1).astype(np.intp)
    texture = np.where(inside, np.take(card.grid.ravel(), row * cols + col), -1).astype(np.int32)
    speed = np.take(np.hypot(table.velocity[:, 0], table.velocity[:, 1]), i)
    return FrameState(texture, inputs, velocity, speed)


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
    inputs: np.ndarray,
    velocity: np.ndarray,
    speed: np.ndarray,
    options: RenderOptions,
    phase_out: np.ndarray | None,
) -> np.ndarray:
    """(n, 3) deviation from 1 per channel group for n frames of one texture."""
    n = inputs.shape[0]
    if texture.n_components == 0:
        return np.broadcast_to(texture.baseline_deviation, (n, 3))
    turns = inputs @ texture.phase_weights
    if phase_out is not None:
        phase_out[:, : texture.n_components] = turns
    wave = (turns - np.rint(turns)).astype(np.float32)  # one turn, in [-1/2, 1/2]
    wave *= TWO_PI_F32
    np.cos(wave, out=wave)
    edge = PASSBAND_FRACTION * options.band_limit_hz
    fastest = float(np.max(speed, initial=0.0))
    if fastest * texture.max_wave_number <= edge and texture.max_temporal_hz <= edge:
        # Every component is in the passband: unit gain, exactly.
        return wave @ texture.weighted_groups + texture.baseline_deviation
    frequency = np.abs(velocity @ texture.wave_vectors) + texture.temporal_hz
    gain = band_limit_gain(frequency, options.band_limit_hz)
    gain[:, ~texture.band_limited] = 1.0
    gain *= texture.amplitude
    return (wave * gain) @ texture.group_matrix + texture.baseline_deviation


def evaluate_frames(
    card: CompiledCard,
    state: FrameState,
    options: RenderOptions,
    *,
    with_phase: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """UV and EV targets of each frame (and, on request, each component's phase in turns).

    Returns:
        ``(uv, ev, phase)``: uv in [0, 1], ev in [1, 4]; ``phase`` is (N, max components)
        unwrapped turns (NaN where a frame has no such component) or None.
    """
    n = state.texture.shape[0]
    order = np.argsort(state.texture, kind="stable")
    sorted_textures = np.take(state.texture, order)
    starts = np.flatnonzero(np.diff(sorted_textures, prepend=-2))
    ends = np.append(starts[1:], n)
    inputs = np.take(state.phase_inputs, order, axis=0)
    velocity = np.take(state.velocity, order, axis=0)
    speed = np.take(state.speed, order)
    # Work in texture-sorted order, where each texture's frames are one contiguous slice.
    deviation_sorted = np.zeros((n, 3))
    phase_sorted = np.full((n, card.max_components), np.nan) if with_phase else None
    for start, end in zip(starts, ends, strict=True):
        index = int(sorted_textures[start])
        if index < 0:
            continue
        deviation_sorted[start:end] = _texture_deviation(
            card.textures[index],
            inputs[start:end],
            velocity[start:end],
            speed[start:end],
            options,
            None if phase_sorted is None else phase_sorted[start:end],
        )
    inverse = np.empty_like(order)
    inverse[order] = np.arange(n)
    deviation = np.take(deviation_sorted, inverse, axis=0)
    phase = None if phase_sorted is None else np.take(phase_sorted, inverse, axis=0)
    uv = np.clip(1.0 + deviation[:, 0], 0.0, 1.0)
    ev = np.clip(1.0 + deviation[:, 1], 1.0, MAX_RELATIVE_FRICTION)
    bipolar = np.clip(1.0 + deviation[:, 2], 0.0, MAX_RELATIVE_FRICTION)
    uv *= np.minimum(bipolar, 1.0)
    ev *= np.maximum(bipolar, 1.0)
    np.minimum(ev, MAX_RELATIVE_FRICTION, out=ev)
    return uv, ev, phase
