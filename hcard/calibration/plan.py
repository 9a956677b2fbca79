"""The calibration protocol: a card and a finger track that identify a device's models, and the
held-out textures that verify a fitted profile (spec/calibration.md section 6).

The protocol follows the thesis's own measurements: strokes at several speeds and normal forces
(the friction of the bare finger, Figs. 1.11-1.12, Eq. 2.35; the ultrasonic reduction against
the dimensionless group, Figs. 2.21-2.24, Eqs. 2.30-2.33), an amplitude staircase (Fig. 2.24),
voltage steps and a square wave (Figs. 3.11-3.13: the force against the voltage and its history)
and rests with the finger lifted (the force sensor's zero, spec/calibration.md K4). It is a card
in the device-independent unit (relative friction), played through the device's own profile:
the recording carries the amplitude and voltage the device measured, so the targets only have
to spread those over the device's range.

**The protocol card** (:func:`protocol_card`) is an ``80 x 50`` mm surface (it fits the E-ViTa's
81 x 54 mm and the coupled stimulator's 80 x 50 mm) of five lanes along x, each 10 mm tall and
cut into 5 mm taxtels (a stroke at 100 mm/s crosses one every 50 ms):

============  ====================================================================  ==========
lane          targets along x (relative friction)                                   devices
============  ====================================================================  ==========
uv-staircase  1, then 0.92 down to 0.05 in 12 steps, then plain                      uv, coupled
uv-steps      plain patches between UV levels 0.3, 0.6, 0.15, ... (steps both ways)  uv, coupled
ev-staircase  1, then 1.02 up to 2.0 in 12 steps (the voltage climbs to its limit)   ev, coupled
ev-square     1 and 1.6 alternating: voltage steps, a square wave in time            ev, coupled
bipolar       plain patches between UV levels and EV levels (one channel at a time)   coupled
============  ====================================================================  ==========

**The protocol track** (:func:`protocol_track`) visits the device's lanes in turn, a *session*
each: the finger lands at x = 1 mm, strokes to x = 79 mm and back at two of the speeds
:data:`SPEEDS_MM_S` under one of the forces :data:`FORCES_N`, lifts (:data:`SHORT_LIFT_S` after
the first session of each pair, a rest of :data:`REST_S` after the second) and
moves to the next lane; the (force, speed) combinations cycle so that every lane meets every
force and speed. Samples at :data:`TRACK_RATE_HZ` (a touch controller's report rate).

**The verification card and track** (:func:`verification_card`, :func:`verification_track`)
hold out what the protocol does not contain: other target levels (UV 0.85 ... 0.4, EV 1.03 ...
1.09), other forces (:data:`VERIFY_FORCES_N`) and speeds (:data:`VERIFY_SPEEDS_MM_S`), on 10 mm
taxtels with a plain patch between every two textures, so that the rendered friction can be
measured against the finger's natural friction next to it
(:func:`hcard.calibration.rendering.rendering_error`). The EV levels stay within what the
coupled stimulator can render at those forces (a 2 kV amplifier gives at most about 1.19 at
0.6 N, Eq. 3.12 with the section 3.6.1 contact).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import hcard.build as build
from hcard.errors import UsageError
from hcard.track import FingerTrack, make_track
from hcard.v1 import card_pb2 as pb

DEVICE_CLASSES = ("uv", "ev", "coupled")
"""What a device can render: UV only (the E-ViTa), EV only (the coupled stimulator with its
plate off), or both."""

SURFACE_MM = (80.0, 50.0)
"""The plan's surface, mm: it fits both reference devices."""
LANE_MM = 10.0
"""Height of a lane, mm."""
PROTOCOL_TAXTEL_MM = 5.0
"""Width of a protocol taxtel along x, mm."""
VERIFY_TAXTEL_MM = 10.0
"""Width of a verification taxtel along x, mm (a longer patch averages more reports)."""
STROKE_X_MM = (1.0, 79.0)
"""Where strokes start and end along x, mm."""

PLAIN = 1.0
UV_STAIRCASE = (PLAIN, 0.92, 0.84, 0.76, 0.68, 0.6, 0.52, 0.44, 0.36, 0.28, 0.2, 0.12, 0.05,
                PLAIN, PLAIN, PLAIN)
UV_STEPS = (PLAIN, 0.3, PLAIN, 0.6, PLAIN, 0.15, PLAIN, 0.45, PLAIN, 0.75, PLAIN, 0.25,
            PLAIN, 0.55, PLAIN, PLAIN)
EV_STAIRCASE = (PLAIN, 1.02, 1.04, 1.07, 1.1, 1.14, 1.18, 1.23, 1.3, 1.4, 1.55, 1.75, 2.0,
                PLAIN, PLAIN, PLAIN)
EV_SQUARE = (PLAIN, 1.6) * 8
BIPOLAR = (PLAIN, 0.5, PLAIN, 1.3, PLAIN, 0.8, PLAIN, 1.1, PLAIN, 0.35, PLAIN, 1.6, PLAIN,
           0.65, PLAIN, PLAIN)
PROTOCOL_LANES: dict[str, tuple[tuple[float, ...], str, tuple[str, ...]]] = {
    "uv-staircase": (UV_STAIRCASE, "uv", ("uv", "coupled")),
    "uv-steps": (UV_STEPS, "uv", ("uv", "coupled")),
    "ev-staircase": (EV_STAIRCASE, "ev", ("ev", "coupled")),
    "ev-square": (EV_SQUARE, "ev", ("ev", "coupled")),
    "bipolar": (BIPOLAR, "bipolar", ("coupled",)),
}
"""Lane name -> (targets along x, channel, device classes that play it), top to bottom."""

VERIFY_UV = (PLAIN, 0.85, PLAIN, 0.7, PLAIN, 0.48, PLAIN, 0.4)
VERIFY_UV_2 = (PLAIN, 0.57, PLAIN, 0.78, PLAIN, 0.62, PLAIN, PLAIN)
VERIFY_EV = (PLAIN, 1.03, PLAIN, 1.05, PLAIN, 1.08, PLAIN, 1.09)
VERIFY_EV_2 = (PLAIN, 1.06, PLAIN, 1.035, PLAIN, 1.065, PLAIN, PLAIN)
VERIFY_LANES: dict[str, tuple[tuple[float, ...], str, tuple[str, ...]]] = {
    "uv-held-out": (VERIFY_UV, "uv", ("uv", "coupled")),
    "uv-held-out-2": (VERIFY_UV_2, "uv", ("uv", "coupled")),
    "ev-held-out": (VERIFY_EV, "ev", ("ev", "coupled")),
    "ev-held-out-2": (VERIFY_EV_2, "ev", ("ev", "coupled")),
}
"""The verification card's lanes (held-out levels, a plain patch between every two)."""

FORCES_N = (0.15, 0.35, 0.7, 1.5)
"""Normal forces of the protocol's sessions, N: a light touch, where the electrostatic force is
largest against the load and an air layer or a finger's flattening shows most (Eqs. 3.17-3.18),
to a firm one, where an air layer is pressed out while a pad still flattens (the two differ
most across the whole range; the thesis's EV measurements span 0.1-2 N) and the load index
shows (Eq. 2.35)."""
SPEEDS_MM_S = (25.0, 50.0, 100.0, 150.0)
"""Stroke speeds of the protocol, mm/s (within the 10-150 mm/s exploration range, Fig. 1.12)."""
VERIFY_FORCES_N = (0.4, 0.6)
"""Normal forces of the verification, N (held out of :data:`FORCES_N`)."""
VERIFY_SPEEDS_MM_S = (40.0, 70.0)
"""Stroke speeds of the verification, mm/s (held out of :data:`SPEEDS_MM_S`)."""
REST_S = 0.6
"""Rest with the finger lifted after every second session, s: longer than the pause that rests
the finger for the calibration (``hcard.calibration.dataset.REST_S``, 0.5 s), so the count of
strokes since a rest (skin recovery, Figs. 2.25-2.26) restarts."""
SHORT_LIFT_S = 0.2
"""Lift between the two sessions of a pair, s: the sensor's zero (K4) without resting the
finger, so the second session's strokes are the 3rd and 4th since the rest. With one pair of
strokes per rest the protocol showed only strokes 0 and 1, which fix the ratio of the first two
strokes' friction, not the depth and the recovery of skin recovery apart (a hidden depth 0.2
over 2 strokes came back 0.27 over 3.3, z 12 and 9)."""
TRACK_RATE_HZ = 100.0
"""Finger samples per second."""
DEFAULT_DURATION_S = 60.0
"""Default length of the protocol track, s."""
DEFAULT_VERIFY_DURATION_S = 24.0
"""Default length of the verification track, s."""


class PlanError(UsageError):
    """A plan that cannot be made (unknown device class, a duration too short)."""


@dataclass(frozen=True)
class Plan:
    """A card and the finger track that plays it.

    Attributes:
        card: the card.
        track: the finger track (mm, s, N).
        lanes: the lanes in the card, top to bottom.
        sessions: (lane, force N, speeds mm/s) of each session of the track.
    """

    card: pb.Card
    track: FingerTrack
    lanes: tuple[str, ...]
    sessions: tuple[tuple[str, float, tuple[float, float]], ...]


def _check_device(device: str) -> None:
    if device not in DEVICE_CLASSES:
        raise PlanError(f"unknown device class {device!r}; classes: {', '.join(DEVICE_CLASSES)}")


def lane_card(lanes: Sequence[tuple[str, tuple[float, ...], str]], taxtel_mm: float,
               title: str, description: str) -> pb.Card:
    """A card whose rows are ``lanes`` (name, targets along x, channel); one texture per
    (channel, level), named ``"<channel> <level>"``; rows past the lanes are plain."""
    width, height = SURFACE_MM
    cols = round(width / taxtel_mm)
    rows = round(height / LANE_MM)
    textures: list[pb.Texture] = [build.texture(PLAIN, channel="bipolar", name="plain")]
    palette = {("plain", PLAIN): 0}
    index = np.zeros((rows, cols), dtype=np.int64)
    for row, (_name, targets, channel) in enumerate(lanes):
        if len(targets) != cols:
            raise PlanError(f"a lane has {len(targets)} targets for {cols} taxtels")
        for col, level in enumerate(targets):
            lane_channel = channel
            if channel == "bipolar":
                lane_channel = "uv" if level < PLAIN else "ev"
            key = ("plain", PLAIN) if level == PLAIN else (lane_channel, float(level))
            if key not in palette:
                palette[key] = len(textures)
                textures.append(build.texture(float(level), channel=lane_channel,
                                              name=f"{lane_channel} {level:g}"))
            index[row, col] = palette[key]
    return build.card(width, height, taxtel_mm=(taxtel_mm, LANE_MM), textures=textures,
                      texture_index=index, title=title, description=description)


def _lanes(table: dict[str, tuple[tuple[float, ...], str, tuple[str, ...]]],
           device: str) -> list[tuple[str, tuple[float, ...], str]]:
    return [(name, targets, channel) for name, (targets, channel, devices) in table.items()
            if device in devices]


def protocol_card(device: str) -> pb.Card:
    """The protocol card of a device class (module docstring)."""
    _check_device(device)
    return lane_card(_lanes(PROTOCOL_LANES, device), PROTOCOL_TAXTEL_MM,
                      f"hcard calibration protocol ({device})",
                      "Lanes of target levels for strokes along x (spec/calibration.md 6).")


def verification_card(device: str) -> pb.Card:
    """The held-out textures of a device class (module docstring)."""
    _check_device(device)
    return lane_card(_lanes(VERIFY_LANES, device), VERIFY_TAXTEL_MM,
                      f"hcard calibration verification ({device})",
                      "Held-out levels between plain patches (spec/calibration.md 6).")


def session_track(
    sessions: Sequence[tuple[int, float, tuple[float, float]]],
    rate_hz: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Samples of the sessions (lane row, force N, two speeds mm/s): land, stroke there and
    back, lift (:func:`lift_after`: a short lift inside a pair, a rest after it); the finger
    moves to the next lane while lifted."""
    x0, x1 = STROKE_X_MM
    dt = 1.0 / rate_hz
    t_parts: list[np.ndarray] = []
    x_parts: list[np.ndarray] = []
    y_parts: list[np.ndarray] = []
    f_parts: list[np.ndarray] = []
    c_parts: list[np.ndarray] = []
    now = 0.0
    for index, (row, force, (there, back)) in enumerate(sessions):
        y = (row + 0.5) * LANE_MM
        for start, end, speed in ((x0, x1, there), (x1, x0, back)):
            steps = max(math.ceil(abs(end - start) / speed * rate_hz), 2)
            x = np.linspace(start, end, steps + 1)
            if t_parts and c_parts[-1][-1]:  # continue the contact: skip the repeated point
                x = x[1:]
            t = now + np.arange(x.size) * dt
            t_parts.append(t)
            x_parts.append(x)
            y_parts.append(np.full(x.size, y))
            f_parts.append(np.full(x.size, force))
            c_parts.append(np.ones(x.size, dtype=bool))
            now = t[-1] + dt
        rest = np.arange(max(round(lift_after(index) * rate_hz), 1))
        t_parts.append(now + rest * dt)
        x_parts.append(np.full(rest.size, x0))
        y_parts.append(np.full(rest.size, y))
        f_parts.append(np.zeros(rest.size))
        c_parts.append(np.zeros(rest.size, dtype=bool))
        now = t_parts[-1][-1] + dt
    return tuple(np.concatenate(p) for p in (t_parts, x_parts, y_parts, f_parts, c_parts))  # type: ignore[return-value]


def lift_after(session: int) -> float:
    """How long the finger is lifted after the ``session``-th session (from 0), s: a short lift
    inside a pair of sessions, a rest after it (:data:`SHORT_LIFT_S`, :data:`REST_S`)."""
    return SHORT_LIFT_S if session % 2 == 0 else REST_S


def _sessions(rows: Sequence[int], forces: Sequence[float], speeds: Sequence[float],
              duration_s: float, rng: np.random.Generator
              ) -> list[tuple[int, float, tuple[float, float]]]:
    """Sessions until ``duration_s``: lanes in turn; every run of ``len(forces)`` sessions
    holds each force once, in an order drawn from ``rng`` per run (so that even a short
    protocol spans the loads, which the EV effects need); the speed pairs (each speed and the
    next) cycle, shifted by one every run, so that lanes, forces and speeds all meet."""
    pairs = [(speeds[i], speeds[(i + 1) % len(speeds)]) for i in range(len(speeds))]
    sessions: list[tuple[int, float, tuple[float, float]]] = []
    elapsed = 0.0
    length = STROKE_X_MM[1] - STROKE_X_MM[0]
    k = 0
    order: list[float] = []
    while elapsed < duration_s:
        if not order:
            order = [forces[i] for i in rng.permutation(len(forces))]
        force = order.pop()
        pair = pairs[(k + k // len(forces)) % len(pairs)]
        sessions.append((rows[k % len(rows)], force, pair))
        elapsed += length / pair[0] + length / pair[1] + lift_after(k)
        k += 1
    return sessions


def _plan(card: pb.Card, lanes: list[tuple[str, tuple[float, ...], str]],
          forces: Sequence[float], speeds: Sequence[float], duration_s: float, seed: int,
          rate_hz: float) -> Plan:
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise PlanError(f"the duration must be a number of seconds > 0, got {duration_s}")
    if not (math.isfinite(rate_hz) and rate_hz >= 10):
        raise PlanError(f"the track rate must be at least 10 Hz, got {rate_hz}")
    rng = np.random.default_rng(seed)
    chosen = _sessions(list(range(len(lanes))), forces, speeds, duration_s, rng)
    t, x, y, fn, contact = session_track(chosen, rate_hz)
    track = make_track(t, x, y, fn, contact, source="calibration plan")
    sessions = tuple((lanes[row][0], force, pair) for row, force, pair in chosen)
    return Plan(card, track, tuple(name for name, _, _ in lanes), sessions)


def protocol(device: str, *, duration_s: float = DEFAULT_DURATION_S, seed: int = 0,
             rate_hz: float = TRACK_RATE_HZ) -> Plan:
    """The protocol card and track of a device class, about ``duration_s`` long (the last
    session is played to its end).

    Raises:
        PlanError: an unknown device class, a duration or rate that is not positive.
    """
    _check_device(device)
    return _plan(protocol_card(device), _lanes(PROTOCOL_LANES, device), FORCES_N, SPEEDS_MM_S,
                 duration_s, seed, rate_hz)


def verification(device: str, *, duration_s: float = DEFAULT_VERIFY_DURATION_S, seed: int = 1,
                 rate_hz: float = TRACK_RATE_HZ) -> Plan:
    """The verification card and track of a device class (held-out levels, forces, speeds).

    Raises:
        PlanError: an unknown device class, a duration or rate that is not positive.
    """
    _check_device(device)
    return _plan(verification_card(device), _lanes(VERIFY_LANES, device), VERIFY_FORCES_N,
                 VERIFY_SPEEDS_MM_S, duration_s, seed, rate_hz)
