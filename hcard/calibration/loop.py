"""The calibration loop: fit, analyse the residual, add the effect that explains it, repeat
(spec/calibration.md).

:func:`calibrate` fits a base predictor (wrapped to output the measured lateral force,
:mod:`hcard.calibration.observation`) to a :class:`~hcard.calibration.dataset.CalibrationData`
on its training split, then repeats:

1. analyse the residual of the current model against every regressor
   (:func:`~hcard.calibration.residuals.analyse_residuals`);
2. for every library effect not yet in the model that can augment it, whose signature
   regressors vary in the data: fit the model with that effect added (all the base's
   calibrated parameters, the observation parameters and the effect's own parameters free,
   starting from the current fit) and compute its held-out error;
3. accept the candidate with the lowest penalised held-out score if it passes the criterion
   (:mod:`hcard.calibration.judges`); otherwise stop;
4. let the selection undo itself: with two effects in the model, score every
   pair of the library's usable effects and move to the best pair by ``H``; with more, try
   removing each accepted effect and swapping it for each unused one (a move never brings in
   an effect whose signature's structure a dominant foreign regressor explains, see (c) of
   the criterion); then drop any effect that no longer earns its place (lower ``H`` and
   ``min_improvement`` of held-out RMSE against the same model without it). Greedy addition
   alone named skin-recovery + load-index at 5.40 mN where occlusion + load-index, in the
   library, reached the truth's 5.01 mN.

**Steps.** :func:`calibrate` checks its arguments
(:func:`~hcard.calibration.judges.check_arguments`), sorts the library
(:func:`~hcard.calibration.judges.usable_effects`,
:func:`~hcard.calibration.judges.claimed_regressors`) and fits every model once through a
:class:`~hcard.calibration.model_pool.ModelPool` (screening included). A round
(:meth:`EffectSearch.run_round`) fits each remaining effect added to the current model
(:meth:`EffectSearch.try_candidates`), fits in full those near the threshold
(:meth:`EffectSearch.settle_near_target`), scores them at the best residual's ``n_eff``
(:meth:`EffectSearch.rescored`), decides (:func:`~hcard.calibration.judges.judge_round`,
:func:`~hcard.calibration.judges.criterion_failure`) and lets the selection undo itself
(:meth:`EffectSearch.revise`: :func:`alternative_sets`, a move to a credited set,
:meth:`EffectSearch.prune` with :func:`~hcard.calibration.judges.earns_place`). The end: what
structure is left (:func:`~hcard.calibration.judges.residual_structure`), the runner-up
(:func:`~hcard.calibration.runner_up.runner_up`), :func:`~hcard.calibration.judges.verdict_of`
and :func:`~hcard.calibration.summary.summarise`.

**Screening** (:mod:`hcard.calibration.screening`). Candidate models (steps 2 and 4) are first
fitted on one training sample in ``k`` (about ``screen_samples`` of them); one whose screened
figures come within :data:`~hcard.calibration.screening.SCREEN_TOLERANCE` of a threshold of the
criterion, or of a rival it must be ranked against, is fitted again on every training sample,
from the same start, before the loop decides on it. The effects chosen, the verdict and every
accepted model's fit are those the loop reaches without screening (``screen_samples = 0``), and
so is the runner-up whenever it may come within the separation thresholds of the final model;
the figures of candidates far from every decision are the screened fits' (marked in the
candidate table), and among rivals far from the final model the one named runner-up may be
another within the tolerance of the best (:func:`~hcard.calibration.runner_up.runner_up`).

**Modules.** The thresholds and everything the loop returns: :mod:`hcard.calibration.results`;
the criterion, the structure left and the verdicts: :mod:`hcard.calibration.judges`; the runner-up:
:mod:`hcard.calibration.runner_up`; the summary paragraph: :mod:`hcard.calibration.summary`.
This module holds the search itself: :func:`calibrate`, its rounds (:class:`EffectSearch`)
and :func:`with_bootstrap`.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from hcard.calibration.bootstrap import stroke_bootstrap
from hcard.calibration.dataset import CalibrationData
from hcard.calibration.fit import FitResult
from hcard.calibration.judges import (
    beyond_foreign_structure,
    check_arguments,
    claimed_regressors,
    earns_place,
    judge_round,
    noise_aware,
    residual_structure,
    usable_effects,
    verdict_of,
)
from hcard.calibration.model_pool import (
    EffectSet,
    ModelPool,
    held_out_criterion,
)
from hcard.calibration.noise import detectable_eta2
from hcard.calibration.residuals import (
    MIN_BIN_COUNT,
    ResidualReport,
    analyse_residuals,
    effective_samples,
)
from hcard.calibration.results import (
    CalibrationResult,
    Candidate,
    LoopSettings,
    ModelFit,
    fitted_figure,
    format_error,
)
from hcard.calibration.runner_up import judged_within, runner_up
from hcard.calibration.screening import (
    SCREEN_TOLERANCE,
    criterion_band,
    may_fall_to,
    screening_mask,
)
from hcard.calibration.summary import summarise
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect

Progress = Callable[[str], None]


class ResidualAnalyser:
    """The residual analysis of a fit on the samples in contact of one
    :class:`~hcard.calibration.dataset.CalibrationData` (:func:`~hcard.calibration.residuals.
    analyse_residuals` against every regressor, with ``bins`` quantile bins; in time on the
    recording's own sample grid, 0 where not fitted)."""

    def __init__(self, data: CalibrationData, bins: int) -> None:
        self.data = data
        self.bins = bins
        self.used = data.used
        self.regressors = {name: values[self.used] for name, values in data.regressors.items()}

    def __call__(self, result: FitResult) -> ResidualReport:
        """The analysis of ``result``'s residuals (output unit) on the samples in contact."""
        return analyse_residuals(
            result.residuals[self.used],
            self.regressors,
            sample_rate_hz=self.data.sample_rate_hz,
            bins=self.bins,
            series=np.where(self.used, result.residuals, 0.0),
            time_ordered=self.data.time_ordered,
        )


def alternative_sets(
    chosen: Sequence[Effect], usable: Sequence[Effect], size: int
) -> tuple[list[list[Effect]], str]:
    """The sets of effects a revision of ``chosen`` scores, and how they were formed (the
    candidate table's note): for a ``size`` of one or two, every set of that size of the
    ``usable`` effects (library order); else every swap of one effect of ``chosen`` for an
    unused one."""
    if size <= 2:
        alternatives = [list(group) for group in itertools.combinations(usable, size)]
        return alternatives, f"{'pair' if size == 2 else 'swap'}, every one of the library scored"
    alternatives = [
        [*(e for e in chosen if e is not out), swap]
        for out in chosen
        for swap in usable
        if swap not in chosen
    ]
    return alternatives, "swap of one accepted effect for an unused one"


class EffectSearch:
    """The rounds of the loop on one base model: the state they share (the pool of fitted
    models, the effects added, the current model, the accepted models and the candidate table)
    and one method per step of a round."""

    def __init__(self, data: CalibrationData, pool: ModelPool, usable: Sequence[Effect],
                 claimed: frozenset[str], settings: LoopSettings, analyse: ResidualAnalyser,
                 say: Callable[[str], None], unit: str) -> None:
        self.data = data
        self.pool = pool
        self.usable = list(usable)
        self.claimed = claimed
        self.settings = settings
        self.analyse = analyse
        self.say = say
        self.unit = unit
        first = pool.fit_base()
        n_eff = effective_samples(first.residuals[first.test])
        self.current = ModelFit((), first, analyse(first), held_out_criterion(first, n_eff))
        self.steps = [self.current]
        self.added: list[Effect] = []
        self.candidates: list[Candidate] = []
        self.visited: set[EffectSet] = {frozenset()}

    def credited(self, effect: Effect, effects: Sequence[Effect]) -> bool:
        """Whether ``effect`` may come into the set ``effects`` by a move: not when a dominant
        foreign regressor explains its signature's structure in the residual of the set
        without it (:func:`~hcard.calibration.judges.beyond_foreign_structure`). A move
        judged by ``H`` alone may otherwise bring in a signature that shows little structure
        at low power (a load index over a few force levels)."""
        without = self.pool.fitted_set([e for e in effects if e is not effect], exact=True)
        if without is None:
            return False
        eta2, foreign = beyond_foreign_structure(
            effect, self.analyse(without), without.residuals[self.analyse.used],
            self.analyse.regressors, self.claimed, self.settings)
        return foreign is None or eta2 >= self.settings.signature_eta2

    def selection_test(self, effect: Effect, model: ModelFit) -> tuple[float, bool]:
        """K9 (c) for ``effect`` entering ``model`` (spec/calibration.md K27), the one test of
        every path that adds an effect (a round's single candidate, a pair, a swap): the share
        of ``model``'s residual against the effect's signature, foreign structure taken out
        (:func:`~hcard.calibration.judges.beyond_foreign_structure`), and whether it reaches
        ``signature_eta2``."""
        eta2, _ = beyond_foreign_structure(effect, model.analysis,
                                           model.fit.residuals[self.analyse.used],
                                           self.analyse.regressors, self.claimed,
                                           self.settings)
        return eta2, eta2 >= self.settings.signature_eta2

    def refused_by_move_test(self, effect: Effect, effects: Sequence[Effect],
                             reference: ModelFit) -> bool:
        """Whether a move to the set ``effects`` must leave out its new ``effect``
        (spec/calibration.md K27): the effect shows no structure against its signature
        (:meth:`selection_test`) on the residual of the round's model ``reference``, nor on
        the residual of ``effects`` without it (the model it enters: two effects that cancel
        show their structures only one at a time), while at least one of those two tests had
        the power to see it: its F-test over the signature's bins detects ``min_eta2`` with
        80 % power at that residual's ``n_eff`` (:func:`~hcard.calibration.noise.
        detectable_eta2`). A signature test without that power (a load index over a few force
        levels, a residual correlated over whole strokes) is no evidence of absence; the move
        is then judged by ``H`` and :meth:`credited`. The set without ``effect`` that is not
        fitted counts as a test that saw nothing without power."""
        without = self.pool.fitted_set([e for e in effects if e is not effect], exact=True)
        seen = [(reference.analysis, reference.fit.residuals[self.analyse.used])]
        if without is not None:
            seen.append((self.analyse(without), without.residuals[self.analyse.used]))
        powered = False
        for analysis, residual in seen:
            eta2, _ = beyond_foreign_structure(effect, analysis, residual,
                                               self.analyse.regressors, self.claimed,
                                               self.settings)
            if eta2 >= self.settings.signature_eta2:
                return False
            powered = powered or any(
                detectable_eta2(analysis.effective_samples,
                                int(np.count_nonzero(
                                    analysis.regressors[name].bin_counts >= MIN_BIN_COUNT)),
                                self.settings.alpha) <= self.settings.min_eta2
                for name in effect.signature if name in analysis.regressors)
        return powered

    def returns_to_own(self, key: EffectSet, own: EffectSet, n_eff: float) -> bool:
        """Whether a move from the set ``own`` (fitted in full) to the screened set ``key``
        would be undone by the pruning that follows it, whatever ``key``'s full fit: ``key``
        is ``own`` plus one effect whose held-out RMSE cannot fall by ``min_improvement``
        against ``own``'s (it does not earn its place), while with ``own``'s single effect
        the set beats that effect alone by ``H`` and by ``min_improvement`` for certain (it
        earns its place), all within the screening tolerance."""
        pool, settings = self.pool, self.settings
        extra = key - own
        alone = frozenset(extra)
        if len(own) != 1 or not own < key or len(extra) != 1 or alone not in pool.fits:
            return False
        rmse = pool.held_out(key)
        if may_fall_to(rmse, (1.0 - settings.min_improvement) * pool.held_out(own)):
            return False
        spread = SCREEN_TOLERANCE if alone in pool.screened else 0.0
        other_low = pool.criterion(alone, n_eff) - (criterion_band(n_eff) if spread else 0.0)
        if not pool.criterion(key, n_eff) + criterion_band(n_eff) < other_low:
            return False
        gain = 1.0 - rmse * (1.0 + SCREEN_TOLERANCE) / (pool.held_out(alone) * (1.0 - spread))
        return gain >= settings.min_improvement

    def revise(self, round_number: int, chosen: list[Effect], reference: ModelFit,
               size: int) -> list[Effect]:
        """The best set of ``size`` effects near ``chosen`` (:func:`alternative_sets`), when
        it beats ``chosen`` by ``H``; then any effect that no longer earns its place against
        the same set without it is dropped (:meth:`prune`). ``n_eff`` is that of the better of
        ``reference`` and ``chosen``'s held-out residual; ``reference`` (the round's current
        model) sets the changes shown in the candidate table."""
        pool, data = self.pool, self.data
        chosen = list(chosen)
        n_eff = max(
            effective_samples(reference.fit.residuals[data.test]),
            effective_samples(
                pool.fits[frozenset(e.name for e in chosen)][1].residuals[data.test]),
        )
        alternatives, note = alternative_sets(chosen, self.usable, size)
        scores, fresh = self._score_sets(alternatives, n_eff)
        own = frozenset(e.name for e in chosen)
        own_score = held_out_criterion(pool.fits[own][1], n_eff)
        stay = self._confirm_doubtful(scores, fresh, own, own_score, n_eff)
        self._record_sets(round_number, scores, fresh, reference, note, n_eff)
        if not stay:
            chosen = self._move(round_number, chosen, scores, own, own_score, reference)
        return self.prune(round_number, chosen, n_eff)

    def _score_sets(
        self, alternatives: Sequence[Sequence[Effect]], n_eff: float
    ) -> tuple[dict[EffectSet, tuple[Sequence[Effect], FitResult, float]],
               list[tuple[EffectSet, float]]]:
        """Every set of ``alternatives`` fitted (from the pool, else now, screened) and scored
        by ``H`` at ``n_eff``: set -> (effects, fit, H), and the sets fitted now with the wall
        time of their fits, s. A set whose fit fails is left out."""
        scores = {}
        fresh: list[tuple[EffectSet, float]] = []
        for effects in alternatives:
            key = frozenset(e.name for e in effects)
            tic = time.perf_counter()
            known = key in self.pool.fits
            result = self.pool.fitted_set(effects)
            if result is None:
                continue
            scores[key] = (effects, result, self.pool.criterion(key, n_eff))
            if not known:
                fresh.append((key, time.perf_counter() - tic))
        return scores, fresh

    def _confirm_doubtful(
        self,
        scores: dict[EffectSet, tuple[Sequence[Effect], FitResult, float]],
        fresh: list[tuple[EffectSet, float]],
        own: EffectSet,
        own_score: float,
        n_eff: float,
    ) -> bool:
        """Fit on every training sample each screened set of ``scores`` that may beat the
        current set ``own`` (``H`` ``own_score``), updating ``scores`` (a failed fit leaves)
        and the seconds of ``fresh`` in place, unless every such set is ``own`` plus an effect
        that pruning would take out again (:meth:`returns_to_own`): then returns True, the
        current set stays."""
        pool = self.pool
        band = criterion_band(n_eff)
        doubtful = [key for key, (_, _, score) in scores.items()
                    if key in pool.screened and score - band < own_score]
        better = [key for key, (_, _, score) in scores.items()
                  if key not in pool.screened and key != own and score < own_score]
        stay = (bool(doubtful) and not better
                and all(self.returns_to_own(key, own, n_eff) for key in doubtful))
        if stay:
            return stay
        # confirming one set refits only it and its subsets, never another set of scores
        for key in doubtful:
            effects = scores[key][0]
            tic = time.perf_counter()
            exact = pool.confirmed(key)
            if exact is None:
                del scores[key]
            else:
                scores[key] = (effects, exact, held_out_criterion(exact, n_eff))
            fresh[:] = [(k, t + time.perf_counter() - tic if k == key else t)
                        for k, t in fresh]
        return stay

    def _record_sets(
        self,
        round_number: int,
        scores: Mapping[EffectSet, tuple[Sequence[Effect], FitResult, float]],
        fresh: Sequence[tuple[EffectSet, float]],
        reference: ModelFit,
        note: str,
        n_eff: float,
    ) -> None:
        """A row of the candidate table for every set first fitted in this revision
        (``fresh``, with its seconds), its changes against ``reference``."""
        for key, seconds in fresh:
            if key not in scores:
                continue
            effects, _result, score = scores[key]
            rmse = self.pool.held_out(key)
            self.say(f"round {round_number}: {' + '.join(sorted(key))}: held-out RMSE "
                     f"{format_error(rmse, self.unit)}"
                     f"{' (screened)' if key in self.pool.screened else ''}")
            self.candidates.append(
                Candidate(round_number, " + ".join(e.name for e in effects), rmse,
                          1.0 - rmse / reference.test_rmse,
                          score - held_out_criterion(reference.fit, n_eff),
                          sum(len(e.parameters) for e in effects), 0.0, False,
                          note, seconds, screened=key in self.pool.screened)
            )

    def _move(
        self,
        round_number: int,
        chosen: list[Effect],
        scores: Mapping[EffectSet, tuple[Sequence[Effect], FitResult, float]],
        own: EffectSet,
        own_score: float,
        reference: ModelFit,
    ) -> list[Effect]:
        """The set of ``scores`` of lowest ``H`` below ``own_score`` whose every new effect
        is not refused by the selection test (:meth:`refused_by_move_test`, K27: the test a
        round applies to a single candidate, on the ``reference`` model's residual and on that
        of the set without the effect) and is :meth:`credited` (``chosen`` when there is
        none)."""
        for key in sorted(scores, key=lambda k: scores[k][2]):
            if key == own or scores[key][2] >= own_score:
                break
            effects = scores[key][0]
            refused = [e.name for e in effects
                       if e not in chosen and e not in self.added
                       and self.refused_by_move_test(e, effects, reference)]
            if refused:
                self.say(f"round {round_number}: not moved to {' + '.join(sorted(key))}: the "
                         f"residual shows no structure against the signature of "
                         f"{', '.join(refused)} (K27)")
                continue
            uncredited = [e.name for e in effects
                          if e not in chosen and not self.credited(e, effects)]
            if uncredited:
                self.say(f"round {round_number}: not moved to {' + '.join(sorted(key))}: the "
                         f"structure against the signature of {', '.join(uncredited)} is a "
                         "foreign regressor's")
                continue
            chosen = list(effects)
            self.say(f"round {round_number}: moved to {' + '.join(e.name for e in chosen)}")
            break
        return chosen

    def prune(self, round_number: int, chosen: list[Effect], n_eff: float) -> list[Effect]:
        """``chosen`` without the effects that do not earn their place
        (:func:`~hcard.calibration.judges.earns_place` at ``n_eff``), taken out one at a time,
        the one whose removal leaves the lowest ``H`` first."""
        pool = self.pool
        while chosen:
            whole = pool.confirmed(frozenset(e.name for e in chosen))
            assert whole is not None  # the set moved to, or a subset that earned its place
            reasons = {}
            for effect in chosen:
                without = pool.fitted_set([e for e in chosen if e is not effect], exact=True)
                if without is not None:
                    why = earns_place(whole, without, n_eff, self.settings.min_improvement)
                    if why:
                        reasons[effect.name] = (why, held_out_criterion(without, n_eff))
            if not reasons:
                break
            weakest = min(reasons, key=lambda name: reasons[name][1])
            chosen = [e for e in chosen if e.name != weakest]
            self.say(f"round {round_number}: removed {weakest}: {reasons[weakest][0]}")
        return chosen

    def _key_with(self, name: str) -> EffectSet:
        """The effect set of the current model plus the effect ``name``."""
        return frozenset([*(e.name for e in self.added), name])

    def try_candidates(self, round_number: int, remaining: Sequence[Effect], n_eff: float,
                       current_score: float) -> list[tuple[Candidate, FitResult | None]]:
        """Each effect of ``remaining`` added to the current model and fitted (screened where
        it may be), with its row of the candidate table: held-out RMSE (N for a lateral
        force), its relative fall, the change of ``H`` at ``n_eff`` against
        ``current_score``, and the current residual's structure against its signature
        (:func:`~hcard.calibration.judges.beyond_foreign_structure`); a failed fit gives a
        row without figures."""
        current, pool = self.current, self.pool
        tried: list[tuple[Candidate, FitResult | None]] = []
        for effect in remaining:
            eta2, _ = self.selection_test(effect, current)
            tic = time.perf_counter()
            key = self._key_with(effect.name)
            try:
                result = pool.fits[key][1] if key in pool.fits \
                    else pool.screen_with(self.added, effect, current.fit)
            except PredictorError as exc:
                tried.append((Candidate(round_number, effect.name, None, None, None,
                                        len(effect.parameters), eta2, False,
                                        f"fit failed: {exc}", time.perf_counter() - tic),
                              None))
                self.say(f"round {round_number}: {effect.name}: fit failed ({exc})")
                continue
            rmse = pool.held_out(key)
            gain = 1.0 - rmse / current.test_rmse
            change = pool.criterion(key, n_eff) - current_score
            tried.append((Candidate(round_number, effect.name, rmse, gain, change,
                                    len(effect.parameters), eta2, False, "",
                                    time.perf_counter() - tic),
                          result))
            self.say(
                f"round {round_number}: {effect.name}: held-out RMSE "
                f"{format_error(rmse, self.unit)} ({-100 * gain:+.1f} %)"
                f"{', screened' if key in pool.screened else ''}"
            )
        return tried

    def settle_near_target(self, tried: list[tuple[Candidate, FitResult | None]],
                           round_number: int, n_eff: float, current_score: float) -> None:
        """Fit on every training sample, in place, each screened candidate of ``tried``
        whose held-out RMSE may fall by ``min_improvement`` once so fitted. The round's
        ``n_eff`` comes from the best-fitting candidate's residual: when some candidate may
        pass, that one is then a full fit too, for every candidate left screened lies above
        the target by more than the tolerance."""
        target = (1.0 - self.settings.min_improvement) * self.current.test_rmse
        for index, (cand, result) in enumerate(tried):
            screened = result is not None and self._key_with(cand.effect) in self.pool.screened
            if screened and may_fall_to(float(fitted_figure(cand.test_rmse)), target):
                self._settle(tried, index, round_number, n_eff, current_score)

    def _settle(self, tried: list[tuple[Candidate, FitResult | None]], index: int,
                round_number: int, n_eff: float, current_score: float) -> None:
        """Fit the screened candidate ``tried[index]`` of the current round on every training
        sample; its row takes the full fit's figures (or says the fit failed)."""
        cand = tried[index][0]
        key = self._key_with(cand.effect)
        tic = time.perf_counter()
        exact = self.pool.confirmed(key)
        seconds = cand.seconds + time.perf_counter() - tic
        if exact is None:
            tried[index] = (replace(cand, test_rmse=None, improvement=None, score_change=None,
                                    seconds=seconds,
                                    note=f"fit failed: {self.pool.failures.get(key, '')}"),
                            None)
            return
        rmse = float(exact.test_rmse or math.nan)
        gain = 1.0 - rmse / self.current.test_rmse
        tried[index] = (replace(cand, test_rmse=rmse, improvement=gain,
                                score_change=held_out_criterion(exact, n_eff) - current_score,
                                seconds=seconds), exact)
        self.say(f"round {round_number}: {cand.effect}: held-out RMSE "
                 f"{format_error(rmse, self.unit)} ({-100 * gain:+.1f} %) on every training "
                 "sample")

    def rescored(self, tried: list[tuple[Candidate, FitResult | None]], n_eff: float
                 ) -> tuple[list[tuple[Candidate, FitResult | None]], float]:
        """The round's candidates and effective sample count, from the best-fitting of the
        current model and the candidates. The current residual of a model that lacks a strong
        effect is correlated over whole strokes (``n_eff`` ~ 1), and ``H`` then weighs only
        the parameter count; the candidates are scored again at the better residual's
        ``n_eff``."""
        fitted = [item for item in tried if item[1] is not None]
        best_mse = min(fitted, key=lambda item: item[0].test_rmse or math.inf, default=None)
        if best_mse is None or best_mse[1] is None:
            return tried, n_eff
        wider = effective_samples(best_mse[1].residuals[best_mse[1].test])
        if wider <= n_eff:
            return tried, n_eff
        current_score = held_out_criterion(self.current.fit, wider)
        return [
            (replace(cand, score_change=None if result is None
                     else self.pool.criterion(self._key_with(cand.effect), wider)
                     - current_score), result)
            for cand, result in tried
        ], wider

    def accept(self, effects: Sequence[Effect], result: FitResult, n_eff: float) -> None:
        """Make the model with ``effects`` (fitted as ``result``) the current one, and an
        accepted step."""
        self.added[:] = effects
        self.current = ModelFit(tuple(e.name for e in self.added), result,
                                self.analyse(result), held_out_criterion(result, n_eff))
        self.steps.append(self.current)

    def run_round(self, round_number: int) -> bool:
        """One round: try every remaining effect, add the one that passes the criterion
        (:func:`~hcard.calibration.judges.judge_round`) and revise the set (:meth:`revise`),
        or, with none passing, try the pairs; False when the loop stops."""
        remaining = [e for e in self.usable if e not in self.added]
        if not remaining:
            return False
        current, settings = self.current, self.settings
        n_eff = effective_samples(current.fit.residuals[current.fit.test])
        current_score = held_out_criterion(current.fit, n_eff)
        tried = self.try_candidates(round_number, remaining, n_eff, current_score)
        self.settle_near_target(tried, round_number, n_eff, current_score)
        tried, n_eff = self.rescored(tried, n_eff)
        accepted_name, rows = judge_round([(c, r is not None) for c, r in tried], settings)
        self.candidates += [replace(row, screened=self._key_with(row.effect) in
                                    self.pool.screened) for row in rows]
        if accepted_name is None:
            return self._try_pairs(round_number, n_eff)
        effect = next(e for e in remaining if e.name == accepted_name)
        result = next(r for c, r in tried if c.effect == accepted_name)
        # a candidate that passes was fitted on every training sample (may_fall_to)
        assert result is not None and self._key_with(effect.name) not in self.pool.screened
        self.added.append(effect)
        self.say(f"round {round_number}: added {effect.name}")
        revised = self.revise(round_number, self.added, current, len(self.added))
        key = frozenset(e.name for e in revised)
        if revised != self.added:
            result = self.pool.confirmed(key)
            assert result is not None  # revise moves only to sets fitted on every sample
        self.accept(revised, result, n_eff)
        if key in self.visited:
            return False  # the revision went back to a model already accepted: nothing new
        self.visited.add(key)
        return True

    def _try_pairs(self, round_number: int, n_eff: float) -> bool:
        """No single addition pays. Two effects whose errors cancel in part can each fail
        alone and still explain the data together: with structure left and fewer than two
        effects in the model, every pair is scored and the best taken (:meth:`revise`);
        False when the loop stops."""
        settings, data = self.settings, self.data
        if len(self.added) >= 2 or len(self.usable) < 2 or not residual_structure(
            self.current.analysis, settings, data.time_ordered, data.noise
        ).any:
            return False
        revised = self.revise(round_number, list(self.added), self.current, 2)
        key = frozenset(e.name for e in revised)
        if len(revised) <= len(self.added) or key in self.visited:
            return False
        result = self.pool.confirmed(key)
        assert result is not None  # revise moves only to sets fitted on every sample
        self.accept(revised, result, n_eff)
        self.visited.add(key)
        self.say(f"round {round_number}: added the pair {' + '.join(self.current.effects)}")
        return True


def calibrate(
    data: CalibrationData,
    base: Predictor,
    library: Sequence[Effect],
    *,
    free: Sequence[str] | None = None,
    settings: LoopSettings | None = None,
    progress: Progress | None = None,
    observation: str = "lateral_force",
    separating: np.ndarray | None = None,
) -> CalibrationResult:
    """Run the calibration loop (module docstring) and return what it found.

    Args:
        data: prepared recordings with a held-out split
            (:func:`~hcard.calibration.dataset.prepare`).
        base: the model to calibrate (any predictor whose output is a relative friction, an
            electrostatic force or a lateral force).
        library: the candidate effects (e.g. every registered calibration effect).
        free: base parameters to fit (default :func:`~hcard.calibration.judges.default_free`).
        settings: thresholds (default :class:`LoopSettings`).
        progress: called with one line of text per fit.
        observation: what ``data.observed`` is
            (:data:`~hcard.calibration.results.OBSERVATIONS`): the lateral force, N (default),
            or the model's own output in its unit.
        separating: mask of the samples of separating experiments (spec/calibration.md K34):
            the final model and its runner-up are judged on them
            (:func:`~hcard.calibration.runner_up.judged_within`).

    Raises:
        PredictorError: an unusable base model, unknown free parameters, no held-out samples,
            or a base fit that fails.
    """
    settings = settings or LoopSettings()
    started = time.perf_counter()
    base_free = check_arguments(data, base, free, observation)
    say = progress or (lambda _text: None)
    unit = "N" if observation == "lateral_force" else base.output.unit
    usable, skipped = usable_effects(library, base, data.regressors)
    pool = ModelPool(data, base, base_free, observation,
                     screening_mask(data.train, settings.screen_samples), say)
    say(f"fitting {base.name} on {int(data.train.sum())} training samples")
    search = EffectSearch(data, pool, usable, claimed_regressors(base, usable), settings,
                     ResidualAnalyser(data, settings.bins), say, unit)
    say(
        f"base: held-out RMSE {format_error(search.current.test_rmse, unit)}, training RMSE "
        f"{format_error(search.current.train_rmse, unit)}"
    )
    settings, lowered = noise_aware(settings, search.current.fit.residuals[data.test],
                                    data.noise)
    if lowered:
        say(lowered)
        search.settings = settings
    for round_number in range(1, settings.max_effects + 1):
        if not search.run_round(round_number):
            break

    current = search.current
    structure = residual_structure(current.analysis, settings, data.time_ordered, data.noise,
                                   current.fit.residuals[search.analyse.used],
                                   search.analyse.regressors)
    names = tuple(e.name for e in search.added)
    comparison = runner_up(current, pool, data, settings)
    if comparison is not None and separating is not None:
        comparison = judged_within(comparison, current, pool, data, settings, separating)
    verdict = verdict_of(structure, names, comparison)
    summary = summarise(base.name, verdict, search.steps[0], current, names, structure, unit)
    if comparison is not None:
        summary += f" {comparison.describe()[0].upper()}{comparison.describe()[1:]}."
    if not usable:
        summary += (
            f" No effect of the library could be tried on {base.name} with these data"
            " (see the skipped effects)."
        )
    say(summary)
    return CalibrationResult(
        model=base.name,
        verdict=verdict,
        summary=summary,
        before=search.steps[0],
        after=current,
        steps=tuple(search.steps),
        candidates=tuple(search.candidates),
        structure=structure,
        library=tuple(e.name for e in library),
        skipped=skipped,
        data=data,
        settings=settings,
        seconds=time.perf_counter() - started,
        effects_added=names,
        unit=unit,
        observation=observation,
        comparison=comparison,
    )


def with_bootstrap(
    result: CalibrationResult,
    samples: int = 50,
    *,
    seed: int = 0,
    progress: Progress | None = None,
) -> CalibrationResult:
    """``result`` with its final model's parameter uncertainties from a stroke-block bootstrap
    of ``samples`` refits (:func:`~hcard.calibration.bootstrap.stroke_bootstrap`, seeded)."""
    boot = stroke_bootstrap(result.after.fit, result.data, samples=samples, seed=seed,
                            progress=progress)
    return replace(result, bootstrap=boot)
