"""The EV amplifier: a voltage envelope on a sinusoidal carrier, with its limits (section 4.2.1).

The amplifier drives ``v(t) = V(t) sin(2 pi f_c t)`` (``f_c`` = 440 Hz on the coupled stimulator)
into the capacitance ``C`` the finger and the insulator form (Eq. 3.8, about 33 pF; 0 without
contact). The current through the user is ``i = C dv/dt``; for a steady carrier of peak ``V``
its peak is ``I = 2 pi f_c C V``. Over one frame of length ``dt`` in which the envelope moves
linearly from ``V_prev`` to ``V``, ``|dv/dt| <= w max(V, V_prev) + |V - V_prev| / dt``
(``w = 2 pi f_c``), so the reported peak current of the frame is

    I_k = C (w max(V_k, V_{k-1}) + |V_k - V_{k-1}| / dt),

an upper bound of the true peak (the limiter holds it at ``I_max`` in the frames where it
saturates, below). With the rate budget ``R = min(S, I_max / C)`` (``S`` the
output slew-rate limit, V/s) the envelope obeys, frame by frame::

    V_k <= V_max,
    V_k <= (R + V_{k-1} / dt) / (w + 1 / dt)      (rising: C (w V_k + dV/dt) <= I_max),
    V_k >= V_{k-1} - dt (R - w V_{k-1})           (falling: C (w V_{k-1} + |dV/dt|) <= I_max),

so the current never exceeds ``I_max`` and the output never slews faster than ``S``. A load
that grows faster than the present voltage allows (a large contact landing on a live plate,
``w C V_{k-1} > I_max``), or a voltage limit lowered under the present envelope, puts the
limiter in hard limit for that frame: the envelope collapses to the new bound while the current
is held at ``I_max``. The voltage and the current therefore never exceed their limits.

The recursion is exact; it runs vectorised wherever the clipped command already satisfies the
rate bounds (smooth envelopes) and sample by sample only through the frames where a bound binds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_SLACK = 1e-9
"""Relative margin kept under the current limit against rounding."""


@dataclass(frozen=True)
class AmplifierRun:
    """Result of :meth:`EVAmplifier.run` over N frames.

    Attributes:
        voltage: (N,) peak voltage envelope, V.
        current: (N,) peak current through the user, A.
        voltage_limited: (N,) the envelope was held below the command by the voltage or slew
            limit.
        current_limited: (N,) the envelope was held below the command by the current limit.
    """

    voltage: np.ndarray
    current: np.ndarray
    voltage_limited: np.ndarray
    current_limited: np.ndarray


class EVAmplifier:
    """The EV amplifier's envelope, limits and user current; the envelope carries over runs.

    Args:
        carrier_hz: carrier frequency ``f_c``, Hz.
        frame_rate_hz: frames per second (the envelope is updated once a frame), Hz.
        max_voltage_v: voltage limit, V.
        max_current_a: current limit, A.
        slew_v_per_s: output slew-rate limit, V/s.
    """

    def __init__(
        self,
        carrier_hz: float,
        frame_rate_hz: float,
        max_voltage_v: float,
        max_current_a: float,
        slew_v_per_s: float,
    ) -> None:
        self.omega = 2.0 * math.pi * carrier_hz
        self.dt = 1.0 / frame_rate_hz
        self.max_voltage_v = max_voltage_v
        self.max_current_a = max_current_a
        self.slew_v_per_s = slew_v_per_s
        self.voltage_v = 0.0

    def reset(self) -> None:
        """Output at zero."""
        self.voltage_v = 0.0

    def _budget(self, capacitance: np.ndarray | float
                ) -> tuple[np.ndarray | float, np.ndarray | bool]:
        """Rate budget ``R`` (V/s) and whether the current (not the slew) sets it, per frame
        (numbers for one capacitance, F)."""
        limit = self.max_current_a * (1.0 - _SLACK)
        if isinstance(capacitance, float):
            current_rate = limit / capacitance if capacitance > 0 else math.inf
            return min(self.slew_v_per_s, current_rate), current_rate < self.slew_v_per_s
        by_current = np.empty(capacitance.shape)
        by_current.fill(np.inf)
        np.divide(limit, capacitance, out=by_current, where=capacitance > 0)
        return np.minimum(self.slew_v_per_s, by_current), by_current < self.slew_v_per_s

    def run(self, command: np.ndarray, capacitance: np.ndarray | float) -> AmplifierRun:
        """Advance over ``len(command)`` frames.

        Args:
            command: (N,) commanded peak envelope, V (negative and NaN read as 0).
            capacitance: (N,) load capacitance through the user, F (0 without contact), or
                one number for every frame (the same numbers, without per-frame budgets).
        """
        cmd = _command(command)
        if isinstance(capacitance, float | int) or getattr(capacitance, "ndim", 1) == 0:
            cap: np.ndarray | float = max(float(capacitance), 0.0)  # NaN stays NaN
        else:
            cap = np.maximum(np.asarray(capacitance, dtype=np.float64), 0.0)
        n = cmd.shape[0]
        if self._idle(cmd):
            # Off and commanded off: the envelope stays at 0 V (what the recursion gives).
            zeros = np.zeros(n, dtype=bool)
            return AmplifierRun(np.zeros(n), np.multiply(cap, np.zeros(n)), zeros, zeros.copy())
        budget, by_current = self._budget(cap)
        w, dt = self.omega, self.dt
        if isinstance(budget, float):
            steady: np.ndarray | float = min(self.max_voltage_v, budget / w)
            budget_at: np.ndarray | float = budget  # the budget of frames k.. (one for all)
        else:
            steady = np.minimum(self.max_voltage_v, budget / w)
        target = np.minimum(cmd, steady)
        volts = np.empty(n)
        hard = np.zeros(n, dtype=bool)
        k, prev = 0, self.voltage_v
        start = prev
        steady_before = None  # the envelope before each frame, when the first pass holds
        while k < n:
            # Vectorised pass: the clipped command, checked against the rate bounds.
            v = target[k:]
            before = np.concatenate(([prev], v[:-1]))
            if not isinstance(budget, float):
                budget_at = budget[k:]
            hi = (budget_at + before / dt) / (w + 1.0 / dt)
            lo = before - dt * (budget_at - w * before)
            bad = (v > hi * (1 + 1e-12)) | (v < lo * (1 - 1e-12))
            j = int(bad.argmax()) if np.logical_or.reduce(bad) else v.shape[0]
            if k == 0 and j == n:
                steady_before = before  # every frame is the clipped command
            volts[k : k + j] = v[:j]
            if j:
                prev = float(v[j - 1])
            k += j
            # Sample by sample while a rate bound binds.
            while k < n:
                b = budget if isinstance(budget, float) else float(budget[k])
                if w * prev > b or prev > self.max_voltage_v:
                    # The load outgrew the voltage, or the limit fell under it: the limiter
                    # saturates and the envelope collapses within the frame.
                    value = steady if isinstance(steady, float) else float(steady[k])
                    hard[k] = True
                else:
                    high = (b + prev / dt) / (w + 1.0 / dt)
                    low = prev - dt * (b - w * prev)
                    value = min(max(float(target[k]), low), high)
                volts[k] = value
                prev = value
                k += 1
                if value == target[k - 1]:
                    break
        self.voltage_v = prev
        before = steady_before if steady_before is not None else \
            np.concatenate(([start], volts[:-1]))
        current = cap * (w * np.maximum(volts, before) + np.abs(volts - before) / dt)
        held = volts < cmd * (1.0 - 1e-9)
        if not np.logical_or.reduce(hard):
            if not np.logical_or.reduce(held):  # nothing held the envelope back
                return AmplifierRun(volts, current, held, held.copy())
            hard_current = hard
        else:
            np.minimum(current, self.max_current_a, out=current, where=hard)
            hard_current = hard & (w * before * cap > self.max_current_a * (1.0 - _SLACK))
        at_voltage_limit = volts >= self.max_voltage_v * (1.0 - 1e-9)
        current_limited = hard_current | (held & ~at_voltage_limit & by_current)
        voltage_limited = (held | hard) & ~current_limited
        return AmplifierRun(volts, current, voltage_limited, current_limited)

    def _idle(self, command: np.ndarray) -> bool:
        """The envelope is at 0 V and ``command`` (sanitised) asks for 0 V throughout, with
        sane limits: the recursion then keeps it at exactly 0 V, holds nothing and draws no
        current, so :meth:`run` may skip it."""
        return (
            self.voltage_v == 0.0
            and self.max_voltage_v > 0.0
            and self.max_current_a >= 0.0
            and self.slew_v_per_s > 0.0
            and not np.logical_or.reduce(command)
        )


_FLOAT_MAX = float(np.finfo(np.float64).max)


def _command(command: np.ndarray) -> np.ndarray:
    """The commanded envelope (V) as the amplifier reads it: NaN and negative values as 0,
    +inf as the largest float (``np.nan_to_num`` then ``max(., 0)``, in three ufuncs)."""
    cmd = np.minimum(np.asarray(command, dtype=np.float64), _FLOAT_MAX)
    np.fmax(cmd, 0.0, out=cmd)  # NaN and -inf read as 0
    cmd += 0.0  # -0.0 reads as 0.0, as np.maximum(-0.0, 0.0) gives
    return cmd
