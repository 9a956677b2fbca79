"""The first stage of a two-stage mixed-effects fit and the population's effects
(spec/calibration.md K19-K25).

Each group (a participant) is prepared alone (:func:`~hcard.calibration.dataset.prepare`: its
own held-out split, K2) and fitted alone (:class:`~hcard.calibration.model_pool.ModelPool`,
i.e. :func:`~hcard.calibration.fit.fit_predictor` with the observation model, K5-K6). The
effects are chosen for the population by the summed held-out criterion (K24), each parameter
of the final model is pooled by :func:`~.random_effects.random_effects` (K21-K23), and every
participant is predicted as one never seen, with the population means of the others (K23).

Every per-participant step (read, prepare and fit the base; fit each candidate effect of a
round; predict as never seen) is a task of an :class:`~hcard.executor.Executor` (K26): in this
process by default, or on Dask workers. A task takes the participant's recordings as file paths
(or in-memory recordings when the caller gives them) and reads and prepares them itself, so a
worker holds one participant's data; the results are gathered in participant order, so the
population is the same wherever the tasks ran.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hcard.calibration.dataset import CalibrationData, prepare
from hcard.calibration.fit import FitResult
from hcard.calibration.judges import check_arguments, earns_place, usable_effects
from hcard.calibration.lab.rigs import RecordingFile
from hcard.calibration.measurement import Measurement, read_measurement
from hcard.calibration.model_pool import ModelPool, held_out_criterion, model_of
from hcard.calibration.population.grouping import PopulationError
from hcard.calibration.population.random_effects import RandomEffects, random_effects
from hcard.calibration.residuals import effective_samples
from hcard.errors import InputError
from hcard.executor import Executor, Outcome
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect

Progress = Callable[[str], None]
Recording = Measurement | RecordingFile | str | os.PathLike[str]
"""A recording as a task takes it: a file path (read on the worker) or one already read."""


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
    fit: FitResult | None = None
    error: str = ""
    held_out_rmse: float = math.nan
    never_seen_rmse: float = math.nan
    flags: dict[str, str] = field(default_factory=dict)
    _fits: dict[tuple[str, ...], FitResult] = field(default_factory=dict, repr=False)
    _usable: tuple[list[str], dict[str, str]] = field(default=([], {}), repr=False)


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


@dataclass(frozen=True)
class ParticipantTask:
    """What every task of one participant needs (picklable: it goes to the workers).

    Attributes:
        label: the participant's label.
        recordings: its recordings, as file paths (read by the task) or already read.
        base: the model.
        free: base parameters fitted (None: the model's calibrated ones).
        observation: what the observed values are.
        split, test_fraction, seed, rezero: the preparation (:func:`prepare`).
    """

    label: str
    recordings: tuple[Recording, ...]
    base: Predictor
    free: tuple[str, ...] | None
    observation: str
    split: str
    test_fraction: float
    seed: int
    rezero: bool

    def data(self) -> CalibrationData:
        """The participant's recordings read (on the worker) and prepared."""
        measurements = [r if isinstance(r, Measurement)
                        else r.read() if isinstance(r, RecordingFile) else read_measurement(r)
                        for r in self.recordings]
        return prepare(measurements, split=self.split, test_fraction=self.test_fraction,
                       seed=self.seed, rezero=self.rezero)


@dataclass(frozen=True)
class FirstFit:
    """A participant's first task's result.

    Attributes:
        fit: the base model's fit, or None when reading, preparing or fitting failed.
        error: why it failed.
        base_free: the base parameters fitted.
        usable: names of the library's effects that can be tried on its data (K8).
        skipped: effect name -> why it cannot.
    """

    fit: FitResult | None
    error: str = ""
    base_free: tuple[str, ...] = ()
    usable: tuple[str, ...] = ()
    skipped: dict[str, str] = field(default_factory=dict)


def first_fit(job: tuple[ParticipantTask, tuple[Effect, ...]]) -> FirstFit:
    """Task: read and prepare one participant's recordings, fit the base model and say which
    of the library's effects can be tried on them (``job``: the participant, the library).
    A recording or fit that fails is a result (:attr:`FirstFit.error`), not retried."""
    task, library = job
    try:
        data = task.data()
        base_free = check_arguments(data, task.base, task.free, task.observation)
        pool = ModelPool(data, task.base, base_free, task.observation, None, _silent)
        fitted = pool.fit([], {})
    except (InputError, PredictorError) as exc:
        return FirstFit(None, str(exc))
    usable, skipped = usable_effects(library, task.base, data.regressors)
    return FirstFit(fitted, "", base_free, tuple(e.name for e in usable), skipped)


def effect_fits(job: tuple[ParticipantTask, tuple[str, ...], tuple[Effect, ...],
                           tuple[Effect, ...], dict[str, float], float]
                ) -> dict[str, FitResult | None]:
    """Task: one participant's fits of one round (K24): ``job`` is the participant, its
    fitted base parameters, the population's effects so far, the candidates, and the start
    (the current fit's parameters and training RSS, N^2); returns candidate name -> the fit
    with it (None: it failed)."""
    task, base_free, chosen, candidates, params, train_rss = job
    pool = ModelPool(task.data(), task.base, base_free, task.observation, None, _silent)
    return {effect.name: _fit_with(pool, [*chosen, effect], params, train_rss)
            for effect in candidates}


def never_seen_rmse(job: tuple[ParticipantTask, tuple[Effect, ...], dict[str, float]]
                    ) -> float:
    """Task: the held-out RMSE (N) of one participant predicted by the model with ``job``'s
    effects at ``job``'s parameter values (the others' population, K23); NaN when the model
    cannot be made or evaluated."""
    task, effects, values = job
    try:
        model = model_of(task.base, effects, values, task.observation)
    except PredictorError:
        return math.nan
    return _held_out_rmse(model, task.data())


def _silent(_text: str) -> None:
    """A progress callback that says nothing (picklable)."""


def _run(executor: Executor, function: Callable[..., object], jobs: Sequence[tuple[str, object]],
         say: Progress) -> dict[str, Outcome[object]]:
    """Every job's outcome by key, whatever order they completed in."""
    return {o.key: o for o in executor.map(function, jobs, say)}


def fit_population(
    groups: Mapping[str, Sequence[Recording]],
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
    executor: Executor | None = None,
) -> PopulationResult:
    """Fit ``base`` to every group of ``groups`` and pool the parameters (module docstring).

    Args:
        groups: label -> the group's recordings (:func:`.grouping.group_recordings`), as file
            paths (each task reads its own) or already read.
        base: the model (a predictor, or a device profile's model).
        library: candidate effects (K24); none: the base model alone.
        free: base parameters fitted (default: the model's calibrated ones).
        split, test_fraction, seed, rezero: each group's held-out split and preparation
            (:func:`~hcard.calibration.dataset.prepare`).
        min_improvement: held-out RMSE fall (fraction) an effect must bring a participant (K9 b).
        max_effects: most effects added to the population.
        observation: what the recordings' observed values are (lateral force, N).
        by: what ``groups`` are labelled by (for the report).
        progress: called with a line per participant, per decision and per finished task.
        executor: where the per-participant tasks run (default: in this process, K26).

    Raises:
        PopulationError: fewer than 2 groups fitted (every failure named).
    """
    say = progress or _silent
    if executor is None:
        with Executor() as here:
            return fit_population(
                groups, base, library, free=free, split=split, test_fraction=test_fraction,
                seed=seed, min_improvement=min_improvement, max_effects=max_effects,
                rezero=rezero, observation=observation, by=by, progress=progress,
                executor=here)
    participants = [ParticipantFit(label, tuple(_source(r) for r in rs))
                    for label, rs in groups.items()]
    tasks = {label: ParticipantTask(label, tuple(rs), base,
                                    None if free is None else tuple(free), observation, split,
                                    test_fraction, seed, rezero)
             for label, rs in groups.items()}
    outcomes = _run(executor, first_fit,
                    [(p.label, (tasks[p.label], tuple(library))) for p in participants], say)
    base_free: dict[str, tuple[str, ...]] = {}
    count = len(participants)
    for number, part in enumerate(participants, start=1):
        outcome = outcomes[part.label]
        first = outcome.value if isinstance(outcome.value, FirstFit) else None
        if first is None or first.fit is None:
            part.error = first.error if first is not None else f"task failed: {outcome.error}"
            say(f"participant {number}/{count} {part.label}: fit failed: {part.error}")
            continue
        fitted = first.fit
        base_free[part.label] = first.base_free
        part._fits[()] = fitted
        part._usable = (list(first.usable), first.skipped)
        part.fit, part.held_out_rmse = fitted, float(fitted.test_rmse or math.nan)
        say(f"participant {number}/{count} {part.label}: {fitted.n_train} training samples, "
            f"held-out RMSE {part.held_out_rmse:.4g}")
    fitted_parts = [p for p in participants if p.fit is not None]
    if len(fitted_parts) < 2:
        failures = "; ".join(f"{p.label}: {p.error}" for p in participants if p.error)
        raise PopulationError(
            f"a population needs at least 2 fitted {by}s, {len(fitted_parts)} of "
            f"{len(participants)} fitted" + (f" ({failures})" if failures else ""))

    usable, skipped = _common_effects(library, fitted_parts)
    rounds = _Rounds(executor, tasks, base_free, say)
    chosen, trials = _choose_effects(fitted_parts, rounds, usable, min_improvement,
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
    jobs: list[tuple[str, object]] = [
        (part.label, (tasks[part.label], tuple(chosen),
                      _never_seen_values(part, fitted_parts, parameters)))
        for part in fitted_parts]
    unseen = _run(executor, never_seen_rmse, jobs, say)
    for part in fitted_parts:
        value = unseen[part.label].value
        part.never_seen_rmse = float(value) if isinstance(value, float) else math.nan
        say(f"{by} {part.label}: held-out RMSE {part.held_out_rmse:.4g} own fit, "
            f"{part.never_seen_rmse:.4g} never seen")
    return PopulationResult(
        model=base.name, by=by, participants=tuple(participants), effects=key,
        trials=tuple(trials), skipped=skipped, parameters=parameters, population=population,
        excluded=excluded, units=units,
        unit="N" if observation == "lateral_force" else base.output.unit,
        settings={"split": split, "test_fraction": test_fraction, "seed": seed,
                  "min_improvement": min_improvement, "max_effects": max_effects,
                  "free": list(base_free[fitted_parts[-1].label])},
    )


def _source(recording: Recording) -> str:
    """A recording's file name for the report."""
    if isinstance(recording, Measurement):
        return recording.source
    if isinstance(recording, RecordingFile):
        return recording.path
    return os.fspath(recording)


@dataclass
class _Rounds:
    """Runs one round's candidate fits of every participant on the executor."""

    executor: Executor
    tasks: Mapping[str, ParticipantTask]
    base_free: Mapping[str, tuple[str, ...]]
    say: Progress

    def fits(self, starts: Mapping[str, FitResult], chosen: Sequence[Effect],
             candidates: Sequence[Effect]) -> dict[str, dict[str, FitResult | None]]:
        """label -> candidate name -> its fit on top of ``chosen`` from ``starts[label]``
        (None: failed, or the task failed after its retries)."""
        jobs: list[tuple[str, object]] = [
            (label, (self.tasks[label], self.base_free[label], tuple(chosen),
                     tuple(candidates), dict(start.params), float(start.train_rss)))
            for label, start in starts.items()]
        outcomes = _run(self.executor, effect_fits, jobs, self.say)
        found: dict[str, dict[str, FitResult | None]] = {}
        for label in starts:
            value = outcomes[label].value
            found[label] = value if isinstance(value, dict) else dict.fromkeys(
                (e.name for e in candidates), None)
        return found


def _common_effects(library: Sequence[Effect], parts: Sequence[ParticipantFit]
                    ) -> tuple[list[Effect], dict[str, str]]:
    """The effects that can be tried on every fitted participant's data (K8), and why each
    other one cannot."""
    usable = list(library)
    skipped: dict[str, str] = {}
    for part in parts:
        names, why = part._usable
        for name, reason in why.items():
            if any(e.name == name for e in usable):
                skipped.setdefault(name, f"{part.label}: {reason}")
        usable = [e for e in usable if e.name in names]
    return usable, skipped


def _fit_with(pool: ModelPool, effects: Sequence[Effect], params: Mapping[str, float],
              train_rss: float) -> FitResult | None:
    """The model with ``effects`` fitted from the start fit's ``params`` (new parameters at
    their defaults), refitted from the last effect's neutral values when that ends worse on
    the training split than the start's ``train_rss`` (K7); None when both fail."""
    best: FitResult | None = None
    new = effects[-1]
    neutral = {f"{new.name}.{k}": v for k, v in new.neutral.items()}
    for begin in (dict(params), {**params, **neutral}):
        try:
            trial = pool.fit(effects, begin)
        except PredictorError:
            continue
        if best is None or trial.train_rss < best.train_rss:
            best = trial
        if best.train_rss <= train_rss:
            break
    return best


def _choose_effects(parts: Sequence[ParticipantFit], rounds: _Rounds,
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
        starts = {p.label: p._fits[key] for p in parts if key in p._fits}
        fits = rounds.fits(starts, chosen, remaining)
        round_trials: list[EffectTrial] = []
        for effect in remaining:
            change: dict[str, float] = {}
            own: dict[str, bool] = {}
            for part in parts:
                current = part._fits.get(key)
                if current is None:
                    continue
                n_eff = effective_samples(current.residuals[current.test])
                with_it = fits[part.label][effect.name]
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


def _never_seen_values(part: ParticipantFit, parts: Sequence[ParticipantFit],
                       parameters: Sequence[str]) -> dict[str, float]:
    """The parameters ``part`` is predicted with as a participant never seen (K23): each at
    the population mean of the other participants (REML ``mu``; their median where fewer
    than 2 have a standard error; the single other's value for a population of 2)."""
    others = [p for p in parts if p is not part]
    values: dict[str, float] = {}
    for name in parameters:
        _, estimates, errors = _estimates(others, name)
        if len(estimates) >= 2:
            values[name] = random_effects(estimates, errors).mu
        else:
            values[name] = float(np.median([p.fit.params[name] for p in others
                                            if p.fit is not None]))
    return values
