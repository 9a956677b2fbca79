"""Every model the calibration loop fits, by its set of effects, and how each was fitted.

The loop (:mod:`hcard.calibration.loop`) compares models that differ by one or two effects.
:class:`ModelPool` fits each set of effects once and keeps it, so that a set the loop meets
again (a pair it scores, a set it prunes back to) is not fitted twice.

**Screening** (:mod:`hcard.calibration.screening`). A candidate is first fitted on every
``k``-th training sample; the pool marks such a fit with how to fit it on every training sample
(the start of the round that tried it, or None: from its best fitted subset, as
:meth:`ModelPool.fitted_set` does), which :meth:`ModelPool.confirmed` does before any decision
its figures could not make. A screened fit's figures are read through its start model's:
``scale[key]`` is the start's held-out RMSE fitted in full over the same model refitted on the
screening samples (a fit on fewer samples generalises a little worse, 4 % on a high-pass with
7.7 ms against samples 8 ms apart; the candidate's share of that is the start's).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.fit import FitResult, fit_predictor
from hcard.calibration.observation import (
    FORCE_OFFSET,
    FRICTION_COEFFICIENT,
    lateral_force_model,
)
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect, augment

CANDIDATE_EVALUATIONS = 120
"""Most model evaluations of a candidate's fit from the effect's defaults (K7). A fit that
converges needs a few tens; one from defaults far from the data (an effect the data do not
hold, next to a finger model that already explains the drift it would) crawls for hundreds,
ends no better than the current model, and is then fitted again from the neutral values."""

EffectSet = frozenset[str]
"""A model of the loop named by the set of its effects' names (the base model: empty)."""


def model_of(
    base: Predictor, effects: Sequence[Effect], start: Mapping[str, float], observation: str
) -> Predictor:
    """The model of the observation of ``base`` with ``effects``, at ``start`` where it names
    one.

    ``observation`` ``"lateral_force"`` wraps the model to output the measured lateral force, N
    (:func:`~hcard.calibration.observation.lateral_force_model`); ``"output"`` keeps the
    base's output and unit. Names in ``start`` the model does not have are ignored."""
    model = augment(base, effects)
    if observation == "lateral_force":
        model = lateral_force_model(model)
    known = {p.name for p in model.parameters}
    return model.with_params(**{k: v for k, v in start.items() if k in known})


def free_parameters(
    model: Predictor, base_free: Sequence[str], effects: Sequence[Effect]
) -> list[str]:
    """The parameters of ``model`` a fit moves, in fit order, without repeats: the base's
    ``base_free`` (those ``model`` has), the observation's friction coefficient and force
    offset (when the model is wrapped to output the lateral force), then every parameter of
    every effect, prefixed ``effect.parameter``."""
    names = {p.name for p in model.parameters}
    free = [name for name in base_free if name in names]
    free += [name for name in (FRICTION_COEFFICIENT, FORCE_OFFSET) if name in names]
    free += [f"{e.name}.{p.name}" for e in effects for p in e.parameters]
    return list(dict.fromkeys(free))


def residual_sum_of_squares(fit: FitResult, samples: np.ndarray) -> float:
    """Residual sum of squares of ``fit`` over the ``samples`` mask, (output unit)^2 (its
    residuals cover every sample, so a fit on the screening samples is measured on the whole
    training split too)."""
    return float(np.sum(fit.residuals[samples] ** 2))


def held_out_criterion(fit: FitResult, n_eff: float) -> float:
    """The held-out information criterion ``H = n_eff ln(MSE_held-out) + 2 k`` of ``fit``
    (dimensionless): ``MSE`` the mean squared residual on ``fit.test``, ``k`` its free
    parameter count, ``n_eff`` the effective held-out sample count. A zero MSE counts as the
    smallest positive float."""
    mse = float(np.mean(fit.residuals[fit.test] ** 2))
    return n_eff * math.log(max(mse, np.finfo(float).tiny)) + 2 * fit.n_free


class ModelPool:
    """The models of one calibration, fitted once each, by their set of effect names.

    Attributes:
        fits: effect set -> (effects in the order fitted, fit).
        screened: the effect sets in ``fits`` fitted on the screening samples only -> how to
            fit them on every training sample: ``(the other effects, the effect added, the
            start fit)``, or None: from the best fitted subset.
        scale: screened effect set -> its start's full over screened held-out RMSE.
        failures: effect set -> why its fit on every training sample failed.
    """

    def __init__(
        self,
        data: CalibrationData,
        base: Predictor,
        base_free: Sequence[str],
        observation: str,
        screen: np.ndarray | None,
        say: Callable[[str], None],
    ) -> None:
        """``data``: the recordings; ``base``: the model to calibrate, whose ``base_free``
        parameters are fitted; ``observation``: what ``data.observed`` is
        (:func:`model_of`); ``screen``: the screening samples (a mask of the training split),
        or None: no screening; ``say``: called with one line of text per notable fit."""
        self.data = data
        self.base = base
        self.base_free = tuple(base_free)
        self.observation = observation
        self.screen = screen
        self.say = say
        self.fits: dict[EffectSet, tuple[tuple[Effect, ...], FitResult]] = {}
        self.screened: dict[EffectSet, tuple[tuple[Effect, ...], Effect, FitResult] | None] = {}
        self.scale: dict[EffectSet, float] = {}
        self.failures: dict[EffectSet, str] = {}
        self._references: dict[int, tuple[FitResult, float]] = {}  # by id of the start fit
        self._dynamic: dict[EffectSet, bool] = {}

    def fit(self, effects: Sequence[Effect], start: Mapping[str, float],
            budget: int | None = None, train: np.ndarray | None = None) -> FitResult:
        """The base with ``effects`` fitted from ``start`` (:func:`model_of`), its
        :func:`free_parameters` free, on ``train`` (default: the training split), with at most
        ``budget`` model evaluations (default: the fit's own). Not pooled."""
        data = self.data
        model = model_of(self.base, effects, start, self.observation)
        wanted = {v.name for v in model.inputs}
        inputs = data.inputs_for(model)
        return fit_predictor(
            model,
            inputs,
            data.observed,
            free=free_parameters(model, self.base_free, effects),
            train=data.train if train is None else train,
            test=data.test,
            dynamic="time" in wanted,
            max_evaluations=budget,
        )

    def fit_base(self) -> FitResult:
        """The base model without effects, fitted on the training split and pooled (every set
        of effects starts from it)."""
        base = self.fit([], {})
        self.fits[frozenset()] = ((), base)
        return base

    def evaluates_every_sample(self, effects: Sequence[Effect]) -> bool:
        """Whether the model with ``effects`` has memory (a ``time`` input): its fit evaluates
        it on every sample whatever the training split (``fit_predictor``'s ``dynamic``), so a
        screened fit saves only the optimiser's algebra, not worth its full refits near
        decisions; such candidates are fitted on every training sample at once."""
        key = frozenset(e.name for e in effects)
        if key not in self._dynamic:
            model = model_of(self.base, effects, {}, self.observation)
            self._dynamic[key] = "time" in {v.name for v in model.inputs}
        return self._dynamic[key]

    def reference_scale(self, start: FitResult) -> float | None:
        """Full over screened held-out RMSE of the model fitted in full as ``start``:
        ``start``'s RMSE over that of the same model (``start.predictor``: its effects in the
        order it was fitted with) refitted on the screening samples from ``start``'s
        parameters, once per fit; None when that refit fails."""
        data = self.data
        if id(start) not in self._references:
            model = start.predictor
            try:
                again = fit_predictor(
                    model, data.inputs_for(model), data.observed, free=start.free,
                    train=self.screen, test=data.test,
                    dynamic="time" in {v.name for v in model.inputs},
                    max_evaluations=CANDIDATE_EVALUATIONS)
                ratio = float(start.test_rmse or math.nan) / float(again.test_rmse or math.nan)
            except PredictorError:
                ratio = math.nan
            self._references[id(start)] = (start, ratio)
        ratio = self._references[id(start)][1]
        return ratio if math.isfinite(ratio) and ratio > 0 else None

    def held_out(self, key: EffectSet) -> float:
        """The held-out RMSE of the pooled model ``key`` (output unit): a screened one scaled
        by ``scale``."""
        return float(self.fits[key][1].test_rmse or math.nan) * self.scale.get(key, 1.0)

    def criterion(self, key: EffectSet, n_eff: float) -> float:
        """``H`` of the pooled model ``key`` at ``n_eff`` (:func:`held_out_criterion`), from
        :meth:`held_out`'s RMSE."""
        return held_out_criterion(self.fits[key][1], n_eff) \
            + 2.0 * n_eff * math.log(self.scale.get(key, 1.0))

    def fit_with(self, effects: Sequence[Effect], new: Effect, start: FitResult,
                 train: np.ndarray | None = None) -> FitResult:
        """``effects`` plus ``new``, from ``start``'s parameters and ``new``'s defaults; when
        that ends worse on the training data than ``start`` (a local minimum), fitted again
        from ``new``'s neutral values (which start at ``start``'s model) and the better of the
        two by training error is kept. The held-out split never chooses. ``train``: the
        training samples (default: all of them; the screening samples when screening).
        Not pooled."""
        mask = self.data.train if train is None else train
        chosen = self.fit([*effects, new], start.params, CANDIDATE_EVALUATIONS, train)
        if residual_sum_of_squares(chosen, mask) > residual_sum_of_squares(start, mask) \
                * (1.0 + 1e-9) and new.neutral:
            neutral = {f"{new.name}.{k}": v for k, v in new.neutral.items()}
            second = self.fit([*effects, new], {**start.params, **neutral}, train=train)
            if residual_sum_of_squares(second, mask) < residual_sum_of_squares(chosen, mask):
                chosen = second
        return chosen

    def screen_with(self, effects: Sequence[Effect], new: Effect, start: FitResult) -> FitResult:
        """The round's candidate ``effects`` plus ``new`` from ``start``, fitted on the
        screening samples and pooled as screened (on every training sample, and pooled as
        such, without screening or when the screened fit fails)."""
        key = frozenset([*(e.name for e in effects), new.name])
        worth = self.screen is not None and not self.evaluates_every_sample([*effects, new])
        ratio = self.reference_scale(start) if worth else None
        if ratio is not None:
            try:
                result = self.fit_with(effects, new, start, self.screen)
            except PredictorError:
                pass
            else:
                self.fits[key] = ((*effects, new), result)
                self.screened[key] = (tuple(effects), new, start)
                self.scale[key] = ratio
                return result
        result = self.fit_with(effects, new, start)
        self.fits[key] = ((*effects, new), result)
        return result

    def confirmed(self, key: EffectSet) -> FitResult | None:
        """The pooled model ``key`` fitted on every training sample, as it is fitted without
        screening: fitted now when the pool holds a screened fit of it (its place in the pool
        kept). None when that fit fails (the reason in ``failures``; the model leaves the
        pool) or the model was never fitted."""
        if key not in self.screened:
            entry = self.fits.get(key)
            return entry[1] if entry is not None else None
        recipe = self.screened.pop(key)
        self.scale.pop(key, None)
        effects = self.fits[key][0]
        self.say(f"{' + '.join(e.name for e in effects)}: fitting on every training sample "
                 "(its screened figures are near a decision)")
        result: FitResult | None
        if recipe is None:
            result = self.from_subsets(effects, exact=True)
        else:
            others, new, start = recipe
            try:
                result = self.fit_with(others, new, start)
            except PredictorError as exc:
                self.failures[key] = str(exc)
                self.say(f"{' + '.join(e.name for e in effects)}: fit failed ({exc})")
                result = None
        if result is None:
            self.fits.pop(key, None)
            return None
        self.fits[key] = (effects, result)
        return result

    def fitted_set(self, effects: Sequence[Effect], exact: bool = False) -> FitResult | None:
        """The fit of the model with ``effects`` (from the pool, else fitted now from the best
        fitted model that lacks one of them); None when its fit fails. ``exact``: on every
        training sample (a screened fit in the pool is fitted again), else the pool's fit
        as it is, and a new fit screened."""
        key = frozenset(e.name for e in effects)
        if key in self.fits:
            return self.confirmed(key) if exact else self.fits[key][1]
        return self.from_subsets(effects, exact)

    def from_subsets(self, effects: Sequence[Effect], exact: bool) -> FitResult | None:
        """``effects`` fitted from the best fitted model that lacks one of them (by training
        error over the whole training split), pooled; screened unless ``exact``. None when the
        fit fails."""
        train = self.data.train
        key = frozenset(e.name for e in effects)
        best: tuple[Effect, FitResult] | None = None
        for effect in effects:
            others = [e for e in effects if e is not effect]
            smaller = self.fitted_set(others, exact)
            if smaller is not None and (
                best is None
                or residual_sum_of_squares(smaller, train)
                < residual_sum_of_squares(best[1], train)
            ):
                best = (effect, smaller)
        if best is None:
            return None
        new, start = best
        rest = [e for e in effects if e is not new]
        start_key = frozenset(e.name for e in rest)
        if not exact and self.screen is not None and not self.evaluates_every_sample(effects):
            ratio = (self.scale.get(start_key) if start_key in self.screened
                     else self.reference_scale(start))
            if ratio is None:  # fitted in full from full subsets, as without screening
                return self.from_subsets(effects, exact=True)
            try:
                result = self.fit_with(rest, new, start, self.screen)
            except PredictorError:
                return self.from_subsets(effects, exact=True)
            self.fits[key] = (tuple(effects), result)
            self.screened[key] = None
            self.scale[key] = ratio
            return result
        try:
            result = self.fit_with(rest, new, start)
        except PredictorError as exc:
            self.failures[key] = str(exc)
            self.say(f"{' + '.join(e.name for e in effects)}: fit failed ({exc})")
            return None
        self.fits[key] = (tuple(effects), result)
        return result
