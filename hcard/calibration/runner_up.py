"""The final model of the calibration loop against its runner-up (spec/calibration.md).

The final model is compared with the best other fitted model of as many effects
(:mod:`hcard.calibration.selection`): the margin in ``H`` and in held-out RMSE is reported, and
when it is below :class:`~hcard.calibration.selection.Separation`'s thresholds the verdict is
:data:`~hcard.calibration.results.AMBIGUOUS`, naming the regressor along which the two
predictions differ most and the measurement that would spread it.

:func:`runner_up` finds the rival and compares (:func:`~hcard.calibration.selection.compare`);
:class:`RivalFigures` reads the pooled models' figures as bounds of their full fits, so that a
model fitted on the screening samples only (:mod:`hcard.calibration.screening`) is fitted in
full before any decision its screened figures could get wrong.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.model_pool import EffectSet, ModelPool, held_out_criterion
from hcard.calibration.residuals import effective_samples
from hcard.calibration.results import LoopSettings, ModelFit
from hcard.calibration.screening import SCREEN_TOLERANCE, criterion_band
from hcard.calibration.selection import Comparison, compare


class RivalFigures:
    """The criterion and held-out RMSE of the pooled models of one size, read as bounds of their
    full fits (a screened model's lie within the screening tolerance of its scaled figures),
    against the final model, at the final model's effective held-out sample count."""

    def __init__(self, final: ModelFit, pool: ModelPool, settings: LoopSettings) -> None:
        """``final``: the loop's final model; ``pool``: every model fitted; ``settings``: the
        thresholds of earning a place and of separation."""
        self.final = final
        self.pool = pool
        self.settings = settings
        self.size = max(len(final.effects), 1)
        self.own = frozenset(final.effects)
        self.n_eff = effective_samples(final.fit.residuals[final.fit.test])
        self.band = criterion_band(self.n_eff)
        self.final_score = held_out_criterion(final.fit, self.n_eff)

    def score(self, key: EffectSet) -> tuple[float, float, float]:
        """``H`` of the pooled model ``key``, and the bounds within which its full fit's
        lies."""
        value = self.pool.criterion(key, self.n_eff)
        spread = self.band if key in self.pool.screened else 0.0
        return value, value - spread, value + spread

    def rmse(self, key: EffectSet) -> tuple[float, float]:
        """Bounds of the held-out RMSE of the pooled model ``key`` fitted in full (output
        unit)."""
        value = self.pool.held_out(key)
        spread = SCREEN_TOLERANCE if key in self.pool.screened else 0.0
        return value * (1.0 - spread), value * (1.0 + spread)

    def settle(self, keys: Sequence[EffectSet]) -> None:
        """Fit the screened ones of ``keys`` on every training sample (failures leave the
        pool)."""
        for key in keys:
            if key in self.pool.screened and key in self.pool.fits:
                self.pool.confirmed(key)

    def earns(self, key: EffectSet) -> bool | None:
        """Whether every effect of ``key`` earns its place against the pooled model without
        it (lower ``H``, held-out RMSE ``min_improvement`` lower; no verdict where the model
        without it was not fitted); None when a full fit could decide otherwise."""
        _, low, high = self.score(key)
        fall, rise = self.rmse(key)
        verdict: bool | None = True
        for name in key:
            smaller = key - {name}
            if smaller not in self.pool.fits:
                continue
            _, small_low, small_high = self.score(smaller)
            small_fall, small_rise = self.rmse(smaller)
            floor = self.settings.min_improvement
            if low >= small_high or not (1.0 - fall / small_rise >= floor):
                return False
            if high >= small_low or not (1.0 - rise / small_fall >= floor):
                verdict = None
        return verdict

    def rivals(self) -> list[EffectSet]:
        """The pooled models with as many effects as the final one (one for the base), other
        than it."""
        return [key for key in self.pool.fits if len(key) == self.size and key != self.own]

    def may_be_close(self, key: EffectSet) -> bool:
        """Whether the full fit of ``key`` may lie within the separation thresholds."""
        settings = self.settings
        return (self.score(key)[1] - self.final_score < settings.separation_criterion
                or self.rmse(key)[0] / self.final.test_rmse - 1.0 < settings.separation_rmse)


def runner_up(final: ModelFit, pool: ModelPool, data: CalibrationData,
              settings: LoopSettings) -> Comparison | None:
    """The final model against its runner-up: the best other fitted model with as many effects
    (one effect when the final model has none) in which every effect earns its place (lowers
    ``H`` and cuts the held-out RMSE by ``min_improvement`` against the same model without it,
    where that was fitted; a pair of a real effect and one left at its neutral values is the
    single effect again, not a rival), else the best of them all; both scored at the final
    model's effective held-out sample count (:mod:`hcard.calibration.selection`). None when
    ``pool`` holds no rival.

    Models of ``pool`` fitted on the screening samples only are fitted on every training
    sample (:meth:`~hcard.calibration.model_pool.ModelPool.confirmed`) before any decision a
    screened figure could get wrong by :data:`SCREEN_TOLERANCE` (:class:`RivalFigures`):
    whether a rival earns its place, and, when some rival may come within the separation
    thresholds of the final model, which rival is best. When none can (or the final model is
    the base model, whose comparison decides nothing), the comparison is not ambiguous
    whichever rival it is: the runner-up is the rival of lowest ``H`` taking screened figures
    as they are, fitted in full, and fitted again while another screened rival looks better
    than its full fit. It is the runner-up without screening, or a rival whose ``H`` lies
    within the tolerance band (:func:`~hcard.calibration.screening.criterion_band`) of it."""
    figures = RivalFigures(final, pool, settings)
    for key in figures.rivals():
        if key in pool.fits and figures.earns(key) is None:
            figures.settle([key, *(key - {name} for name in key)])
    if not figures.rivals():
        return None
    admissible = [key for key in figures.rivals() if figures.earns(key)]
    best = _best_rival(figures, admissible or figures.rivals())
    if best is None:
        return None
    effects, rival = pool.fits[best]
    used = data.used
    observed = data.observed[used]
    return compare(
        final.effects,
        figures.final_score,
        final.test_rmse,
        observed - final.fit.residuals[used],
        tuple(e.name for e in effects),
        held_out_criterion(rival, figures.n_eff),
        float(rival.test_rmse or math.nan),
        observed - rival.residuals[used],
        {name: values[used] for name, values in data.regressors.items()},
        settings.separation(),
        settings.bins,
        decides=bool(final.effects),
    )


def _best_rival(figures: RivalFigures, candidates: list[EffectSet]) -> EffectSet | None:
    """The rival of ``candidates`` of lowest ``H``. When a rival may make the comparison
    ambiguous, by full fits: every screened one whose full fit may beat the best is fitted on
    every training sample. Else the best taking screened figures as they are, fitted in full,
    again while another screened one looks better. None when every fit failed."""
    pool = figures.pool
    exact = bool(figures.final.effects) and any(figures.may_be_close(key)
                                                for key in candidates)
    while True:
        candidates = [key for key in candidates if key in pool.fits]
        if not candidates:
            return None
        best = min(candidates, key=lambda k: figures.score(k)[0])
        doubtful = [key for key in candidates if key in pool.screened and (
            figures.score(key)[1] < figures.score(best)[2] if exact else key == best)]
        if not doubtful:
            return best
        figures.settle(doubtful)


def judged_within(comparison: Comparison, final: ModelFit, pool: ModelPool,
                  data: CalibrationData, settings: LoopSettings, within: np.ndarray
                  ) -> Comparison:
    """``comparison`` (the final model against its runner-up) judged again on the samples
    ``within`` alone: the separating experiment's recordings (spec/calibration.md K34), where
    the two models' predictions differ by design. Over every recording the margin of RMSE is
    diluted by the samples where the two agree (the hidden air layer against the pad's
    flattening: ``H`` +755 but RMSE +0.2 % over protocol and experiment together); on the
    experiment's held-out samples it is the difference the experiment was made to show. ``H``
    of both at the final model's effective sample count there. ``comparison`` itself when the
    runner-up was not fitted on every sample or ``within`` holds no held-out sample."""
    rival = pool.fits.get(frozenset(comparison.runner_up))
    test = final.fit.test & within
    if rival is None or frozenset(comparison.runner_up) in pool.screened or not test.any():
        return comparison
    _, fit = rival
    n_eff = effective_samples(final.fit.residuals[test])

    def figures(residuals: np.ndarray, n_free: int) -> tuple[float, float]:
        mse = float(np.mean(residuals[test] ** 2))
        return (n_eff * math.log(max(mse, np.finfo(float).tiny)) + 2 * n_free,
                math.sqrt(mse))

    final_h, final_rmse = figures(final.fit.residuals, final.fit.n_free)
    rival_h, rival_rmse = figures(fit.residuals, fit.n_free)
    used = data.used & within
    observed = data.observed[used]
    return compare(
        comparison.chosen, final_h, final_rmse, observed - final.fit.residuals[used],
        comparison.runner_up, rival_h, rival_rmse, observed - fit.residuals[used],
        {name: values[used] for name, values in data.regressors.items()},
        settings.separation(), settings.bins, decides=bool(final.effects),
    )
