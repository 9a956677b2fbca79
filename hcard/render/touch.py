"""Per-touch-sample state of the rendering equation (spec/README.md section 6, rule R4).

For each sample: the velocity estimate, the contact time origin and the odometer (the
velocity-locked position). Computed vectorised over a block of samples, with the state of the
previous sample carried in, so batch and streaming rendering share this code.

R4's velocity estimate is defined here once for every user: :func:`has_velocity` (which samples
have one), :func:`velocity_estimate` (the renderer's vector), :func:`speed_estimate` and
:func:`step_speed` (its magnitude, for the device's velocity compensation, the simulated finger
and the conformance suite) and :func:`segment_speeds` (the magnitude whatever the contact).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TouchTable:
    """Derived state of touch samples, arrays of length M.

    Attributes:
        t: sample time, s.
        position: (M, 2) measured position, mm.
        contact: finger on the surface.
        velocity: (M, 2) velocity estimate, mm/s (finite difference of the last two samples of
            the contact; zero at touch-down).
        odometer: (M, 2) velocity-locked position, mm.
        contact_start: time of the touch-down of the current contact, s.
        samples_in_contact: 0 at touch-down, then 1, 2, ...
    """

    t: np.ndarray
    position: np.ndarray
    contact: np.ndarray
    velocity: np.ndarray
    odometer: np.ndarray
    contact_start: np.ndarray
    samples_in_contact: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def tail(self, start: int) -> TouchTable:
        """Rows from ``start`` on."""
        return TouchTable(
            self.t[start:],
            self.position[start:],
            self.contact[start:],
            self.velocity[start:],
            self.odometer[start:],
            self.contact_start[start:],
            self.samples_in_contact[start:],
        )

    def concat(self, other: TouchTable) -> TouchTable:
        """This table followed by ``other``."""
        return TouchTable(
            *(
                np.concatenate((getattr(self, name), getattr(other, name)))
                for name in (
                    "t",
                    "position",
                    "contact",
                    "velocity",
                    "odometer",
                    "contact_start",
                    "samples_in_contact",
                )
            )
        )


def has_velocity(contact: np.ndarray, previous_contact: np.ndarray) -> np.ndarray:
    """Rule R4: the samples with a velocity estimate, those in contact that are not a
    touch-down (the previous sample was in contact too)."""
    return contact & previous_contact


def velocity_estimate(displacement: np.ndarray, dt: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """Rule R4's ``v_i = (p_i - p_(i-1)) / (t_i - t_(i-1))``, mm/s, (M, 2): ``displacement``
    (M, 2) mm and ``dt`` (M,) s from the previous sample; (0, 0) where ``moving`` (M,) is
    False."""
    velocity = np.zeros(displacement.shape)
    velocity[moving] = displacement[moving] / dt[moving, None]
    return velocity


def speed_estimate(t: np.ndarray, x: np.ndarray, y: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """``|v_i|`` of rule R4 for each of M samples (times ``t`` s, position ``x, y`` mm),
    mm/s: ``|p_i - p_(i-1)| / (t_i - t_(i-1))`` where the sample has a velocity estimate
    (:func:`has_velocity`) and the interval is positive, else 0 (always for the first)."""
    speed = np.zeros(t.shape[0])
    if t.shape[0] < 2:
        return speed
    dt = t[1:] - t[:-1]
    moving = has_velocity(contact[1:], contact[:-1]) & (dt > 0)
    distance = np.hypot(x[1:] - x[:-1], y[1:] - y[:-1])
    np.divide(distance, dt, out=speed[1:], where=moving)
    return speed


def segment_speeds(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rule R4's ``|v_i|`` (:func:`speed_estimate`) of each of M samples (times ``t`` s,
    position ``x, y`` mm) whatever the contact, mm/s: the speed of the straight segment from
    the previous sample to it, for a finger that moves between samples in contact or not (the
    simulated finger, the conformance suite's ground truth); 0 for the first sample and where
    the interval is not positive."""
    return speed_estimate(t, x, y, np.ones(t.shape[0], dtype=bool))


def step_speed(dx_mm: float, dy_mm: float, dt_s: float, moving: bool) -> float:
    """:func:`speed_estimate` of one sample, mm/s: its displacement ``(dx_mm, dy_mm)`` from
    the previous sample over ``dt_s``; 0 unless ``moving`` (:func:`has_velocity`) and
    ``dt_s > 0``."""
    if not (moving and dt_s > 0):
        return 0.0
    return float(np.hypot(dx_mm, dy_mm)) / dt_s


def empty_table() -> TouchTable:
    """A table with no samples."""
    return TouchTable(
        np.zeros(0),
        np.zeros((0, 2)),
        np.zeros(0, dtype=bool),
        np.zeros((0, 2)),
        np.zeros((0, 2)),
        np.zeros(0),
        np.zeros(0, dtype=np.int64),
    )


def extend_table(
    previous: TouchTable,
    t: np.ndarray,
    position: np.ndarray,
    contact: np.ndarray,
    horizon_s: float,
) -> TouchTable:
    """Derive the state of new samples that follow the last row of ``previous``.

    Args:
        previous: table whose last row (if any) is the sample before ``t[0]``.
        t: (M,) times, s, strictly increasing and after ``previous``.
        position: (M, 2) positions, mm.
        contact: (M,) contact flags.
        horizon_s: dead-reckoning horizon H, s.
    """
    if t.shape[0] == 1:
        return _extend_by_one(previous, t, position, contact, horizon_s)
    return _extend_block(previous, t, position, contact, horizon_s)


def _extend_block(
    previous: TouchTable,
    t: np.ndarray,
    position: np.ndarray,
    contact: np.ndarray,
    horizon_s: float,
) -> TouchTable:
    """:func:`extend_table`, vectorised over the samples."""
    m = t.shape[0]
    has_prev = len(previous) > 0
    prev_t = np.concatenate(([previous.t[-1] if has_prev else -np.inf], t[:-1]))
    prev_p = np.concatenate(
        (previous.position[-1:] if has_prev else np.zeros((1, 2)), position[:-1])
    )
    prev_c = np.concatenate(([bool(previous.contact[-1]) if has_prev else False], contact[:-1]))
    touchdown = contact & ~prev_c
    idx = np.arange(m)
    last_touchdown = np.maximum.accumulate(np.where(touchdown, idx, -1))

    carried = int(previous.samples_in_contact[-1]) + 1 if has_prev else 0
    in_contact = np.where(last_touchdown >= 0, idx - last_touchdown, carried + idx)

    moving = has_velocity(contact, prev_c)
    dt = t - prev_t
    velocity = velocity_estimate(position - prev_p, dt, moving)

    prev_start = previous.contact_start[-1] if has_prev else 0.0
    contact_start = np.where(
        last_touchdown >= 0, t[np.maximum(last_touchdown, 0)], prev_start
    )

    # Odometer: anchored to the measured position at touch-down and at the first velocity
    # estimate (the second sample of a contact); otherwise advanced by the previous velocity
    # over at most the dead-reckoning horizon.
    anchor = contact & (in_contact <= 1)
    prev_v = np.concatenate(
        (previous.velocity[-1:] if has_prev else np.zeros((1, 2)), velocity[:-1])
    )
    step = prev_v * np.minimum(dt, horizon_s)[:, None]
    step[anchor | ~contact] = 0.0
    travelled = np.cumsum(step, axis=0)
    last_anchor = np.maximum.accumulate(np.where(anchor, idx, -1))
    k = np.maximum(last_anchor, 0)
    start_odometer = previous.odometer[-1] if has_prev else np.zeros(2)
    base = np.where(
        (last_anchor >= 0)[:, None],
        position[k] - travelled[k],
        start_odometer[None, :],
    )
    odometer = base + travelled
    odometer[~contact] = position[~contact]
    velocity[~contact] = 0.0
    return TouchTable(
        t.copy(),
        position.copy(),
        contact.copy(),
        velocity,
        odometer,
        contact_start,
        in_contact,
    )


def _extend_by_one(
    previous: TouchTable,
    t: np.ndarray,
    position: np.ndarray,
    contact: np.ndarray,
    horizon_s: float,
) -> TouchTable:
    """:func:`extend_table` for one sample (a stream pushes them one at a time): the same
    operations on one element each, in floats, without the ~40 array operations of the
    vectorised form (:func:`_extend_block`); the numbers are the same (tests/render/test_renderer.py
    compares them)."""
    time, (x, y), on = float(t[0]), position[0].tolist(), bool(contact[0])
    if len(previous):
        last_t, (last_x, last_y) = float(previous.t[-1]), previous.position[-1].tolist()
        last_on = bool(previous.contact[-1])
        carried = int(previous.samples_in_contact[-1]) + 1
        last_start = float(previous.contact_start[-1])
        (last_vx, last_vy), (odo_x, odo_y) = (
            previous.velocity[-1].tolist(), previous.odometer[-1].tolist()
        )
    else:
        last_t, last_x, last_y, last_on, carried, last_start = -np.inf, 0.0, 0.0, False, 0, 0.0
        last_vx = last_vy = odo_x = odo_y = 0.0
    touchdown = on and not last_on
    in_contact = 0 if touchdown else carried
    dt = time - last_t
    vx = vy = 0.0
    if on and not touchdown:  # has_velocity: velocity_estimate of this one sample (R4)
        vx, vy = (x - last_x) / dt, (y - last_y) / dt
    start = time if touchdown else last_start
    anchor = on and in_contact <= 1
    step_x = step_y = 0.0
    if not anchor and on:  # dead reckoning over at most the horizon
        held = min(dt, horizon_s)
        step_x, step_y = last_vx * held, last_vy * held
    if anchor:
        base_x, base_y = x - step_x, y - step_y
    else:
        base_x, base_y = odo_x, odo_y
    odometer = (base_x + step_x, base_y + step_y) if on else (x, y)
    return TouchTable(
        np.array([time]),
        np.array([[x, y]]),
        np.array([on]),
        np.array([[vx, vy]]),
        np.array([odometer]),
        np.array([start]),
        np.array([in_contact], dtype=np.int64),
    )
