"""Time series of a recording, for effects and regressors: first-order filters, touch-downs,
and two regressors of the calibration.

The filters (:func:`high_pass`, :func:`low_pass`, restarted at :func:`touchdowns`) serve
effects whose form is a response in time (charge leakage, skin recovery: Eq. 3.22); the
regressors ``voltage_history`` (:func:`time_since_change`) and ``amplitude_history``
(:func:`recent_change`) are columns of the calibration's dataset (:mod:`hcard.calibration.
dataset`; the regressor names: :mod:`hcard.physics.effects`). Time must increase strictly from
sample to sample, except that a decrease starts a new recording (several recordings
concatenated, each with its own time origin).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from hcard.physics.predictor import PredictorError


def _series(x: Any, t: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(x, t)`` as 1-D arrays of one length, or None when ``t`` gives no time axis
    (a scalar or constant time: the steady state).

    Time must increase strictly, except that a decrease starts a new recording (several
    recordings concatenated, each with its own time origin)."""
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(t, float))
    if x_arr.ndim == 0 or t_arr.size < 2 or np.ptp(t_arr) == 0:
        return None
    if x_arr.ndim != 1:
        raise PredictorError(f"a time series must be 1-D, got shape {x_arr.shape}")
    if np.any(np.diff(t_arr) == 0):
        raise PredictorError("time must increase strictly from sample to sample (repeated time)")
    return x_arr, t_arr


def _segments(t: np.ndarray, restart: np.ndarray | None = None) -> list[slice]:
    """The runs of increasing time in ``t`` (one per concatenated recording), split again at
    every sample where ``restart`` (boolean, aligned with ``t``) is true."""
    cuts = np.diff(t) < 0
    if restart is not None:
        cuts = cuts | restart[1:]
    starts = [0, *(np.flatnonzero(cuts) + 1).tolist(), t.size]
    return [slice(a, b) for a, b in itertools.pairwise(starts)]


def _restart_mask(restart: Any, size: int) -> np.ndarray | None:
    """``restart`` as a boolean array of ``size`` samples (None: no restarts)."""
    if restart is None:
        return None
    mask = np.asarray(restart)
    if mask.ndim == 0:
        return None
    if mask.shape != (size,):
        raise PredictorError(
            f"restart must be one flag per sample ({size}), got shape {mask.shape}"
        )
    return mask.astype(bool)


def touchdowns(contact: Any, t: Any = None) -> np.ndarray | None:
    """Where the finger touches down: a boolean array, true at the first sample of every
    contact, from the ``contact`` input (1 while the finger touches the surface, 0 out of
    contact). A contact starts where ``contact`` turns on after a sample off, at the first
    sample if it is on, and where time ``t`` (s) decreases (a new recording). A new stroke
    without a lift between (a reversal, the finger still on the surface) is no touch-down.
    None when ``contact`` is one number (no contact column: one contact throughout)."""
    on = np.asarray(contact, dtype=np.float64)
    if on.ndim == 0:
        return None
    if on.ndim != 1:
        raise PredictorError(f"contact must be one flag per sample (1-D), got shape {on.shape}")
    if np.any(np.isnan(on)):
        raise PredictorError("contact must not be NaN (1 in contact, 0 out of contact)")
    touching = on > 0.5
    start = np.zeros(on.size, dtype=bool)
    if on.size:
        start[0] = touching[0]
        start[1:] = touching[1:] & ~touching[:-1]
    if t is not None and np.ndim(t) == 1 and np.size(t) == on.size:
        start[1:] |= touching[1:] & (np.diff(np.asarray(t, dtype=np.float64)) < 0)
    return start


def high_pass(
    x: Any, t: Any, tau: float, step_offset: float = 0.5, restart: Any = None
) -> np.ndarray:
    """First-order high-pass of ``x`` sampled at times ``t`` (s), time constant ``tau`` (s).

    ``e_k = a_k e_{k-1} + a_k^theta (x_k - x_{k-1})`` with ``a_k = exp(-(t_k - t_{k-1})/tau)``
    and ``theta = step_offset``: exact for an input that changes in steps a fraction ``theta``
    of the sample interval before the sample that first shows the new value. The default 1/2
    (midway) suits a measured input, of which a recording only says that it changed between
    two samples; 0 suits a command logged at the instant it changes (the response is then zero
    at that sample). The recording starts from rest, the drive switched on the same ``theta``
    of the first interval before the first sample (``e_0 = a_1^theta x_0``). The discrete form
    of ``tau s / (1 + tau s)`` (Eq. 3.22); as ``tau -> inf`` it passes ``x`` unchanged, and as
    ``tau -> 0`` it vanishes when ``theta > 0``; ``tau = inf`` passes ``x`` unchanged exactly.
    Without a time axis (scalar or constant ``t``) the input is returned unchanged. Where time
    decreases a new recording starts, from rest; so does every sample where ``restart`` (one
    boolean per sample, e.g. :func:`touchdowns`) is true: the filter restarts from rest there,
    the drive switched on ``theta`` of the interval before that sample.
    """
    if not (tau > 0) or math.isnan(tau):
        raise PredictorError(f"time constant must be positive, got {tau}")
    if not 0.0 <= step_offset <= 1.0:
        raise PredictorError(f"step offset must lie in [0, 1], got {step_offset}")
    series = _series(x, t)
    if series is None or math.isinf(tau):
        return np.array(np.asarray(x, dtype=np.float64))
    x_arr, t_arr = series
    parts = _segments(t_arr, _restart_mask(restart, t_arr.size))
    return np.concatenate(
        [_high_pass(x_arr[p], t_arr[p], tau, step_offset, _lead(t_arr, p)) for p in parts]
    )


def _lead(t_arr: np.ndarray, part: slice) -> float | None:
    """The interval before a segment's first sample (s) when the segment restarts within a
    run of increasing time, else None (a recording's first sample: no interval before it)."""
    a = part.start
    if a == 0 or t_arr[a] < t_arr[a - 1]:
        return None
    return float(t_arr[a] - t_arr[a - 1])


def _high_pass(
    x_arr: np.ndarray, t_arr: np.ndarray, tau: float, theta: float, lead: float | None = None
) -> np.ndarray:
    """:func:`high_pass` of one recording (time increasing strictly), step offset ``theta``;
    ``lead`` (s): the interval before the first sample, in which the drive switched on (None:
    the first interval of the recording stands in for it).

    Vectorised by runs of equal sample interval (one IIR filter per run, its state carried
    over), so that a recording with gaps (a training split without its held-out strokes)
    costs a filter call per gap, not a Python step per sample.
    """
    out = np.empty_like(x_arr)
    if x_arr.size == 0:
        return out
    dt = np.diff(t_arr)
    decay = np.exp(-dt / tau)
    # The drive is switched on theta of the interval before the first sample.
    if lead is not None:
        out[0] = x_arr[0] * math.exp(-lead / tau) ** theta
    else:
        out[0] = x_arr[0] * (decay[0] ** theta if dt.size else 1.0)
    if x_arr.size == 1:
        return out
    drive = np.power(decay, theta) * np.diff(x_arr)
    # Runs of (nearly) equal intervals: a new run where the interval changes.
    change = np.flatnonzero(np.abs(np.diff(dt)) > 1e-9 * dt[1:]) + 1
    starts = [0, *change.tolist()]
    ends = [*change.tolist(), dt.size]
    from scipy.signal import lfilter  # here: scipy.signal costs ~0.6 s to import, and listing
    # the effects (`hcard plugins`) must not pay it

    previous = out[0]
    for a, b in zip(starts, ends, strict=True):
        factor = decay[a]
        run, _ = lfilter([1.0], [1.0, -factor], drive[a:b], zi=[factor * previous])
        out[a + 1 : b + 1] = run
        previous = run[-1]
    return out


def low_pass(
    x: Any, t: Any, tau: float, step_offset: float = 0.5, restart: Any = None
) -> np.ndarray:
    """First-order low-pass of ``x`` at times ``t`` (s), time constant ``tau`` (s):
    ``x - high_pass(x, t, tau, step_offset, restart)``, starting from rest (``y_0 = 0``) at
    the first sample and at every sample where ``restart`` is true. With ``step_offset = 0``
    (steps at the sample instants) this is ``y_k = a_k y_{k-1} + (1 - a_k) x_{k-1}``.
    ``tau = 0`` passes ``x`` unchanged exactly, and so does a missing time axis (the steady
    state)."""
    if tau == 0:
        return np.array(np.asarray(x, dtype=np.float64))
    series = _series(x, t)
    if series is None:
        return np.asarray(x, dtype=np.float64)
    x_arr, t_arr = series
    return x_arr - high_pass(x_arr, t_arr, tau, step_offset, restart)


def time_since_change(x: Any, t: Any) -> np.ndarray:
    """Time (s) since ``x`` last changed value, per sample (since ``t_0`` before any change).

    The ``voltage_history`` regressor (of the voltage) in the module docstring.
    """
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, float), np.asarray(t, float))
    changed = np.ones(x_arr.size, dtype=bool)
    changed[1:] = x_arr[1:] != x_arr[:-1]
    last = np.maximum.accumulate(np.where(changed, np.arange(x_arr.size), 0))
    return t_arr - t_arr[last]


def recent_change(x: Any, t: Any, window: float) -> np.ndarray:
    """``x(t) - x(t - window)`` per sample (unit of ``x``), with ``x`` before ``t_0`` taken as
    zero; ``window`` in s. The ``amplitude_history`` regressor (of the amplitude)."""
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, float), np.asarray(t, float))
    index = np.searchsorted(t_arr, t_arr - window, side="right") - 1
    earlier = np.where(index >= 0, x_arr[np.maximum(index, 0)], 0.0)
    return x_arr - earlier
