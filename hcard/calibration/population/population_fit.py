"""The first stage of a two-stage mixed-effects fit and the population's effects
(spec/calibration.md K19-K25).

Each group (a participant) is prepared alone (:func:`~hcard.calibration.dataset.prepare`: its
own held-out split, K2) and fitted alone (:class:`~hcard.calibration.model_pool.ModelPool`,
i.e. :func:`~hcard.calibration.fit.fit_predictor` with the observation model, K5-K6). The
effects are chosen for the population by the summed held-out criterion (K24), each parameter
of the final model is pooled by :func:`~.random_effects.random_effects` (K21-K23), and every
participant is predicted as one never seen, with the population means of the others (K23).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hcard.calibration.dataset import CalibrationData, prepare
from hcard.calibration.fit import FitResult
from hcard.calibration.judges import check_arguments, earns_place, usable_effects
from hcard.calibration.measurement import Measurement, MeasurementError
from hcard.calibration.model_pool import ModelPool, held_out_criterion, model_of
from hcard.calibration.population.grouping import PopulationError
from hcard.calibration.population.random_effects import RandomEffects, random_effects
from hcard.calibration.residuals import effective_samples
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect

Progress = Callable[[str], None]


@dataclass(frozen=True)
class EffectTrial:
    """One candidate effect tried for the population in one round (K24).

    Attributes:
        effect: its name.
        round: the round (1 = added to the base).
        criterion_change: per participant label, ``H(with) - H(without)`` (dimensionless);
            NaN where the fit with it failed.
        own: per participant label, whether the effect earns its place for that participant
            alone (K9 a and b: ``H`` falls and the held-out RMSE falls by ``min_improvement``).
        added: whether the population took it.
    """

    effect: str
    round: int
    criterion_change: dict[str, float]
    own: dict[str, bool]
    added: bool = False

    @property
    def summed_change(self) -> float:
        """Summed ``H(with) - H(without)`` over the participants whose fit did not fail."""
        values = [v for v in self.criterion_change.values() if math.isfinite(v)]
        return float(sum(values)) if values else math.nan

    @property
    def own_count(self) -> int:
        """How many participants the effect earns its place for alone."""
        return sum(self.own.values())


@dataclass
class ParticipantFit:
    """One group's fit (K20) and its errors (K23).

    Attributes:
        label: the group's label (participant code).
        sources: its recordings' files.
        data: its prepared samples, or None when reading them failed.
        fit: its fit with the population's effects, or None when it failed.
        error: why it failed (empty when it did not).
        held_out_rmse: RMSE of its own fit on its own held-out split (output unit, N).
        never_seen_rmse: RMSE on its held-out split of the population-mean model of the other
            participants (output unit), NaN when it could not be evaluated.
        flags: effect name -> ``"needs"`` (it earns its place here, the population did not add
            it) or ``"does not need"`` (the population added it, it does not earn its place
            here) (K24).
    """

    label: str
    sources: tuple[str, ...]
    data: CalibrationData | None = None
    fit: FitResult | None = None
    error: str = ""
    held_out_rmse: float = math.nan
    never_seen_rmse: float = math.nan
    flags: dict[str, str] = field(default_factory=dict)
    _fits: dict[tuple[str, ...], FitResult] = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class PopulationResult:
    """A population calibration (K19-K25).

    Attributes:
        model: the base predictor's name.
        by: what the recordings were grouped by.
        participants: every group, fitted or failed, in the order of first appearance.
        effects: the population's effects, in the order added.
        trials: every candidate tried, round by round.
        skipped: effect name -> why it was not tried.
        parameters: the final model's free parameters, in fit order.
        population: parameter -> its random-effects population, for those with at least two
            participants whose estimate has a finite standard error.
        excluded: parameter -> participant labels left out of its population (no finite,
            positive standard error: held, not identified or at a bound).
        units: parameter -> unit.
        unit: unit of the observed quantity and of the errors.
        settings: the split, test fraction, seed, minimum improvement and most effects.
    """

    model: str
    by: str
    participants: tuple[ParticipantFit, ...]
    effects: tuple[str, ...]
    trials: tuple[EffectTrial, ...]
    skipped: dict[str, str]
    parameters: tuple[str, ...]
    population: dict[str, RandomEffects]
    excluded: dict[str, tuple[str, ...]]
    units: dict[str, str]
    unit: str
    settings: dict[str, object]

    @property
    def fitted(self) -> tuple[ParticipantFit, ...]:
        """The participants whose fit succeeded."""
        return tuple(p for p in self.participants if p.fit is not None)

    @property
    def failed(self) -> tuple[ParticipantFit, ...]:
        """The participants whose data or fit failed."""
        return tuple(p for p in self.participants if p.fit is None)

    def mean_error(self, which: str) -> float:
        """Root mean square over the fitted participants of their ``held_out_rmse`` or
        ``never_seen_rmse`` (``which``), output unit."""
        values = [getattr(p, which) for p in self.fitted if math.isfinite(getattr(p, which))]
        return float(math.sqrt(np.mean(np.square(values)))) if values else math.nan


def _held_out_rmse(model: Predictor, data: CalibrationData) -> float:
    """RMSE of ``model`` over ``data``'s held-out samples (output unit), evaluated over every
    sample in order (a model with memory sees the whole input history, K1); NaN when it does
    not evaluate."""
    try:
        predicted = np.asarray(model.forward(**data.inputs_for(model)), dtype=np.float64)
        predicted = np.broadcast_to(predicted, data.observed.shape)
    except PredictorError:
        return math.nan
    residual = data.observed[data.test] - predicted[data.test]
    return float(math.sqrt(np.mean(residual**2))) if residual.size else math.nan


def fit_population(
    groups: Mapping[str, Sequence[Measurement]],
    base: Predictor,
    library: Sequence[Effect] = (),
    *,
    free: Sequence[str] | None = None,
    split: str = "stroke",
    test_fraction: float = 0.25,
    seed: int = 0,
    min_improvement: float = 0.05,
    max_effects: int = 4,
    rezero: bool = True,
    observation: str = "lateral_force",
    by: str = "participant",
    progress: Progress | None = None,
) -> PopulationResult:
    """Fit ``base`` to every group of ``groups`` and pool the parameters (module docstring).

    Args:
        groups: label -> the group's recordings (:func:`.grouping.group_recordings`).
        base: the model (a predictor, or a device profile's model).
        library: candidate effects (K24); none: the base model alone.
        free: base parameters fitted (default: the model's calibrated ones).
        split, test_fraction, seed, rezero: each group's held-out split and preparation
            (:func:`~hcard.calibration.dataset.prepare`).
        min_improvement: held-out RMSE fall (fraction) an effect must bring a participant (K9 b).
        max_effects: most effects added to the population.
        observation: what the recordings' observed values are (lateral force, N).
        by: what ``groups`` are labelled by (for the report).
        progress: called with a line per participant and per decision.

    Raises:
        PopulationError: fewer than 2 groups fitted (every failure named).
    """
    say = progress or (lambda _text: None)
    participants = [ParticipantFit(label, tuple(m.source for m in ms))
                    for label, ms in groups.items()]
    pools: dict[str, ModelPool] = {}
    base_free: tuple[str, ...] = ()
    count = len(participants)
    for number, part in enumerate(participants, start=1):
        try:
            data = prepare(list(groups[part.label]), split=split, test_fraction=test_fraction,
                           seed=seed, rezero=rezero)
            part.data = data
            base_free = check_arguments(data, base, free, observation)
            pool = ModelPool(data, base, base_free, observation, None, lambda _t: None)
            fitted = pool.fit([], {})
        except (MeasurementError, PredictorError) as exc:
            part.error = str(exc)
            say(f"participant {number}/{count} {part.label}: fit failed: {exc}")
            continue
        pools[part.label] = pool
        part._fits[()] = fitted
        part.fit, part.held_out_rmse = fitted, float(fitted.test_rmse or math.nan)
        say(f"participant {number}/{count} {part.label}: {fitted.n_train} training samples, "
            f"held-out RMSE {part.held_out_rmse:.4g}")
    fitted_parts = [p for p in participants if p.fit is not None]
    if len(fitted_parts) < 2:
        failures = "; ".join(f"{p.label}: {p.error}" for p in participants if p.error)
        raise PopulationError(
            f"a population needs at least 2 fitted {by}s, {len(fitted_parts)} of "
            f"{len(participants)} fitted" + (f" ({failures})" if failures else ""))

    usable, skipped = _common_effects(library, base, fitted_parts)
    chosen, trials = _choose_effects(fitted_parts, pools, usable, min_improvement,
                                     max_effects, say)
    key = tuple(e.name for e in chosen)
    for part in fitted_parts:
        final = part._fits.get(key)
        if final is None:  # its fit with the population's effects failed
            part.fit, part.error = None, f"fit with {', '.join(key)} failed"
            say(f"{by} {part.label}: fit with the population's effects failed")
            continue
        part.fit, part.held_out_rmse = final, float(final.test_rmse or math.nan)
    last = {trial.effect: trial for trial in trials}  # flags: the last round that tried it
    for trial in last.values():
        for part in fitted_parts:
            own = trial.own.get(part.label)
            if own is None:
                continue
            if own and not trial.added:
                part.flags[trial.effect] = "needs"
            elif trial.added and not own:
                part.flags[trial.effect] = "does not need"
    fitted_parts = [p for p in fitted_parts if p.fit is not None]
    if len(fitted_parts) < 2:
        raise PopulationError(f"a population needs at least 2 fitted {by}s")

    parameters = tuple(n for n in fitted_parts[0].fit.free  # type: ignore[union-attr]
                       if n not in fitted_parts[0].fit.held)  # type: ignore[union-attr]
    model = fitted_parts[0].fit.predictor  # type: ignore[union-attr]
    units = {p.name: p.unit for p in model.parameters if p.name in parameters}
    population, excluded = _pool(fitted_parts, parameters)
    for part in fitted_parts:
        part.never_seen_rmse = _never_seen(part, fitted_parts, parameters, base, chosen,
                                           observation)
        say(f"{by} {part.label}: held-out RMSE {part.held_out_rmse:.4g} own fit, "
            f"{part.never_seen_rmse:.4g} never seen")
    return PopulationResult(
        model=base.name, by=by, participants=tuple(participants), effects=key,
        trials=tuple(trials), skipped=skipped, parameters=parameters, population=population,
        excluded=excluded, units=units,
        unit="N" if observation == "lateral_force" else base.output.unit,
        settings={"split": split, "test_fraction": test_fraction, "seed": seed,
                  "min_improvement": min_improvement, "max_effects": max_effects,
                  "free": list(base_free)},
    )


def _common_effects(library: Sequence[Effect], base: Predictor,
                    parts: Sequence[ParticipantFit]) -> tuple[list[Effect], dict[str, str]]:
    """The effects that can be tried on every fitted participant's data (K8), and why each
    other one cannot."""
    usable = list(library)
    skipped: dict[str, str] = {}
    for part in parts:
        assert part.data is not None
        keep, why = usable_effects(usable, base, part.data.regressors)
        for name, reason in why.items():
            skipped.setdefault(name, f"{part.label}: {reason}")
        usable = keep
    return usable, skipped


def _fit_with(pool: ModelPool, effects: Sequence[Effect], start: FitResult) -> FitResult | None:
    """The model with ``effects`` fitted from ``start``'s values (new parameters at their
    defaults), refitted from the last effect's neutral values when that ends worse on the
    training split (K7); None when both fail."""
    best: FitResult | None = None
    new = effects[-1]
    neutral = {f"{new.name}.{k}": v for k, v in new.neutral.items()}
    for begin in (dict(start.params), {**start.params, **neutral}):
        try:
            trial = pool.fit(effects, begin)
        except PredictorError:
            continue
        if best is None or trial.train_rss < best.train_rss:
            best = trial
        if best.train_rss <= start.train_rss:
            break
    return best


def _choose_effects(parts: Sequence[ParticipantFit], pools: Mapping[str, ModelPool],
                    usable: Sequence[Effect], min_improvement: float, max_effects: int,
                    say: Progress) -> tuple[list[Effect], list[EffectTrial]]:
    """Greedy forward selection by the summed held-out criterion (K24): each round every
    remaining candidate is fitted to every participant on top of the population's effects; the
    one with the lowest summed ``H`` change is added when that sum is negative and the effect
    earns its place (K9 a, b) for at least half the participants."""
    chosen: list[Effect] = []
    trials: list[EffectTrial] = []
    for round_number in range(1, max_effects + 1):
        remaining = [e for e in usable if e not in chosen]
        if not remaining:
            break
        key = tuple(e.name for e in chosen)
        round_trials: list[EffectTrial] = []
        for effect in remaining:
            change: dict[str, float] = {}
            own: dict[str, bool] = {}
            for part in parts:
                current = part._fits.get(key)
                if current is None:
                    continue
                n_eff = effective_samples(current.residuals[current.test])
                with_it = _fit_with(pools[part.label], [*chosen, effect], current)
                if with_it is None:
                    change[part.label] = math.nan
                    own[part.label] = False
                    continue
                grown = (*key, effect.name)
                part._fits[grown] = with_it
                change[part.label] = (held_out_criterion(with_it, n_eff)
                                      - held_out_criterion(current, n_eff))
                own[part.label] = earns_place(with_it, current, n_eff, min_improvement) == ""
            trial = EffectTrial(effect.name, round_number, change, own)
            round_trials.append(trial)
            say(f"round {round_number}: {effect.name}: summed change of H "
                f"{trial.summed_change:+.1f}, earns its place for {trial.own_count} of "
                f"{len(own)}")
        passing = [t for t in round_trials
                   if t.summed_change < 0 and 2 * t.own_count >= len(t.own)]
        best = min(passing, key=lambda t: t.summed_change, default=None)
        trials += [EffectTrial(t.effect, t.round, t.criterion_change, t.own,
                               added=t is best) for t in round_trials]
        if best is None:
            break
        chosen.append(next(e for e in remaining if e.name == best.effect))
        say(f"round {round_number}: population adds {best.effect}")
    return chosen, trials


def _estimates(parts: Sequence[ParticipantFit], name: str
               ) -> tuple[list[str], list[float], list[float]]:
    """Labels, estimates and standard errors of parameter ``name`` over ``parts`` whose
    standard error is finite and positive and which did not end on a bound."""
    labels, values, errors = [], [], []
    for part in parts:
        fit = part.fit
        assert fit is not None
        se = fit.uncertainties.get(name, math.inf)
        if math.isfinite(se) and se > 0 and name not in fit.at_bounds:
            labels.append(part.label)
            values.append(fit.params[name])
            errors.append(se)
    return labels, values, errors


def _pool(parts: Sequence[ParticipantFit], parameters: Sequence[str]
          ) -> tuple[dict[str, RandomEffects], dict[str, tuple[str, ...]]]:
    """Each parameter's random-effects population (K21-K22) and who was left out of it."""
    population: dict[str, RandomEffects] = {}
    excluded: dict[str, tuple[str, ...]] = {}
    for name in parameters:
        labels, values, errors = _estimates(parts, name)
        excluded[name] = tuple(p.label for p in parts if p.label not in set(labels))
        if len(values) >= 2:
            population[name] = random_effects(values, errors)
    return population, excluded


def _never_seen(part: ParticipantFit, parts: Sequence[ParticipantFit],
                parameters: Sequence[str], base: Predictor, effects: Sequence[Effect],
                observation: str) -> float:
    """Held-out RMSE of ``part`` predicted as a participant never seen (K23): every parameter
    at the population mean of the other participants (REML ``mu``; their median where fewer
    than 2 have a standard error; the single other's value for a population of 2)."""
    others = [p for p in parts if p is not part]
    assert part.data is not None
    values: dict[str, float] = {}
    for name in parameters:
        _, estimates, errors = _estimates(others, name)
        if len(estimates) >= 2:
            values[name] = random_effects(estimates, errors).mu
        else:
            values[name] = float(np.median([p.fit.params[name] for p in others
                                            if p.fit is not None]))
    try:
        model = model_of(base, effects, values, observation)
    except PredictorError:
        return math.nan
    return _held_out_rmse(model, part.data)
