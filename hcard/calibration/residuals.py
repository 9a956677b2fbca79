"""Residual analysis: is structure left in a fit's residual, and against what (spec/calibration.md).

:func:`analyse_residuals` takes a residual (``observed - predicted``, in the output unit) and the
regressors the data has (amplitude in m, voltage in V, speed in m/s, normal force in N, time in
contact in s, stroke number, ...), each a 1-D array aligned with the residual, and reports per
regressor:

- the residual's mean in quantile bins of the regressor (or per distinct value, for a regressor
  with few distinct values such as a stroke number), with a one-way ANOVA F-test of "the bin means
  are equal" and the fraction of the residual variance the bins explain (``eta^2``);
- the Spearman rank correlation and a flag for a monotonic trend;

and, taking the residual's order as time order, its lag-1 autocorrelation, a Ljung-Box statistic
over the first lags and, given the sample rate, the dominant frequency of its spectrum.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from hcard.calibration.noise import BlockTest, ar1_block_test
from hcard.physics import PredictorError

DEFAULT_BINS = 10
"""Quantile bins per regressor."""

MIN_BIN_COUNT = 3
"""Bins with fewer samples are left out of the F-test."""


@dataclass(frozen=True)
class RegressorStats:
    """Structure of the residual against one regressor.

    Attributes:
        name: the regressor's name.
        bin_centres: median of the regressor in each bin (regressor unit).
        bin_means: mean residual in each bin (output unit).
        bin_counts: samples per bin.
        f_statistic: one-way ANOVA F of the residual across bins (0 if undefined).
        p_value: p-value of that F-test, corrected for the residual's autocorrelation
            (:func:`_corrected_f_p`; 1 if undefined, e.g. a constant regressor).
        eta2: between-bin sum of squares over total sum of squares, in [0, 1]: the fraction
            of the residual variance explained by the bins.
        spearman_rho: Spearman rank correlation of the residual with the regressor.
        spearman_p: its two-sided p-value, for the effective sample count.
        monotonic: True when the rank correlation is significant (p < 0.01) and the bin means
            rise or fall in step with the bins (absolute rank correlation of the bin means with
            the bin order at least 0.9).
    """

    name: str
    bin_centres: np.ndarray
    bin_means: np.ndarray
    bin_counts: np.ndarray
    f_statistic: float
    p_value: float
    eta2: float
    spearman_rho: float
    spearman_p: float
    monotonic: bool


@dataclass(frozen=True)
class TimeStats:
    """Structure of the residual in time (sample order).

    Attributes:
        lag1_autocorrelation: correlation of the residual with itself one sample later.
        ljung_box_q: ``n (n+2) sum_k r_k^2 / (n-k)`` over lags ``1..lags``.
        ljung_box_p: its p-value against chi-squared with ``lags`` degrees of freedom.
        lags: number of lags in the Ljung-Box statistic.
        dominant_frequency_hz: frequency of the largest non-DC peak of the residual's
            spectrum (Hz), or None without a sample rate.
        dominant_power_fraction: share of the residual's (non-DC) spectral power at that peak,
            or None without a sample rate.
        beyond_noise: the residual against an AR(1) noise fitted to it
            (:func:`~hcard.calibration.noise.ar1_block_test`, spec/calibration.md K29), or None
            when the samples are not in time order.
    """

    lag1_autocorrelation: float
    ljung_box_q: float
    ljung_box_p: float
    lags: int
    dominant_frequency_hz: float | None
    dominant_power_fraction: float | None
    beyond_noise: BlockTest | None = None


@dataclass(frozen=True)
class ResidualReport:
    """What :func:`analyse_residuals` found.

    Attributes:
        n: number of samples.
        rms: root-mean-square residual (output unit).
        regressors: per-regressor statistics, in the order given.
        time: structure in sample order.
        effective_samples: how many of the ``n`` samples are effectively independent, given
            the residual's lag-1 autocorrelation (:func:`effective_samples`); the F-test and
            Spearman p-values are computed for that many.
    """

    n: int
    rms: float
    regressors: dict[str, RegressorStats]
    time: TimeStats
    effective_samples: float = math.nan

    def structured(
        self, alpha: float = 0.01, min_eta2: float = 0.05
    ) -> list[tuple[str, float, float]]:
        """Regressors against which structure remains: ``(name, eta2, p)``, strongest first.

        A regressor counts when its F-test p-value is below ``alpha`` *and* its bins explain at
        least ``min_eta2`` of the residual variance (with many samples a tiny, physically
        irrelevant structure is significant; ``min_eta2`` keeps it out).
        """
        found = [
            (s.name, s.eta2, s.p_value)
            for s in self.regressors.values()
            if s.p_value < alpha and s.eta2 >= min_eta2
        ]
        return sorted(found, key=lambda item: (-item[1], item[2]))

    def time_structured(self, alpha: float = 0.01) -> bool:
        """Whether the residual is correlated in time (Ljung-Box p-value below ``alpha``)."""
        return self.time.ljung_box_p < alpha

    def table(self) -> str:
        """A plain-text table of the statistics, one regressor a row, then the time structure."""
        header = (
            f"{'regressor':<20} {'eta2':>7} {'F':>10} {'p':>10} {'rho':>7} {'p(rho)':>10} "
            f"{'trend':>6}"
        )
        lines = [f"residual: n = {self.n}, rms = {self.rms:.4g}", header, "-" * len(header)]
        for s in self.regressors.values():
            lines.append(
                f"{s.name:<20} {s.eta2:>7.4f} {s.f_statistic:>10.4g} {s.p_value:>10.3g} "
                f"{s.spearman_rho:>7.3f} {s.spearman_p:>10.3g} {'yes' if s.monotonic else 'no':>6}"
            )
        t = self.time
        lines.append(
            f"time: lag-1 autocorrelation {t.lag1_autocorrelation:.4f}, Ljung-Box Q = "
            f"{t.ljung_box_q:.4g} over {t.lags} lags (p = {t.ljung_box_p:.3g})"
        )
        if t.dominant_frequency_hz is not None:
            lines.append(
                f"time: dominant frequency {t.dominant_frequency_hz:.4g} Hz "
                f"({100 * (t.dominant_power_fraction or 0.0):.1f} % of the power)"
            )
        return "\n".join(lines)


def bin_labels(x: np.ndarray, bins: int) -> np.ndarray:
    """Bin label of each sample: by distinct value when there are at most ``bins`` of them,
    else by quantile bins (ties kept together)."""
    distinct = np.unique(x)
    if distinct.size <= bins:
        return np.searchsorted(distinct, x)
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, bins + 1)[1:-1]))
    return np.searchsorted(edges, x, side="right")


def _regressor_stats(
    name: str, residual: np.ndarray, x: np.ndarray, bins: int, n_eff: float
) -> RegressorStats:
    labels = bin_labels(x, bins)
    present = np.unique(labels)
    centres = np.array([np.median(x[labels == k]) for k in present])
    means = np.array([residual[labels == k].mean() for k in present])
    counts = np.array([np.count_nonzero(labels == k) for k in present])

    used = [
        residual[labels == k]
        for k, c in zip(present, counts, strict=True)
        if c >= MIN_BIN_COUNT
    ]
    total = float(np.sum((residual - residual.mean()) ** 2))
    f_stat, p_value, eta2 = 0.0, 1.0, 0.0
    if len(used) >= 2 and total > 0:
        pooled = np.concatenate(used)
        between = sum(g.size * (g.mean() - pooled.mean()) ** 2 for g in used)
        within = sum(float(np.sum((g - g.mean()) ** 2)) for g in used)
        eta2 = float(between / (between + within)) if between + within > 0 else 0.0
        if within > 0:
            f_stat = float(stats.f_oneway(*used).statistic)
            p_value = _corrected_f_p(f_stat, len(used), pooled.size, n_eff)
        elif between > 0:
            f_stat, p_value = math.inf, 0.0

    rho, rho_p = 0.0, 1.0
    if np.ptp(x) > 0 and np.ptp(residual) > 0:
        rho = float(stats.spearmanr(x, residual).statistic)
        dof = max(n_eff - 2.0, 1.0)
        t = rho * math.sqrt(dof / max(1.0 - rho * rho, 1e-300))
        rho_p = float(2.0 * stats.t.sf(abs(t), dof))
    monotonic = False
    if rho_p < 0.01 and means.size >= 3:
        step = stats.spearmanr(np.arange(means.size), means).statistic
        monotonic = bool(abs(float(step)) >= 0.9)
    return RegressorStats(
        name=name,
        bin_centres=centres,
        bin_means=means,
        bin_counts=counts,
        f_statistic=f_stat,
        p_value=p_value,
        eta2=eta2,
        spearman_rho=rho,
        spearman_p=rho_p,
        monotonic=monotonic,
    )


@dataclass(frozen=True)
class JointStats:
    """The residual against the cells of several regressors binned together.

    Attributes:
        names: the regressors, in order.
        cells: cells with at least :data:`MIN_BIN_COUNT` samples (the ANOVA's groups).
        eta2: share of the residual's variance between the cells.
        adjusted_eta2: ``eta2`` less what ``cells`` groups explain by chance at the effective
            sample count, ``(eta2 - c) / (1 - c)`` with ``c = (cells - 1) / n_eff``, at least 0.
        p_value: of the F-test, corrected for autocorrelation like the per-regressor ones.
    """

    names: tuple[str, ...]
    cells: int
    eta2: float
    adjusted_eta2: float
    p_value: float


def joint_structure(residual: np.ndarray, regressors: Mapping[str, np.ndarray],
                    n_eff: float, bins: int = DEFAULT_BINS) -> JointStats:
    """``residual`` against the cells of ``regressors`` binned together (each as in
    :func:`analyse_residuals`: by distinct value when it has at most ``bins``, else by quantile
    bins), for a structure that lives in their combination: an effect on the electrostatic
    force that grows with the load shows only where there is voltage, so binned on the load
    alone the samples without voltage dilute it (eta2 0.009 where the effect cut the held-out
    error by 9 %)."""
    r = np.asarray(residual, dtype=np.float64)
    names = tuple(regressors)
    label = np.zeros(r.size, dtype=np.int64)
    for name in names:
        groups = bin_labels(np.asarray(regressors[name], dtype=np.float64), bins)
        label = label * (int(groups.max()) + 1) + groups
    _, cell = np.unique(label, return_inverse=True)
    counts = np.bincount(cell)
    used = [r[cell == k] for k in np.flatnonzero(counts >= MIN_BIN_COUNT)]
    if len(used) < 2:
        return JointStats(names, len(used), 0.0, 0.0, 1.0)
    pooled = np.concatenate(used)
    between = sum(g.size * (g.mean() - pooled.mean()) ** 2 for g in used)
    within = sum(float(np.sum((g - g.mean()) ** 2)) for g in used)
    if between + within <= 0:
        return JointStats(names, len(used), 0.0, 0.0, 1.0)
    eta2 = float(between / (between + within))
    chance = min((len(used) - 1) / max(n_eff, 1.0), 0.999)
    adjusted = max((eta2 - chance) / (1.0 - chance), 0.0)
    if within > 0:
        f_stat = float(stats.f_oneway(*used).statistic)
        p_value = _corrected_f_p(f_stat, len(used), pooled.size, n_eff)
    else:
        p_value = 0.0
    return JointStats(names, len(used), eta2, adjusted, p_value)


def _corrected_f_p(f_stat: float, groups: int, n: int, n_eff: float) -> float:
    """p-value of a one-way ANOVA F over ``groups`` groups of ``n`` samples of which only
    ``n_eff`` are effectively independent: the sums of squares carry ``n_eff / n`` of the
    information, so ``F`` is scaled by that and tested on ``n_eff - groups`` degrees of freedom
    (the usual design-effect correction for autocorrelated samples)."""
    scale = min(n_eff / n, 1.0)
    dof = max(n_eff - groups, 1.0)
    return float(stats.f.sf(f_stat * scale, groups - 1, dof))


def effective_samples(series: np.ndarray) -> float:
    """``n (1 - rho) / (1 + rho)`` for the lag-1 autocorrelation ``rho`` (clipped to [0, 0.999])
    of ``series``: the number of effectively independent samples, in [1, n]."""
    n = series.size
    centred = series - series.mean()
    denominator = float(np.dot(centred, centred))
    rho = float(np.dot(centred[:-1], centred[1:]) / denominator) if denominator > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    return float(min(max(n * (1.0 - rho) / (1.0 + rho), 1.0), n))


def _time_stats(residual: np.ndarray, sample_rate_hz: float | None) -> TimeStats:
    centred = residual - residual.mean()
    n = centred.size
    denominator = float(np.dot(centred, centred))
    lags = max(1, min(20, n // 5))
    if denominator > 0:
        r = np.array([np.dot(centred[:-k], centred[k:]) / denominator for k in range(1, lags + 1)])
    else:
        r = np.zeros(lags)
    q = float(n * (n + 2) * np.sum(r**2 / (n - np.arange(1, lags + 1))))
    frequency = fraction = None
    if sample_rate_hz is not None:
        power = np.abs(np.fft.rfft(centred)) ** 2
        freqs = np.fft.rfftfreq(n, d=1.0 / sample_rate_hz)
        if power.size > 1 and power[1:].sum() > 0:
            peak = 1 + int(np.argmax(power[1:]))
            frequency = float(freqs[peak])
            fraction = float(power[peak] / power[1:].sum())
    return TimeStats(
        lag1_autocorrelation=float(r[0]),
        ljung_box_q=q,
        ljung_box_p=float(stats.chi2.sf(q, lags)),
        lags=lags,
        dominant_frequency_hz=frequency,
        dominant_power_fraction=fraction,
    )


def analyse_residuals(
    residual: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    *,
    sample_rate_hz: float | None = None,
    bins: int = DEFAULT_BINS,
    series: np.ndarray | None = None,
    time_ordered: bool = True,
) -> ResidualReport:
    """Statistics of ``residual`` against each regressor and in time.

    Args:
        residual: 1-D array ``observed - predicted`` (output unit), in time order for the time
            statistics.
        regressors: name -> 1-D array aligned with ``residual``, in the regressor's SI unit.
        sample_rate_hz: sampling rate (Hz) of a uniformly sampled residual, for the dominant
            frequency; None leaves it out.
        bins: quantile bins per regressor (at least 2).
        series: the residual as a uniformly sampled time series for the time statistics
            (e.g. with samples out of the fit, such as lifts, set to 0), when ``residual``
            leaves samples out; default ``residual`` itself.
        time_ordered: whether the sample order is time order. When it is not (a table of
            steady-state points) the samples count as independent for the p-values.

    Raises:
        PredictorError: empty or non-finite residual or regressor, mismatched lengths, too few
            samples, a bad bin count or a non-positive sample rate.
    """
    r = np.asarray(residual, dtype=np.float64)
    if r.ndim != 1:
        raise PredictorError(f"residual must be a 1-D array, got shape {r.shape}")
    if r.size < 2 * MIN_BIN_COUNT:
        raise PredictorError(f"residual has {r.size} sample(s); need at least {2 * MIN_BIN_COUNT}")
    if not np.all(np.isfinite(r)):
        raise PredictorError(
            f"residual has {np.count_nonzero(~np.isfinite(r))} non-finite value(s) (NaN or inf)"
        )
    if bins < 2:
        raise PredictorError(f"bins must be at least 2, got {bins}")
    if sample_rate_hz is not None and not (
        math.isfinite(sample_rate_hz) and sample_rate_hz > 0
    ):
        raise PredictorError(f"sample_rate_hz must be positive and finite, got {sample_rate_hz}")
    in_time = r if series is None else np.asarray(series, dtype=np.float64)
    n_eff = effective_samples(in_time) * r.size / in_time.size if time_ordered else float(r.size)
    results: dict[str, RegressorStats] = {}
    for name, values in regressors.items():
        x = np.asarray(values, dtype=np.float64)
        if x.shape != r.shape:
            raise PredictorError(
                f"regressor {name} has shape {x.shape}, the residual has {r.shape}"
            )
        if not np.all(np.isfinite(x)):
            raise PredictorError(
                f"regressor {name} has {np.count_nonzero(~np.isfinite(x))} non-finite "
                "value(s) (NaN or inf)"
            )
        results[name] = _regressor_stats(name, r, x, bins, n_eff)
    time = _time_stats(in_time, sample_rate_hz)
    if time_ordered:
        time = replace(time, beyond_noise=ar1_block_test(r))
    return ResidualReport(
        n=r.size,
        rms=float(np.sqrt(np.mean(r**2))),
        regressors=results,
        time=time,
        effective_samples=n_eff,
    )


INTERACTION_BINS = 5
"""Quantile bins per regressor of the interaction test (:func:`interaction_structure`): 25
cells for a pair, each with enough samples for its mean."""


@dataclass(frozen=True)
class InteractionStats:
    """The residual's structure in the combination of two regressors beyond each alone.

    Attributes:
        names: the two regressors.
        eta2: share of the residual's variance that the cell means of the pair explain beyond
            the additive fit of their two one-way bin means (two-way ANOVA interaction sum of
            squares over the total).
        f_statistic: interaction F, ``(SS_int / df_int) / (SS_within / (n - cells))``.
        p_value: its p-value, corrected for autocorrelation like the one-way tests.
    """

    names: tuple[str, str]
    eta2: float
    f_statistic: float
    p_value: float


def interaction_structure(residual: np.ndarray, first: np.ndarray, second: np.ndarray,
                          names: tuple[str, str], n_eff: float,
                          bins: int = INTERACTION_BINS) -> InteractionStats:
    """Two-way ANOVA of ``residual`` on ``first`` x ``second`` binned (:func:`bin_labels`,
    ``bins`` each): the variance the pair's cells explain beyond the sum of their main effects
    (spec/calibration.md K28). A residual ``c (L - L_mean)(A - A_mean)`` has no structure
    against the load ``L`` or the amplitude ``A`` alone; its cells hold it all."""
    r = np.asarray(residual, dtype=np.float64)
    a = bin_labels(np.asarray(first, dtype=np.float64), bins)
    b = bin_labels(np.asarray(second, dtype=np.float64), bins)
    na, nb = int(a.max()) + 1, int(b.max()) + 1
    total = float(np.sum((r - r.mean()) ** 2))
    if na < 2 or nb < 2 or total <= 0:
        return InteractionStats(names, 0.0, 0.0, 1.0)
    cell = a * nb + b
    counts = np.bincount(cell, minlength=na * nb)
    sums = np.bincount(cell, weights=r, minlength=na * nb)
    means = sums / np.maximum(counts, 1)
    within = float(np.sum((r - means[cell]) ** 2))
    # the additive fit: one-hot of both factors (the first level of the second dropped)
    design = np.zeros((r.size, na + nb - 1))
    design[np.arange(r.size), a] = 1.0
    rows = np.flatnonzero(b > 0)
    design[rows, na + b[rows] - 1] = 1.0
    coef, *_ = np.linalg.lstsq(design, r, rcond=None)
    additive = float(np.sum((r - design @ coef) ** 2))
    cells = int(np.count_nonzero(counts))
    df_int = cells - (na + nb - 1)
    df_within = r.size - cells
    if df_int < 1 or df_within < 1:
        return InteractionStats(names, 0.0, 0.0, 1.0)
    ss_int = max(additive - within, 0.0)
    if within <= 0:
        return InteractionStats(names, ss_int / total, math.inf, 0.0)
    f_stat = (ss_int / df_int) / (within / df_within)
    scale = min(n_eff / r.size, 1.0)
    dof = max(n_eff - cells, 1.0)
    p_value = float(stats.f.sf(f_stat * scale, df_int, dof))
    return InteractionStats(names, ss_int / total, float(f_stat), p_value)


TIME_REGRESSORS = frozenset({"time", "contact_time", "occlusion_time"})
"""Regressors that order the recording in time, left out of the interaction test (K28):
structure in time is judged by the time tests (K10, K29), and a regressor blocked in time
(an amplitude held for a session) splits each time bin into shorter stretches of time, so a
trend in time reads as an interaction with it (eta2 0.35 for amplitude x time on a
residual whose structure was the trend)."""


def interactions(residual: np.ndarray, regressors: Mapping[str, np.ndarray], n_eff: float,
                 alpha: float, min_eta2: float) -> list[InteractionStats]:
    """Every pair of ``regressors`` (each varying, none of :data:`TIME_REGRESSORS`) whose
    interaction (:func:`interaction_structure`) is significant at ``alpha`` divided by the
    number of pairs (Bonferroni) and explains at least ``min_eta2`` of ``residual``'s
    variance, strongest first (K28)."""
    varying = [name for name, x in regressors.items()
               if name not in TIME_REGRESSORS and np.ptp(np.asarray(x)) > 0]
    pairs = [(p, q) for i, p in enumerate(varying) for q in varying[i + 1:]]
    if not pairs:
        return []
    level = alpha / len(pairs)
    found = [
        found_pair for p, q in pairs
        if (found_pair := interaction_structure(residual, regressors[p], regressors[q],
                                                (p, q), n_eff)).p_value < level
        and found_pair.eta2 >= min_eta2
    ]
    return sorted(found, key=lambda s: -s.eta2)


def linear_share(residual: np.ndarray, regressor: np.ndarray, effective: float
                 ) -> tuple[float, float]:
    """The share of ``residual``'s variance along a straight line in ``regressor`` (the
    squared Pearson correlation ``r^2``) and its two-sided p-value from the t-test of ``r``
    with ``effective`` independent samples; ``(0, 1)`` for a constant regressor or residual."""
    from scipy import stats  # here: scipy.stats costs ~0.6 s to import

    x = np.asarray(regressor, dtype=np.float64) - float(np.mean(regressor))
    y = np.asarray(residual, dtype=np.float64) - float(np.mean(residual))
    sxx, syy = float(np.dot(x, x)), float(np.dot(y, y))
    if sxx <= 0.0 or syy <= 0.0:
        return 0.0, 1.0
    r2 = min(float(np.dot(x, y)) ** 2 / (sxx * syy), 1.0)
    dof = max(effective - 2.0, 1.0)
    t2 = r2 * dof / max(1.0 - r2, 1e-300)
    return r2, float(stats.f.sf(t2, 1.0, dof))


def mostly_one_value(regressor: np.ndarray) -> bool:
    """Whether one value holds at least half of ``regressor``'s samples (a regressor that is
    mostly 0 with a tail of both signs, whose quantile bins merge)."""
    values = np.asarray(regressor, dtype=np.float64)
    if values.size == 0:
        return False
    _, counts = np.unique(values, return_counts=True)
    return 2 * int(counts.max()) >= values.size
