"""The calibration loop: fit, analyse the residual, add the effect that explains it, repeat
(issue 7, item 5; DESIGN.md section 8).

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
   below; otherwise stop.

**Criterion** (stated in every report as :data:`CRITERION`). Each model ``m`` with ``k_m`` free
parameters gets a held-out information criterion

    ``H_m = n_eff ln(MSE_test,m) + 2 k_m``

where ``MSE_test`` is the mean squared error on the held-out samples (which the fit never saw)
and ``n_eff = n_test (1 - rho) / (1 + rho)`` is the number of effectively independent held-out
samples given the lag-1 autocorrelation ``rho`` of the current model's held-out residual
(samples of one stroke are not independent; clipped to [1, n_test]). The candidate with the
lowest ``H`` is accepted when (a) ``H`` falls (the error gain pays for the added parameters),
(b) its held-out RMSE falls by at least ``min_improvement`` (default 5 %: a practically
significant gain, not a fit to noise or drift), and (c) the current residual shows structure
against at least one regressor of the effect's signature (F-test p < ``alpha`` with
``eta^2 >= signature_eta2``): an effect is never credited for an error it does not explain
where it says it would.

**Verdicts.** When no candidate passes, the residual of the final model is analysed once more.
Structure left against a regressor (p < ``alpha`` and ``eta^2 >= min_eta2``) or in time
(lag-1 autocorrelation ``>= min_autocorrelation``) gives :data:`NOT_EXPLAINED`, naming where
the structure is; none gives :data:`NO_EFFECT` (nothing added) or :data:`EXPLAINED` (effects
added).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.effects import Effect, augment
from hcard.calibration.fit import FitResult, fit_predictor
from hcard.calibration.observation import (
    FORCE_OFFSET,
    FRICTION_COEFFICIENT,
    lateral_force_model,
)
from hcard.calibration.residuals import ResidualReport, analyse_residuals, effective_samples
from hcard.physics import Predictor, PredictorError

NO_EFFECT = "no effect needed"
EXPLAINED = "explained by added effects"
NOT_EXPLAINED = "structured residual not explained by any known effect"

CANDIDATE_EVALUATIONS = 120
"""Most model evaluations of a candidate's fit from the effect's defaults (K7). A fit that
converges needs a few tens; one from defaults far from the data (an effect the data do not
hold, next to a finger model that already explains the drift it would) crawls for hundreds,
ends no better than the current model, and is then fitted again from the neutral values."""

CRITERION = (
    "held-out information criterion H = n_eff ln(MSE_held-out) + 2k (k free parameters, n_eff "
    "the held-out sample count corrected for lag-1 autocorrelation); an effect is added when "
    "it lowers H, cuts the held-out RMSE by at least {min_improvement:.0%}, and the residual "
    "shows structure against its signature"
)


@dataclass(frozen=True)
class LoopSettings:
    """Thresholds of the loop (module docstring).

    Attributes:
        min_improvement: relative fall of the held-out RMSE an added effect must bring.
        alpha: significance level of the residual F-tests.
        min_eta2: share of residual variance a regressor must explain for the final residual to
            count as structured (10 %: samples of one stroke share its speed and force, so a
            slow sensor drift left per stroke already explains a few percent by chance).
        signature_eta2: share an effect's signature regressor must explain in the current
            residual for the effect to be credited.
        min_autocorrelation: lag-1 autocorrelation of the final residual above which it counts
            as structured in time.
        max_effects: most effects added.
        bins: quantile bins of the residual analysis.
    """

    min_improvement: float = 0.05
    alpha: float = 0.01
    min_eta2: float = 0.10
    signature_eta2: float = 0.01
    min_autocorrelation: float = 0.5
    max_effects: int = 4
    bins: int = 10

    def criterion(self) -> str:
        """The selection criterion in words, with this instance's thresholds."""
        return CRITERION.format(min_improvement=self.min_improvement)


@dataclass(frozen=True)
class ModelFit:
    """One fitted model of the loop.

    Attributes:
        effects: names of the effects in the model, in the order added.
        fit: the fit (its predictor outputs the lateral force, N).
        analysis: the residual analysis of all samples under this model.
        score: held-out criterion ``H`` at the ``n_eff`` of the round that produced it.
    """

    effects: tuple[str, ...]
    fit: FitResult
    analysis: ResidualReport
    score: float

    @property
    def test_rmse(self) -> float:
        """Held-out RMSE, N."""
        return float(self.fit.test_rmse) if self.fit.test_rmse is not None else math.nan

    @property
    def train_rmse(self) -> float:
        """Training RMSE, N."""
        return self.fit.train_rmse


@dataclass(frozen=True)
class Candidate:
    """One effect tried in one round.

    Attributes:
        round: 1-based round number.
        effect: effect name.
        test_rmse: held-out RMSE with the effect added, N (None when not fitted).
        improvement: relative fall of the held-out RMSE against the round's current model.
        score_change: change of ``H`` against the current model (negative is better).
        added_parameters: number of parameters the effect adds.
        signature_eta2: the largest eta^2 among the effect's signature regressors in the current
            residual.
        accepted: whether the effect was added.
        note: why it was (not) added, or why it was not fitted.
        seconds: wall time of its fit, s.
    """

    round: int
    effect: str
    test_rmse: float | None
    improvement: float | None
    score_change: float | None
    added_parameters: int
    signature_eta2: float
    accepted: bool
    note: str
    seconds: float = 0.0


@dataclass(frozen=True)
class Structure:
    """Where the residual of the final model is still structured.

    Attributes:
        regressors: ``(name, eta2, p)`` of each structured regressor, strongest first.
        autocorrelation: lag-1 autocorrelation of the residual in time order.
        in_time: whether it counts as structured in time.
        dominant_frequency_hz: largest non-DC spectral peak of the residual, Hz (or None).
    """

    regressors: tuple[tuple[str, float, float], ...]
    autocorrelation: float
    in_time: bool
    dominant_frequency_hz: float | None

    @property
    def any(self) -> bool:
        """Whether any structure is left."""
        return bool(self.regressors) or self.in_time

    def describe(self) -> str:
        """Where the structure is, in words."""
        parts = [f"{name} (eta2 {eta2:.2f})" for name, eta2, _ in self.regressors]
        if self.in_time:
            where = f"in time (lag-1 autocorrelation {self.autocorrelation:.2f}"
            if self.dominant_frequency_hz is not None:
                where += f", dominant frequency {self.dominant_frequency_hz:.3g} Hz"
            parts.append(where + ")")
        return "against " + ", ".join(parts) if parts else "none"


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found.

    Attributes:
        model: name of the base predictor.
        verdict: :data:`NO_EFFECT`, :data:`EXPLAINED` or :data:`NOT_EXPLAINED`.
        summary: one paragraph: the error before and after and what was added or left.
        before: the base model's fit.
        after: the final model's fit (``before`` when nothing was added).
        steps: every accepted model, the base first.
        candidates: every effect tried, round by round.
        structure: structure left in the final residual.
        library: names of the effects in the library.
        skipped: effect name -> why it could not be tried on this model or these data.
        data: the data fitted.
        settings: the thresholds.
        seconds: wall time of the loop, s.
        effects_added: names of the effects added, in order.
        unit: unit of the observed quantity and of the errors (``"N"`` for a lateral force).
        observation: what the data's observed values are (:data:`OBSERVATIONS`).
    """

    model: str
    verdict: str
    summary: str
    before: ModelFit
    after: ModelFit
    steps: tuple[ModelFit, ...]
    candidates: tuple[Candidate, ...]
    structure: Structure
    library: tuple[str, ...]
    skipped: dict[str, str]
    data: CalibrationData
    settings: LoopSettings
    seconds: float = 0.0
    effects_added: tuple[str, ...] = field(default=())
    unit: str = "N"
    observation: str = "lateral_force"

    @property
    def improvement(self) -> float:
        """Relative fall of the held-out RMSE from before to after."""
        return 1.0 - self.after.test_rmse / self.before.test_rmse

    def effect_parameters(self, name: str) -> dict[str, tuple[float, float, str]]:
        """An added effect's fitted parameters: short name -> (value, uncertainty, unit)."""
        prefix = f"{name}."
        units = {p.name: p.unit for p in self.after.fit.predictor.parameters}
        return {
            key[len(prefix) :]: (
                value,
                self.after.fit.uncertainties.get(key, math.nan),
                units.get(key, ""),
            )
            for key, value in self.after.fit.params.items()
            if key.startswith(prefix)
        }


Progress = Callable[[str], None]


def format_error(value: float, unit: str) -> str:
    """An error for people: forces in mN, other units as they are."""
    if unit == "N":
        return f"{value * 1e3:.4g} mN"
    return f"{value:.4g} {unit}".rstrip()


def default_free(base: Predictor) -> tuple[str, ...]:
    """The base parameters a calibration fits by default: the predictor's ``calibrated``
    attribute when it sets one, else all of its parameters."""
    chosen = tuple(getattr(base, "calibrated", ()) or ())
    return chosen or tuple(p.name for p in base.parameters)


OBSERVATIONS = ("lateral_force", "output")
"""What the data's ``observed`` array is: the lateral force a tribometer measures (the model is
wrapped by :func:`~hcard.calibration.observation.lateral_force_model`), or the model's own output
(e.g. an electrostatic force measured on a scale)."""


def _model(
    base: Predictor, effects: Sequence[Effect], start: Mapping[str, float], observation: str
) -> Predictor:
    """The model of the observation of ``base`` with ``effects``, at ``start`` where it names
    one."""
    model = augment(base, effects)
    if observation == "lateral_force":
        model = lateral_force_model(model)
    known = {p.name for p in model.parameters}
    return model.with_params(**{k: v for k, v in start.items() if k in known})


def _free(model: Predictor, base_free: Sequence[str], effects: Sequence[Effect]) -> list[str]:
    names = {p.name for p in model.parameters}
    free = [name for name in base_free if name in names]
    free += [name for name in (FRICTION_COEFFICIENT, FORCE_OFFSET) if name in names]
    free += [f"{e.name}.{p.name}" for e in effects for p in e.parameters]
    return list(dict.fromkeys(free))


def _score(fit: FitResult, n_eff: float) -> float:
    mse = float(np.mean(fit.residuals[fit.test] ** 2))
    return n_eff * math.log(max(mse, np.finfo(float).tiny)) + 2 * fit.n_free


def _signature_eta2(effect: Effect, analysis: ResidualReport, alpha: float) -> float:
    values = [
        analysis.regressors[name].eta2
        for name in effect.signature
        if name in analysis.regressors and analysis.regressors[name].p_value < alpha
    ]
    return max(values, default=0.0)


def _structure(analysis: ResidualReport, settings: LoopSettings, time_ordered: bool) -> Structure:
    rho = analysis.time.lag1_autocorrelation
    return Structure(
        regressors=tuple(analysis.structured(settings.alpha, settings.min_eta2)),
        autocorrelation=rho,
        in_time=time_ordered and rho >= settings.min_autocorrelation,
        dominant_frequency_hz=analysis.time.dominant_frequency_hz,
    )


def calibrate(
    data: CalibrationData,
    base: Predictor,
    library: Sequence[Effect],
    *,
    free: Sequence[str] | None = None,
    settings: LoopSettings | None = None,
    progress: Progress | None = None,
    observation: str = "lateral_force",
) -> CalibrationResult:
    """Run the calibration loop (module docstring) and return what it found.

    Args:
        data: prepared recordings with a held-out split
            (:func:`~hcard.calibration.dataset.prepare`).
        base: the model to calibrate (any predictor whose output is a relative friction, an
            electrostatic force or a lateral force).
        library: the candidate effects (e.g. every registered calibration effect).
        free: base parameters to fit (default :func:`default_free`).
        settings: thresholds (default :class:`LoopSettings`).
        progress: called with one line of text per fit.
        observation: what ``data.observed`` is (:data:`OBSERVATIONS`): the lateral force, N
            (default), or the model's own output in its unit.

    Raises:
        PredictorError: an unusable base model, unknown free parameters, no held-out samples,
            or a base fit that fails.
    """
    settings = settings or LoopSettings()
    if observation not in OBSERVATIONS:
        raise PredictorError(
            f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}"
        )
    say = progress or (lambda _text: None)
    unit = "N" if observation == "lateral_force" else base.output.unit
    started = time.perf_counter()
    if not data.test.any():
        raise PredictorError("the data have no held-out samples; the loop needs a split")
    base_free = tuple(free) if free is not None else default_free(base)
    unknown = sorted(set(base_free) - {p.name for p in base.parameters})
    if unknown:
        raise PredictorError(
            f"{base.name}: unknown parameter(s) {', '.join(unknown)} to fit; parameters: "
            f"{', '.join(p.name for p in base.parameters)}"
        )

    given = data.inputs_for(base)
    missing = sorted(v.name for v in base.inputs if v.default is None and v.name not in given)
    if missing:
        raise PredictorError(
            f"model {base.name} needs input(s) {', '.join(missing)}, which these recordings "
            f"do not provide (they give {', '.join(sorted(data.inputs))})"
        )

    def fit(effects: Sequence[Effect], start: Mapping[str, float],
            budget: int | None = None) -> FitResult:
        model = _model(base, effects, start, observation)
        wanted = {v.name for v in model.inputs}
        inputs = data.inputs_for(model)
        return fit_predictor(
            model,
            inputs,
            data.observed,
            free=_free(model, base_free, effects),
            train=data.train,
            test=data.test,
            dynamic="time" in wanted,
            max_evaluations=budget,
        )

    def fit_candidate(effect: Effect, current_fit: FitResult) -> FitResult:
        """The current model plus ``effect``, fitted from the effect's defaults; when that
        ends worse on the training data than the current model (a local minimum), fitted
        again from the effect's neutral values (which start at the current model) and the
        better of the two by training error is kept. The held-out split never chooses."""
        chosen = fit([*added, effect], current_fit.params, CANDIDATE_EVALUATIONS)
        if chosen.train_rss > current_fit.train_rss * (1.0 + 1e-9) and effect.neutral:
            neutral = {f"{effect.name}.{k}": v for k, v in effect.neutral.items()}
            second = fit([*added, effect], {**current_fit.params, **neutral})
            if second.train_rss < chosen.train_rss:
                chosen = second
        return chosen

    def analyse(result: FitResult) -> ResidualReport:
        return analyse_residuals(
            result.residuals[used],
            used_regressors,
            sample_rate_hz=data.sample_rate_hz,
            bins=settings.bins,
            # in time: the residual on the recording's own sample grid, 0 where not fitted
            series=np.where(used, result.residuals, 0.0),
            time_ordered=data.time_ordered,
        )

    used = data.used
    used_regressors = {name: values[used] for name, values in data.regressors.items()}
    skipped: dict[str, str] = {}
    usable: list[Effect] = []
    for effect in library:
        why = effect.applies_to(base)
        if why is None and not any(name in data.regressors for name in effect.signature):
            why = (
                f"its signature ({', '.join(effect.signature)}) does not vary in these data, "
                "so it cannot be identified"
            )
        if why:
            skipped[effect.name] = why
        else:
            usable.append(effect)

    say(f"fitting {base.name} on {int(data.train.sum())} training samples")
    first = fit([], {})
    n_eff = effective_samples(first.residuals[first.test])
    current = ModelFit((), first, analyse(first), _score(first, n_eff))
    say(
        f"base: held-out RMSE {format_error(current.test_rmse, unit)}, training RMSE "
        f"{format_error(current.train_rmse, unit)}"
    )
    steps = [current]
    added: list[Effect] = []
    candidates: list[Candidate] = []
    for round_number in range(1, settings.max_effects + 1):
        remaining = [e for e in usable if e not in added]
        if not remaining:
            break
        n_eff = effective_samples(current.fit.residuals[current.fit.test])
        current_score = _score(current.fit, n_eff)
        tried: list[tuple[Candidate, FitResult | None]] = []
        for effect in remaining:
            eta2 = _signature_eta2(effect, current.analysis, settings.alpha)
            tic = time.perf_counter()
            try:
                result = fit_candidate(effect, current.fit)
            except PredictorError as exc:
                tried.append(
                    (
                        Candidate(
                            round_number,
                            effect.name,
                            None,
                            None,
                            None,
                            len(effect.parameters),
                            eta2,
                            False,
                            f"fit failed: {exc}",
                            time.perf_counter() - tic,
                        ),
                        None,
                    )
                )
                say(f"round {round_number}: {effect.name}: fit failed ({exc})")
                continue
            rmse = float(result.test_rmse or math.nan)
            gain = 1.0 - rmse / current.test_rmse
            change = _score(result, n_eff) - current_score
            tried.append(
                (
                    Candidate(
                        round_number,
                        effect.name,
                        rmse,
                        gain,
                        change,
                        len(effect.parameters),
                        eta2,
                        False,
                        "",
                        time.perf_counter() - tic,
                    ),
                    result,
                )
            )
            say(
                f"round {round_number}: {effect.name}: held-out RMSE {format_error(rmse, unit)} "
                f"({-100 * gain:+.1f} %)"
            )
        fitted = [item for item in tried if item[1] is not None]

        def failure(cand: Candidate) -> str:
            """Why ``cand`` cannot be added (empty: it passes every check of the criterion)."""
            if cand.score_change >= 0:
                return "does not lower the held-out criterion"
            if cand.improvement < settings.min_improvement:
                return (
                    f"cuts the held-out RMSE by {cand.improvement:.1%}, less than "
                    f"{settings.min_improvement:.0%}"
                )
            if cand.signature_eta2 < settings.signature_eta2:
                return "the residual shows no structure against its signature"
            return ""

        passing = [item for item in fitted if not failure(item[0])]
        best = min(fitted, key=lambda item: item[0].score_change, default=None)
        chosen = min(passing, key=lambda item: item[0].score_change, default=None)
        accepted_name = chosen[0].effect if chosen is not None else None
        reason = failure(best[0]) if best is not None else ""
        for cand, _fit in tried:
            if cand.effect == accepted_name:
                note = (
                    "added: best held-out criterion"
                    if best is not None and cand is best[0]
                    else "added: best held-out criterion of the candidates that pass every check"
                )
            elif cand.test_rmse is None:
                note = cand.note
            elif accepted_name is None and best is not None and cand is best[0]:
                note = f"best of the round, not added: {reason}"
            elif failure(cand):
                note = f"not added: {failure(cand)}"
            else:
                note = "a better candidate in this round"
            candidates.append(
                Candidate(
                    cand.round,
                    cand.effect,
                    cand.test_rmse,
                    cand.improvement,
                    cand.score_change,
                    cand.added_parameters,
                    cand.signature_eta2,
                    cand.effect == accepted_name,
                    note,
                    cand.seconds,
                )
            )
        if accepted_name is None:
            break
        effect = next(e for e in remaining if e.name == accepted_name)
        result = next(r for c, r in tried if c.effect == accepted_name)
        assert result is not None
        added.append(effect)
        current = ModelFit(
            tuple(e.name for e in added), result, analyse(result), _score(result, n_eff)
        )
        steps.append(current)
        say(f"round {round_number}: added {effect.name}")

    structure = _structure(current.analysis, settings, data.time_ordered)
    before = steps[0]
    names = tuple(e.name for e in added)
    if structure.any:
        verdict = NOT_EXPLAINED
    elif added:
        verdict = EXPLAINED
    else:
        verdict = NO_EFFECT
    summary = _summary(base.name, verdict, before, current, names, structure, unit)
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
        before=before,
        after=current,
        steps=tuple(steps),
        candidates=tuple(candidates),
        structure=structure,
        library=tuple(e.name for e in library),
        skipped=skipped,
        data=data,
        settings=settings,
        seconds=time.perf_counter() - started,
        effects_added=names,
        unit=unit,
        observation=observation,
    )


def _summary(
    model: str,
    verdict: str,
    before: ModelFit,
    after: ModelFit,
    added: tuple[str, ...],
    structure: Structure,
    unit: str,
) -> str:
    change = 1.0 - after.test_rmse / before.test_rmse
    text = (
        f"held-out RMSE {format_error(before.test_rmse, unit)} before, "
        f"{format_error(after.test_rmse, unit)} after ({-100 * change:+.1f} %). "
    )
    if added:
        text += f"Added to {model}: {', '.join(added)}. "
    if verdict == NO_EFFECT:
        text += f"No effect needed: {model} explains the data; no structure is left."
    elif verdict == EXPLAINED:
        text += "No structure is left in the residual."
    else:
        text += f"Structured residual not explained by any known effect: {structure.describe()}."
    return text
