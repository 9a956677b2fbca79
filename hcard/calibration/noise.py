"""The sensor's noise measured where the finger does not slide, and the power of the structure
tests.

**Noise model.** Out of contact (lifts and rests) the lateral-force sensor reads its own noise.
:func:`measure_noise` takes every run of at least :data:`MIN_RUN` lifted samples, removes each
run's mean (the zero, which re-zeroing takes out), and measures the noise's standard deviation
and its lag-1 autocorrelation from pairs of consecutive samples of one run: an AR(1) model
``e_i = a e_(i-1) + w_i``. Coloured noise (``a`` well above 0) makes a residual correlated in
time without any structure in the model; the loop compares the residual's lag-1 autocorrelation
with the noise's (:func:`time_structure_threshold`) instead of with a fixed number.

**Power.** :func:`detectable_eta2` is the smallest share of the residual variance (``eta^2``)
that a one-way ANOVA F-test over ``groups`` bins detects with probability ``power`` at level
``alpha`` with ``n_eff`` effectively independent samples: the noncentral F with noncentrality
``lambda = n_eff eta^2 / (1 - eta^2)`` (Cohen's ``f^2 = eta^2 / (1 - eta^2)``) exceeds the
critical value with that probability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard.quantities import MN_PER_N

MIN_RUN = 10
"""Lifted samples a run needs to count for the noise model."""

SETTLE_S = 0.05
"""Start of each lifted run left out of the noise model, s: the sensor's response to the
lift-off, a step from the friction force to 0, is not its noise. A lateral-force sensor with a
resonance at 150 Hz and damping ratio 0.1 rings for 1/(zeta omega) = 11 ms per e-fold: its
first 50 ms made the noise of a device that has it read 23 mN with lag-1 0.41 for its 7.7 mN
white noise (bench/bench_device_hit_rates.py, force-sensor-resonance)."""

EXCESS_MIN_SHARE = 0.3
"""Share of a residual's variance beyond the sensor noise measured out of contact that counts as
structure in time (:func:`beyond_noise`, spec/calibration.md K37). In contact the force reads
more than the sensor's own noise without any effect missing from the model -- the normal
force's noise through the friction coefficient, the skin's stick-slip -- so the share must
exceed what that gives: 0.01-0.05 through the reference device with nothing hidden, up to 0.22
on the synthetic recordings of tests/calibration (test_loop.py, test_selection.py), 0.55 with
a 150 Hz sensor resonance."""

EXCESS_MIN_LAG1 = 0.25
"""Lag-1 autocorrelation the residual's variance beyond the sensor noise needs to count as
structure in time (:func:`beyond_noise`): anything slower than an oscillation at a fifth of the
sample rate (``cos(2 pi / 5) = 0.31``)."""

DEFAULT_POWER = 0.8
"""Probability of detection the stated power refers to."""


@dataclass(frozen=True)
class NoiseModel:
    """AR(1) model of the lateral-force sensor's noise, from samples out of contact.

    Attributes:
        sigma: standard deviation, N.
        lag1: lag-1 autocorrelation (the AR(1) coefficient), in [-1, 1].
        samples: lifted samples used.
        runs: lifted runs used.
    """

    sigma: float
    lag1: float
    samples: int
    runs: int

    def describe(self) -> str:
        """The model in words."""
        return (
            f"sensor noise from {self.samples} samples out of contact in {self.runs} lifts and "
            f"rests: {self.sigma * MN_PER_N:.3g} mN standard deviation, lag-1 autocorrelation "
            f"{self.lag1:.2f} (AR(1))"
        )


def measure_noise(values: np.ndarray, lifted: np.ndarray, t: np.ndarray | None = None,
                  settle_s: float = SETTLE_S) -> NoiseModel | None:
    """The :class:`NoiseModel` of ``values`` (N) over the runs of ``lifted`` samples (module
    docstring), each without its first ``settle_s`` seconds when the sample times ``t`` (s)
    are given (:data:`SETTLE_S`); None without a run of :data:`MIN_RUN` samples."""
    v = np.asarray(values, dtype=np.float64)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(lifted, np.int8), [0]])))
    centred: list[np.ndarray] = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if t is not None:
            start += int(np.searchsorted(t[start:end] - t[start], settle_s * (1.0 - 1e-9)))
        if end - start >= MIN_RUN:
            run = v[start:end]
            centred.append(run - run.mean())
    if not centred:
        return None
    power = sum(float(np.dot(run, run)) for run in centred)
    lagged = sum(float(np.dot(run[:-1], run[1:])) for run in centred)
    samples = sum(run.size for run in centred)
    lag1 = float(np.clip(lagged / power, -1.0, 1.0)) if power > 0 else 0.0
    # each run loses to its mean the variance of that mean: for AR(1) noise, more than one
    # sample's worth (_mean_loss)
    kept = sum(run.size - _mean_loss(run.size, lag1) for run in centred)
    sigma = math.sqrt(power / max(kept, 1.0))
    return NoiseModel(sigma=sigma, lag1=lag1, samples=samples, runs=len(centred))


def _mean_loss(length: int, lag1: float) -> float:
    """``L Var(mean) / sigma^2`` of ``length`` samples of AR(1) noise of lag-1 ``lag1``:
    ``1 + 2 sum_k (1 - k/L) a^k`` (k = 1 .. L-1), what removing a run's mean takes from
    ``E[sum (x - mean)^2] = sigma^2 (L - loss)``; 1 for white noise, clipped below ``L``."""
    a = max(lag1, 0.0)
    if a == 0.0 or length < 2:
        return 1.0
    k = np.arange(1, length)
    loss = 1.0 + 2.0 * float(np.sum((1.0 - k / length) * a**k))
    return min(loss, length - 1.0)


def time_structure_threshold(base: float, noise: NoiseModel | None) -> float:
    """Lag-1 autocorrelation of a residual above which it is structured in time: ``base``
    for white noise; for noise of lag-1 autocorrelation ``a``, the residual must keep less
    than half of the noise's decorrelation ``1 - a``: ``max(base, a + (1 - a) / 2)``."""
    if noise is None or noise.lag1 <= 0:
        return base
    return max(base, noise.lag1 + (1.0 - noise.lag1) / 2.0)


def beyond_noise(rms: float, lag1: float, effective: float, noise: NoiseModel | None
                 ) -> tuple[float, float, float]:
    """The share of a residual's variance beyond the sensor ``noise``, that excess's lag-1
    autocorrelation, and the p-value of the excess: with residual variance ``s_r^2 = rms^2``
    (N^2), lag-1 ``rho`` and ``effective`` independent samples, noise ``s_n^2`` and ``a``, the
    share is ``1 - s_n^2 / s_r^2``, the excess's lag-1 covariance over its variance
    ``(rho s_r^2 - a s_n^2) / (s_r^2 - s_n^2)``, and the p-value the F-test's of the variance
    ratio ``s_r^2 / s_n^2`` with ``effective`` and the noise's effective ``m (1 - a) / (1 + a)``
    degrees of freedom (``m`` samples). ``(0, 0, 1)`` without a noise model or when the
    residual holds no more than the noise."""
    if noise is None or not rms > noise.sigma:
        return 0.0, 0.0, 1.0
    from scipy import stats  # here: scipy.stats costs ~0.6 s to import

    total, floor = rms * rms, noise.sigma * noise.sigma
    a = max(noise.lag1, 0.0)
    noise_dof = max(noise.samples * (1.0 - a) / (1.0 + a) - noise.runs, 1.0)
    p_value = float(stats.f.sf(total / floor, max(effective - 1.0, 1.0), noise_dof))
    return 1.0 - floor / total, (lag1 * total - noise.lag1 * floor) / (total - floor), p_value


def detectable_eta2(
    n_eff: float, groups: int, alpha: float, power: float = DEFAULT_POWER
) -> float:
    """Smallest ``eta^2`` the F-test over ``groups`` bins detects with probability ``power`` at
    level ``alpha`` with ``n_eff`` effectively independent samples (module docstring); 1 when
    no ``eta^2`` is (fewer samples than bins)."""
    from scipy import optimize, stats  # here: scipy.stats costs ~0.6 s to import

    dfn, dfd = groups - 1, n_eff - groups
    if dfn < 1 or dfd < 1:
        return 1.0
    critical = float(stats.f.isf(alpha, dfn, dfd))

    def shortfall(eta2: float) -> float:
        lam = n_eff * eta2 / (1.0 - eta2)
        return float(stats.ncf.sf(critical, dfn, dfd, lam)) - power

    if shortfall(1.0 - 1e-9) < 0:
        return 1.0
    return float(optimize.brentq(shortfall, 1e-12, 1.0 - 1e-9, xtol=1e-10))


MIN_BLOCK = 64
"""Fewest samples in a block of :func:`ar1_block_test`."""

BLOCK_CORRELATION_TIMES = 20.0
"""Block length of :func:`ar1_block_test` in the AR(1) noise's correlation times
``(1 + a) / (1 - a)`` samples: the blocks' means are then nearly independent under the noise
model (their correlation ~ ``a / (L (1 - a)^2)``, 0.08 at ``a`` = 0.73)."""

MIN_BLOCKS = 8
"""Fewest blocks :func:`ar1_block_test` decides on."""


@dataclass(frozen=True)
class BlockTest:
    """Whether a residual is structured in time beyond an AR(1) noise fitted to it.

    Attributes:
        lag1: the AR(1) coefficient ``a`` fitted from the first differences,
            ``a = 1 + 2 r_d`` with ``r_d`` their lag-1 autocorrelation (a slow drift hardly
            changes the differences, so it does not inflate ``a``).
        sigma: the AR(1) noise's marginal standard deviation from the differences,
            ``var(d) / (2 (1 - a))``, output unit.
        block: samples per block.
        blocks: blocks used.
        ratio: variance of the block means over the AR(1) prediction of it.
        p_value: one-sided (more variance than the noise gives), of ``ln(ratio)`` against a
            normal of variance ``2/(blocks - 1)`` (the block variance's sampling spread) plus
            the fitted noise's, ``(1/(1 + a) + 2/(1 - a))^2 4/n``; 0 when too few blocks
            (the test cannot clear the residual).
    """

    lag1: float
    sigma: float
    block: int
    blocks: int
    ratio: float
    p_value: float


def ar1_block_test(residual: np.ndarray) -> BlockTest:
    """Test ``residual`` (in time order) for structure slower than an AR(1) noise
    (spec/calibration.md K29): fit ``e_i = a e_(i-1) + w_i`` to its first differences
    (:class:`BlockTest`), cut it into blocks of ``max(MIN_BLOCK, BLOCK_CORRELATION_TIMES (1 + a)
    / (1 - a))`` samples and compare the variance of the block means with the AR(1) one,
    ``sigma^2 / L (1 + 2 sum_k (1 - k/L) a^k)``. Coloured sensor noise gives a ratio near 1;
    a drift or a level that changes from stroke to stroke gives more."""
    from scipy import stats  # here: scipy.stats costs ~0.6 s to import

    r = np.asarray(residual, dtype=np.float64)
    d = np.diff(r)
    dc = d - d.mean() if d.size else d
    power = float(np.dot(dc, dc))
    if d.size < 3 or power <= 0:
        return BlockTest(0.0, 0.0, 0, 0, math.nan, 0.0)
    r_d = float(np.dot(dc[:-1], dc[1:]) / power)
    a = float(np.clip(1.0 + 2.0 * r_d, 0.0, 0.99))
    sigma2 = power / d.size / (2.0 * (1.0 - a))
    block = max(MIN_BLOCK, math.ceil(BLOCK_CORRELATION_TIMES * (1.0 + a) / (1.0 - a)))
    blocks = r.size // block
    if blocks < MIN_BLOCKS:
        return BlockTest(a, math.sqrt(sigma2), block, blocks, math.nan, 0.0)
    means = r[: blocks * block].reshape(blocks, block).mean(axis=1)
    k = np.arange(1, block)
    predicted = sigma2 / block * (1.0 + 2.0 * float(np.sum((1.0 - k / block) * a**k)))
    ratio = float(np.var(means, ddof=1) / predicted)
    # ln(ratio): sampling spread of the block variance, 2/(m - 1), plus that of the fitted
    # noise: the prediction goes as var(d) (1 + a) / (1 - a)^2, d ln / da = 1/(1 + a) +
    # 2/(1 - a), with var(a) = 4 var(r_d) ~ 4/n
    slope = 1.0 / (1.0 + a) + 2.0 / (1.0 - a)
    spread = math.sqrt(2.0 / (blocks - 1) + slope**2 * 4.0 / d.size)
    p = float(stats.norm.sf(math.log(max(ratio, 1e-300)) / spread))
    return BlockTest(a, math.sqrt(sigma2), block, blocks, ratio, p)
