"""Tribometer recordings written out by hand from the thesis formulas, for the loop's tests.

Nothing here calls an effect plugin or a predictor: the friction is Eq. 2.33 with the group of
Eq. 2.30 and the Eq. 4.1 definition ``F_l = mu0 Fn mu'``, computed with numpy, and each hidden
effect is its formula written again:

- occlusion (sweat builds up under the finger, mu0 rises with time in contact):
  ``mu0(t) = mu0 (1 + g (1 - exp(-t / tau)))``, in the prefactor and inside Psi;
- load index (Eq. 2.35, friction ~ Fn^k): ``F_l ~ Fn (Fn / 1 N)^(k - 1)``;
- direction-dependent friction: ``F_l (1 + d sign(U))``;
- coloured sensor noise: an AR(1) process ``e_i = a e_(i-1) + s sqrt(1 - a^2) w_i``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from hcard.calibration.measurement import Measurement

PLATE_HZ = 27_500.0
MU0 = 0.5
NU = 0.33
PSI_STAR = 2.38


@dataclass(frozen=True)
class Hidden:
    """The hidden effects of a hand-written recording (0 or 1: absent)."""

    occlusion_gain: float = 0.0
    occlusion_tau_s: float = 15.0
    load_index: float = 1.0
    direction: float = 0.0


def ar1(rng: np.random.Generator, n: int, sigma: float, lag1: float) -> np.ndarray:
    """AR(1) noise of standard deviation ``sigma`` and lag-1 autocorrelation ``lag1``."""
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    drive = rng.normal(0.0, sigma * math.sqrt(1.0 - lag1 * lag1), n)
    for i in range(1, n):
        out[i] = lag1 * out[i - 1] + drive[i]
    return out


def relative_friction(speed: np.ndarray, amplitude: np.ndarray, mu0: np.ndarray) -> np.ndarray:
    """``mu' = 1 - exp(-Psi / Psi*)``, ``Psi = |U| / (w f mu0 (1 + nu))`` (Eqs. 2.30, 2.33); 1
    without vibration."""
    with np.errstate(divide="ignore", invalid="ignore"):
        psi = np.abs(speed) / (amplitude * PLATE_HZ * mu0 * (1.0 + NU))
    return np.where(amplitude > 0, 1.0 - np.exp(-psi / PSI_STAR), 1.0)


def uv_recording(
    hidden: Hidden,
    *,
    seed: int,
    noise_n: float = 1.5e-3,
    noise_lag1: float = 0.0,
    duration_s: float = 40.0,
    rate_hz: float = 500.0,
    stroke_column: str | None = None,
    lift_noise_n: float | None = None,
    rest_every: int = 8,
    amplitudes: tuple[float, ...] = (0.0, 0.5e-6, 1.0e-6, 1.5e-6, 2.0e-6),
) -> Measurement:
    """A back-and-forth UV recording: strokes of 0.4 s at one speed (10-80 mm/s, alternating
    direction), normal force (0.15-1.5 N) and amplitude (one of ``amplitudes``, m) each, lifts
    of 0.2 s, and a 1 s rest after every ``rest_every`` strokes (0: never). Lateral noise
    ``noise_n`` (N) with lag-1 autocorrelation ``noise_lag1``, normal noise ``lift_noise_n``
    (default ``noise_n``), white.

    ``stroke_column``: None (no column), ``"lifts"`` (-1 in the lifts) or ``"carried"`` (the
    stroke number carried through the following lift and rest).
    """
    rng = np.random.default_rng(seed)
    step = 1.0 / rate_hz
    t_parts, fn_parts, u_parts, w_parts, id_parts = [], [], [], [], []
    t0, stroke = 0.0, 0
    while t0 < duration_s:
        fn = rng.uniform(0.15, 1.5)
        u = rng.uniform(0.01, 0.08) * (1 if stroke % 2 == 0 else -1)
        w = rng.choice(amplitudes)
        n_stroke = round(0.4 * rate_hz)
        lift = 1.0 if rest_every and stroke % rest_every == rest_every - 1 else 0.2
        n_lift = round(lift * rate_hz)
        n = n_stroke + n_lift
        t_parts.append(t0 + step * np.arange(n))
        fn_parts.append(np.concatenate([np.full(n_stroke, fn), np.zeros(n_lift)]))
        u_parts.append(np.concatenate([np.full(n_stroke, u), np.zeros(n_lift)]))
        w_parts.append(np.full(n, w))
        carried = np.full(n, stroke)
        id_parts.append(carried if stroke_column == "carried"
                        else np.concatenate([carried[:n_stroke], np.full(n_lift, -1)]))
        t0 += n * step
        stroke += 1
    t = np.concatenate(t_parts)
    fn = np.concatenate(fn_parts)
    speed = np.concatenate(u_parts)
    amplitude = np.concatenate(w_parts)
    touching = fn > 0
    mu0 = MU0 * (1.0 + hidden.occlusion_gain * -np.expm1(-t / hidden.occlusion_tau_s))
    load = np.where(touching, np.power(np.where(touching, fn, 1.0), hidden.load_index - 1.0), 0)
    lateral = (
        mu0 * fn * load * relative_friction(speed, amplitude, mu0)
        * (1.0 + hidden.direction * np.sign(speed))
    )
    lateral = lateral * np.sign(speed)  # signed by the direction of motion
    lateral = lateral + ar1(rng, t.size, noise_n, noise_lag1)
    normal = fn + rng.normal(0.0, noise_n if lift_noise_n is None else lift_noise_n, t.size)
    return Measurement(
        t=t,
        normal_force=normal,
        lateral_force=lateral,
        amplitude=amplitude,
        speed=speed,
        stroke=None if stroke_column is None else np.concatenate(id_parts),
        conditions={"plate_frequency_hz": PLATE_HZ, "device": "hand-written"},
    )


def test_the_generator_follows_eq_2_33_at_a_hand_computed_point() -> None:
    # U = 50 mm/s, w = 1 um: Psi = 0.05 / (1e-6 * 27500 * 0.5 * 1.33) = 2.7341,
    # mu' = 1 - exp(-2.7341 / 2.38) = 0.6830 (computed by hand).
    value = relative_friction(np.array([0.05]), np.array([1e-6]), np.array([0.5]))
    assert float(value[0]) == pytest.approx(0.6830, abs=2e-4)
    m = uv_recording(Hidden(), seed=1, noise_n=1e-9)
    sliding = (m.normal_force > 0.1) & (m.amplitude == 0)
    # without vibration F_l = mu0 Fn, signed by the speed
    assert np.allclose(m.lateral_force[sliding] * np.sign(m.speed[sliding]),
                       MU0 * m.normal_force[sliding], atol=1e-6)
