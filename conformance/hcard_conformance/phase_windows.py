"""Where A1 leaves the phase of a texture free (spec/conformance.md 3.2, rule A1 phase).

A velocity-locked grating (README R8) and a temporal vibration have no place on the surface:
their phase starts where the finger touched down and integrates its velocity (R4, R9), so an
error far below every perceptual threshold (a touch sensor 0.1 % off in scale, a grating
turned 0.07 degrees) moves their phase without bound along a stroke. A1 judges their level,
amplitude and waveform, not where their cycles fall: the compared frames of such a texture are
cut into **phase windows**, each one cycle of the texture's fastest playing component long (at
least :data:`MIN_WINDOW_S`), and each window may shift by up to half the period of its slowest
playing component against the lag of the rest.
Position-locked textures keep one lag for the whole render (their place is A4's to judge, and
A1's too).

This module only finds the windows and their allowances from the card, the track and the golden
render; :func:`hcard_conformance.metrics.relative_error` uses them.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from hcard.render import RenderOptions
from hcard.render.compiled import velocity_locked
from hcard.render.touch import velocity_estimate
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb

MIN_WINDOW_S = 0.002
"""Shortest phase window, s: the rise-time JND (spec D2, thesis 5.2.2), the finest time scale at
which the finger tells two friction signals apart."""
WINDOW_CYCLES = 1.0
"""Cycles of the fastest playing component a phase window holds: within a cycle the waveform
must match (an amplitude or shape error cannot hide in a shift), while a frequency error of
A3's 5 % drifts only a twentieth of a cycle."""
MIN_COMPONENT_HZ = 10.0
"""Slowest temporal frequency that counts as a vibration, Hz: a component slower than this
(a grating nearly across the stroke) barely changes within a window, so it sets no allowance."""


@dataclass(frozen=True)
class PhaseWindows:
    """Phase windows over the golden frames.

    Attributes:
        window: per golden frame, the index of its phase window, -1 for frames whose phase is
            fixed (position-locked textures, no finger speed, out of contact).
        half_width: per window, the largest shift allowed against the global lag, frames.
    """

    window: np.ndarray
    half_width: np.ndarray


def phase_free_textures(card: pb.Card, options: RenderOptions) -> set[int]:
    """Palette indices of textures whose every component is temporal or resolves to VELOCITY
    (R8), and which have at least one component."""
    out = set()
    for index, texture in enumerate(card.textures):
        components = list(texture.components)
        if components and all(c.domain == pb.DOMAIN_TEMPORAL
                              or velocity_locked(c, texture.locking, options)
                              for c in components):
            out.add(index)
    return out


def sample_velocities(track: FingerTrack) -> np.ndarray:
    """R4's velocity estimate of each sample (:func:`hcard.render.touch.velocity_estimate`),
    mm/s, shape (M, 2), whatever the contact (a sample after a lift takes its own finite
    difference, which no frame in contact uses before the next sample); the first takes the
    second's."""
    t, x, y = (np.asarray(a, dtype=float) for a in (track.t, track.x, track.y))
    v = np.zeros((len(t), 2))
    if len(t) >= 2:
        dt = np.diff(t)
        v[1:] = velocity_estimate(np.column_stack((np.diff(x), np.diff(y))), dt, dt > 0)
        v[0] = v[1]
    return v


def playing_frequencies_hz(texture: pb.Texture, velocity: np.ndarray,
                           band_limit_hz: float) -> list[float]:
    """The temporal frequencies (R10's ``F_c``, Hz) of the components of ``texture`` that play
    at ``velocity`` (mm/s): at least :data:`MIN_COMPONENT_HZ` and under the band limit."""
    found = []
    for c in texture.components:
        if c.domain == pb.DOMAIN_TEMPORAL:
            f = c.frequency
        else:
            n = (math.cos(c.orientation), math.sin(c.orientation))
            f = c.frequency * abs(n[0] * velocity[0] + n[1] * velocity[1])
        if MIN_COMPONENT_HZ <= f < band_limit_hz:
            found.append(f)
    return found


def phase_windows(golden_t: np.ndarray, golden_texture: np.ndarray, compared: np.ndarray,
                  card: pb.Card, track: FingerTrack, options: RenderOptions,
                  max_shift_s: float) -> PhaseWindows:
    """The phase windows of a render: runs of compared frames (``compared``, A-sel) playing one
    phase-free texture, each cut into windows of ``max(MIN_WINDOW_S, WINDOW_CYCLES / F_max)``
    allowed ``min(1 / (2 F_min), max_shift_s)`` of shift, where ``F_max``, ``F_min`` are the
    fastest and slowest playing frequencies at the finger velocity of the window's first frame;
    frames where no component plays (no speed, or every component faded) keep the global
    lag."""
    fs = 1.0 / float(np.median(np.diff(golden_t))) if len(golden_t) > 1 else 1.0
    free = phase_free_textures(card, options)
    velocities = sample_velocities(track)
    sample_of = np.clip(np.searchsorted(np.asarray(track.t, float), golden_t, side="right") - 1,
                        0, len(track) - 1)
    window = np.full(len(golden_t), -1, dtype=int)
    half_widths: list[int] = []
    texture = np.asarray(golden_texture, dtype=int)
    free_frames = compared & np.isin(texture, sorted(free))
    edges = np.flatnonzero(np.diff(np.concatenate(([0], free_frames.astype(np.int8), [0]))))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        cuts = np.flatnonzero(np.diff(texture[start:stop]) != 0) + start + 1
        bounds = [start, *cuts.tolist(), stop]
        for a, b in itertools.pairwise(bounds):
            first = a
            while first < b:
                playing = playing_frequencies_hz(card.textures[int(texture[first])],
                                                 velocities[sample_of[first]],
                                                 options.band_limit_hz)
                if not playing:
                    first += max(round(MIN_WINDOW_S * fs), 1)
                    continue
                length = max(round(max(MIN_WINDOW_S, WINDOW_CYCLES / max(playing)) * fs), 1)
                window[first:min(first + length, b)] = len(half_widths)
                half_widths.append(round(min(0.5 / min(playing), max_shift_s) * fs))
                first += length
    return PhaseWindows(window, np.asarray(half_widths, dtype=int))

