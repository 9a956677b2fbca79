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
   below; otherwise stop;
4. let the selection undo itself: with two effects in the model, score every
   pair of the library's usable effects and move to the best pair by ``H``; with more, try
   removing each accepted effect and swapping it for each unused one (a move never brings in
   an effect whose signature's structure a dominant foreign regressor explains, see (c)
   below); then drop any effect that no longer earns its place (lower ``H`` and
   ``min_improvement`` of held-out RMSE against the same model without it). Greedy addition
   alone named skin-recovery + load-index at 5.40 mN where occlusion + load-index, in the
   library, reached the truth's 5.01 mN.

**Runner-up.** The final model is compared with the best other fitted model of as many effects
(:mod:`hcard.calibration.selection`): the margin in ``H`` and in held-out RMSE is reported, and
when it is below :class:`~hcard.calibration.selection.Separation`'s thresholds the verdict is
:data:`AMBIGUOUS`, naming the regressor along which the two predictions differ most and the
measurement that would spread it.

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
against the effect's signature (F-test p < ``alpha`` with ``eta^2 >= signature_eta2``, against
one of its regressors or, chance-adjusted, against the joint cells of all of them): an effect
is never credited for an error it does not explain where it says it would. When the residual
holds structure against a *foreign* regressor, one no model input or effect signature covers
(the sliding direction, the position, the recording), and that structure is at least
:data:`FOREIGN_DOMINANCE` times the signature's, (c) is judged with it taken out
(:func:`_beyond_foreign_structure`).

**Screening** (:mod:`hcard.calibration.screening`). Candidate models (steps 2 and 4) are first
fitted on one training sample in ``k`` (about ``screen_samples`` of them); one whose screened
figures come within :data:`~hcard.calibration.screening.SCREEN_TOLERANCE` of a threshold of the
criterion, or of a rival it must be ranked against, is fitted again on every training sample,
from the same start, before the loop decides on it. The effects chosen, the verdict and every
accepted model's fit are those the loop reaches without screening (``screen_samples = 0``), and
so is the runner-up whenever it may come within the separation thresholds of the final model;
the figures of candidates far from every decision are the screened fits' (marked in the
candidate table), and among rivals far from the final model the one named runner-up may be
another within the tolerance of the best (:func:`_runner_up`).

**Verdicts.** When no candidate passes, the residual of the final model is analysed once more.
Structure left against a regressor (p < ``alpha`` and ``eta^2 >= min_eta2``) or in time
(lag-1 autocorrelation ``>= min_autocorrelation``) gives :data:`NOT_EXPLAINED`, naming where
the structure is; none gives :data:`NO_EFFECT` (nothing added), :data:`AMBIGUOUS` (effects
added, and a runner-up within the margin) or :data:`EXPLAINED` (effects added).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Container, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from hcard.calibration.bootstrap import BootstrapResult, stroke_bootstrap
from hcard.calibration.dataset import CalibrationData
from hcard.calibration.effects import Effect, augment
from hcard.calibration.fit import FitResult, fit_predictor
from hcard.calibration.noise import NoiseModel, detectable_eta2, time_structure_threshold
from hcard.calibration.observation import (
    FORCE_OFFSET,
    FRICTION_COEFFICIENT,
    lateral_force_model,
)
from hcard.calibration.residuals import (
    MIN_BIN_COUNT,
    ResidualReport,
    analyse_residuals,
    bin_labels,
    effective_samples,
    joint_structure,
)
from hcard.calibration.screening import (
    SCREEN_SAMPLES,
    SCREEN_TOLERANCE,
    criterion_band,
    may_fall_to,
    screening_mask,
)
from hcard.calibration.selection import Comparison, Separation, compare
from hcard.physics import Predictor, PredictorError
from hcard.quantities import MN_PER_N

NO_EFFECT = "no effect needed"
EXPLAINED = "explained by added effects"
NOT_EXPLAINED = "structured residual not explained by any known effect"
AMBIGUOUS = "ambiguous: the data cannot separate the final model from its runner-up"

FOREIGN_DOMINANCE = 2.0
"""How many times the signature's eta2 a foreign regressor's must be before the signature test
is judged with the foreign structure taken out (:func:`_beyond_foreign_structure`)."""

CANDIDATE_EVALUATIONS = 120
"""Most model evaluations of a candidate's fit from the effect's defaults (K7). A fit that
converges needs a few tens; one from defaults far from the data (an effect the data do not
hold, next to a finger model that already explains the drift it would) crawls for hundreds,
ends no better than the current model, and is then fitted again from the neutral values."""

CRITERION = (
    "held-out information criterion H = n_eff ln(MSE_held-out) + 2k (k free parameters, n_eff "
    "the held-out sample count corrected for lag-1 autocorrelation); an effect is added when "
    "it lowers H, cuts the held-out RMSE by at least {min_improvement:.0%}, and the residual "
    "shows structure against its signature (one regressor, or all of them jointly)"
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
        signature_eta2: share of the current residual an effect's signature must explain
            (one of its regressors, or their joint cells chance-adjusted) for the effect to be
            credited.
        min_autocorrelation: lag-1 autocorrelation of the final residual above which it counts
            as structured in time.
        max_effects: most effects added.
        bins: quantile bins of the residual analysis.
        separation_criterion: smallest difference of ``H`` between the final model and its
            runner-up for the data to separate them.
        separation_rmse: smallest relative difference of their held-out RMSE for the same.
        screen_samples: training samples a candidate is first fitted on (every ``k``-th,
            :mod:`hcard.calibration.screening`); candidates whose screened figures come near a
            decision are fitted on every training sample before it is made. 0: every candidate
            is fitted on every training sample.
    """

    min_improvement: float = 0.05
    alpha: float = 0.01
    min_eta2: float = 0.10
    signature_eta2: float = 0.01
    min_autocorrelation: float = 0.5
    max_effects: int = 4
    bins: int = 10
    separation_criterion: float = 10.0
    separation_rmse: float = 0.01
    screen_samples: int = SCREEN_SAMPLES

    def separation(self) -> Separation:
        """The thresholds below which the final model and its runner-up are not separated."""
        return Separation(self.separation_criterion, self.separation_rmse)

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
        signature_eta2: the largest significant eta^2 of the current residual against the
            effect's signature: a single regressor, or their joint cells chance-adjusted.
        accepted: whether the effect was added.
        note: why it was (not) added, or why it was not fitted.
        seconds: wall time of its fit, s.
        screened: whether its figures are those of a fit on the screening samples only
            (:mod:`hcard.calibration.screening`; the held-out RMSE scaled by its start
            model's full over screened one): far enough from every threshold that a full fit
            could not change the decision.
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
    screened: bool = False


def _known(figure: float | None) -> float:
    """A :class:`Candidate` figure that its fit has set (every fitted candidate has them)."""
    assert figure is not None
    return figure


@dataclass(frozen=True)
class Structure:
    """Where the residual of the final model is still structured.

    Attributes:
        regressors: ``(name, eta2, p)`` of each structured regressor, strongest first.
        autocorrelation: lag-1 autocorrelation of the residual in time order.
        in_time: whether it counts as structured in time.
        dominant_frequency_hz: largest non-DC spectral peak of the residual, Hz (or None).
        small: ``(name, eta2, p)`` of each regressor with significant structure (p < alpha)
            below the practical threshold ``min_eta2``: reported, not acted on.
        time_threshold: lag-1 autocorrelation above which the residual counts as structured
            in time (from the noise model, :func:`~hcard.calibration.noise.
            time_structure_threshold`).
        noise: the sensor noise measured out of contact, or None.
        min_eta2: the practical threshold of ``eta^2``.
        detectable: ``(name, eta2)``: the smallest ``eta^2`` each regressor's F-test detects
            with 80 % power at the residual's effective sample count.
    """

    regressors: tuple[tuple[str, float, float], ...]
    autocorrelation: float
    in_time: bool
    dominant_frequency_hz: float | None
    small: tuple[tuple[str, float, float], ...] = ()
    time_threshold: float = 0.5
    noise: NoiseModel | None = None
    min_eta2: float = 0.10
    detectable: tuple[tuple[str, float], ...] = ()

    @property
    def any(self) -> bool:
        """Whether any structure is left."""
        return bool(self.regressors) or self.in_time

    def describe(self) -> str:
        """Where the structure is, in words."""
        parts = [f"{name} (eta2 {eta2:.2f})" for name, eta2, _ in self.regressors]
        if self.in_time:
            where = f"in time (lag-1 autocorrelation {self.autocorrelation:.2f}"
            if self.noise is not None and self.noise.lag1 > 0:
                where += f" against {self.noise.lag1:.2f} of the sensor noise"
            if self.dominant_frequency_hz is not None:
                where += f", dominant frequency {self.dominant_frequency_hz:.3g} Hz"
            parts.append(where + ")")
        return "against " + ", ".join(parts) if parts else "none"

    def describe_small(self) -> str:
        """The small but significant structure, in words (empty when there is none)."""
        if not self.small:
            return ""
        shown = ", ".join(
            f"{name}: eta2 {eta2:.3f}, p {_p_text(p)}" for name, eta2, p in self.small
        )
        return f"small structure against {shown}, below the practical threshold of " \
            f"eta2 {self.min_eta2:g}"


def _p_text(p: float) -> str:
    """A p-value for people: ``< 1e-6`` below that, else ``= 0.0012``."""
    return "< 1e-6" if p < 1e-6 else f"= {p:.2g}"


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
        comparison: the final model against the best other model of as many effects (one
            effect when none was added), or None when no other was fitted.
        bootstrap: the final model's parameter uncertainties from a stroke-block bootstrap
            (:func:`with_bootstrap`), or None: the uncertainties are then the fit's
            ``sigma^2 (J^T J)^-1``.
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
    comparison: Comparison | None = None
    bootstrap: BootstrapResult | None = None

    @property
    def uncertainty_method(self) -> str:
        """Which uncertainty the parameters carry and how it was computed."""
        if self.bootstrap is not None:
            return self.bootstrap.method()
        return (
            "sigma^2 (J^T J)^-1 of the fit, which takes every training sample as independent "
            "white noise: an under-estimate when the residual is correlated (a stroke-block "
            "bootstrap was not run)"
        )

    @property
    def improvement(self) -> float:
        """Relative fall of the held-out RMSE from before to after."""
        return 1.0 - self.after.test_rmse / self.before.test_rmse

    def effect_parameters(self, name: str) -> dict[str, tuple[float, float, str]]:
        """An added effect's fitted parameters: short name -> (value, uncertainty, unit); the
        uncertainty is the bootstrap's when one was run (:attr:`uncertainty_method`)."""
        prefix = f"{name}."
        units = {p.name: p.unit for p in self.after.fit.predictor.parameters}
        sigma = (
            self.after.fit.uncertainties if self.bootstrap is None
            else self.bootstrap.uncertainties
        )
        return {
            key[len(prefix) :]: (
                value,
                sigma.get(key, math.nan),
                units.get(key, ""),
            )
            for key, value in self.after.fit.params.items()
            if key.startswith(prefix)
        }


Progress = Callable[[str], None]


def format_error(value: float, unit: str) -> str:
    """An error for people: forces in mN, other units as they are."""
    if unit == "N":
        return f"{value * MN_PER_N:.4g} mN"
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


def _rss(fit: FitResult, samples: np.ndarray) -> float:
    """Residual sum of squares of ``fit`` over the ``samples`` mask (its residuals cover every
    sample, so a fit on the screening samples is measured on the whole training split too)."""
    return float(np.sum(fit.residuals[samples] ** 2))


def _score(fit: FitResult, n_eff: float) -> float:
    mse = float(np.mean(fit.residuals[fit.test] ** 2))
    return n_eff * math.log(max(mse, np.finfo(float).tiny)) + 2 * fit.n_free


def _signature_eta2(effect: Effect, analysis: ResidualReport, residual: np.ndarray,
                    regressors: Mapping[str, np.ndarray], alpha: float) -> float:
    """How much of ``residual`` (the current model's, on the samples in use) lies where
    ``effect`` says its error would: the largest significant (p < ``alpha``) eta2 of a single
    signature regressor, or, for a signature of several regressors, the chance-adjusted eta2
    of their joint cells (:func:`~hcard.calibration.residuals.joint_structure`). An effect on
    the electrostatic force shows only where there is voltage: on the load alone its residual
    read eta2 0.009, jointly on load and voltage 0.09."""
    values = [
        analysis.regressors[name].eta2
        for name in effect.signature
        if name in analysis.regressors and analysis.regressors[name].p_value < alpha
    ]
    present = [name for name in effect.signature if name in regressors]
    if len(present) >= 2:
        joint = joint_structure(residual, {name: regressors[name] for name in present},
                                analysis.effective_samples)
        if joint.p_value < alpha:
            values.append(joint.adjusted_eta2)
    return max(values, default=0.0)


def _beyond_foreign_structure(
    effect: Effect,
    analysis: ResidualReport,
    residual: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    claimed: frozenset[str],
    settings: LoopSettings,
) -> tuple[float, str | None]:
    """:func:`_signature_eta2` of the residual with its structure against the strongest
    *foreign* regressor taken out: one that is neither an input of the models nor in a usable
    effect's signature (``claimed``: the sliding direction, the position and the recording are
    foreign) and that holds significant structure
    (p < ``alpha``, ``eta^2 >= min_eta2``). Its bin means are subtracted, and the residual
    analysed again on the effect's signature. Returns that eta2 and the foreign regressor
    (None, and the plain eta2, when there is none).

    Only a foreign regressor that explains :data:`FOREIGN_DOMINANCE` times the signature's
    share is taken out: it is then the likelier cause. One that merely matches it is the
    effect's own structure seen through the design (a recording per ambient pressure: the
    recording holds the pressure's structure exactly), and taking it out would hide the effect.
    An effect is credited only for structure that is not the foreign regressor's seen through
    a correlated design: with friction 20 % higher sliding towards -x and back-and-forth
    strokes that start every session in the same direction, the stroke count after a rest
    carries the direction, and skin-recovery (signature: stroke) cut the held-out error by
    more than 5 % without any recovery in the data."""
    plain = _signature_eta2(effect, analysis, residual, regressors, settings.alpha)
    foreign = [
        stats for name, stats in analysis.regressors.items()
        if name not in claimed and name in regressors and stats.p_value < settings.alpha
        and stats.eta2 >= max(settings.min_eta2, FOREIGN_DOMINANCE * plain)
    ]
    if not foreign:
        return plain, None
    strongest = max(foreign, key=lambda stats: stats.eta2)
    labels = bin_labels(np.asarray(regressors[strongest.name], dtype=np.float64),
                        settings.bins)
    means = np.bincount(labels, weights=residual) / np.maximum(np.bincount(labels), 1)
    controlled = residual - means[labels]
    own = {name: regressors[name] for name in effect.signature if name in regressors}
    again = analyse_residuals(controlled, own, bins=settings.bins)
    return min(plain, _signature_eta2(effect, again, controlled, own, settings.alpha)), \
        strongest.name


def _structure(
    analysis: ResidualReport,
    settings: LoopSettings,
    time_ordered: bool,
    noise: NoiseModel | None = None,
) -> Structure:
    rho = analysis.time.lag1_autocorrelation
    threshold = time_structure_threshold(settings.min_autocorrelation, noise)
    significant = analysis.structured(settings.alpha, 0.0)
    detectable = tuple(
        (
            name,
            detectable_eta2(
                analysis.effective_samples,
                int(np.count_nonzero(s.bin_counts >= MIN_BIN_COUNT)),
                settings.alpha,
            ),
        )
        for name, s in analysis.regressors.items()
    )
    return Structure(
        regressors=tuple(item for item in significant if item[1] >= settings.min_eta2),
        autocorrelation=rho,
        in_time=time_ordered and rho >= threshold,
        dominant_frequency_hz=analysis.time.dominant_frequency_hz,
        small=tuple(item for item in significant if item[1] < settings.min_eta2),
        time_threshold=threshold,
        noise=noise,
        min_eta2=settings.min_eta2,
        detectable=detectable,
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
            budget: int | None = None, train: np.ndarray | None = None) -> FitResult:
        model = _model(base, effects, start, observation)
        wanted = {v.name for v in model.inputs}
        inputs = data.inputs_for(model)
        return fit_predictor(
            model,
            inputs,
            data.observed,
            free=_free(model, base_free, effects),
            train=data.train if train is None else train,
            test=data.test,
            dynamic="time" in wanted,
            max_evaluations=budget,
        )

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

    # what the models can act on: the base's inputs, and every usable effect's inputs and
    # signature; structure against anything else (direction, position, recording) is foreign
    claimed = frozenset(
        {v.name for v in base.inputs}
        | {name for effect in usable for name in effect.signature}
        | {v.name for effect in usable for v in effect.inputs}
    )
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
    # every model fitted, by its set of effect names: (effects in order, fit)
    pool: dict[frozenset[str], tuple[tuple[Effect, ...], FitResult]] = {frozenset(): ((), first)}
    visited: set[frozenset[str]] = {frozenset()}

    # Screening (hcard.calibration.screening): a candidate is first fitted on every k-th
    # training sample; the pool marks such a fit with how to fit it on every training sample
    # (the start of the round that tried it, or None: from its best fitted subset, as
    # fitted_set does), which `confirmed` does before any decision its figures could not make.
    # A screened fit's figures are read through its start model's: `scale[key]` is the
    # start's held-out RMSE fitted in full over the same model refitted on the screening
    # samples (a fit on fewer samples generalises a little worse, 4 % on a high-pass with
    # 7.7 ms against samples 8 ms apart; the candidate's share of that is the start's).
    screen = screening_mask(data.train, settings.screen_samples)
    screened: dict[frozenset[str], tuple[tuple[Effect, ...], Effect, FitResult] | None] = {}
    scale: dict[frozenset[str], float] = {}
    references: dict[int, tuple[FitResult, float]] = {}  # by id of the start fit (kept)

    dynamic_sets: dict[frozenset[str], bool] = {}

    def evaluates_every_sample(effects: Sequence[Effect]) -> bool:
        """Whether the model with ``effects`` has memory (a ``time`` input): its fit evaluates
        it on every sample whatever the training split (``fit_predictor``'s ``dynamic``), so a
        screened fit saves only the optimiser's algebra, not worth its full refits near
        decisions; such candidates are fitted on every training sample at once."""
        key = frozenset(e.name for e in effects)
        if key not in dynamic_sets:
            model = _model(base, effects, {}, observation)
            dynamic_sets[key] = "time" in {v.name for v in model.inputs}
        return dynamic_sets[key]

    def reference_scale(start: FitResult) -> float | None:
        """Full over screened held-out RMSE of the model fitted in full as ``start``:
        ``start``'s RMSE over that of the same model (``start.predictor``: its effects in the
        order it was fitted with) refitted on the screening samples from ``start``'s
        parameters, once per fit; None when that refit fails."""
        if id(start) not in references:
            model = start.predictor
            try:
                again = fit_predictor(
                    model, data.inputs_for(model), data.observed, free=start.free,
                    train=screen, test=data.test,
                    dynamic="time" in {v.name for v in model.inputs},
                    max_evaluations=CANDIDATE_EVALUATIONS)
                ratio = float(start.test_rmse or math.nan) / float(again.test_rmse or math.nan)
            except PredictorError:
                ratio = math.nan
            references[id(start)] = (start, ratio)
        ratio = references[id(start)][1]
        return ratio if math.isfinite(ratio) and ratio > 0 else None

    def held_out(key: frozenset[str]) -> float:
        """The pool's held-out RMSE of ``key``: a screened one scaled (``scale``)."""
        return float(pool[key][1].test_rmse or math.nan) * scale.get(key, 1.0)

    def criterion(key: frozenset[str], n_eff: float) -> float:
        """``H`` of the pool's model ``key`` at ``n_eff``, from :func:`held_out`'s RMSE."""
        return _score(pool[key][1], n_eff) + 2.0 * n_eff * math.log(scale.get(key, 1.0))

    def fit_with(effects: Sequence[Effect], new: Effect, start: FitResult,
                 train: np.ndarray | None = None) -> FitResult:
        """``effects`` plus ``new``, from ``start``'s parameters and ``new``'s defaults; when
        that ends worse on the training data than ``start`` (a local minimum), fitted again
        from ``new``'s neutral values (which start at ``start``'s model) and the better of the
        two by training error is kept. The held-out split never chooses. ``train``: the
        training samples (default: all of them; the screening samples when screening)."""
        mask = data.train if train is None else train
        chosen = fit([*effects, new], start.params, CANDIDATE_EVALUATIONS, train)
        if _rss(chosen, mask) > _rss(start, mask) * (1.0 + 1e-9) and new.neutral:
            neutral = {f"{new.name}.{k}": v for k, v in new.neutral.items()}
            second = fit([*effects, new], {**start.params, **neutral}, train=train)
            if _rss(second, mask) < _rss(chosen, mask):
                chosen = second
        return chosen

    def screen_with(effects: Sequence[Effect], new: Effect, start: FitResult) -> FitResult:
        """The round's candidate ``effects`` plus ``new`` from ``start``, fitted on the
        screening samples and pooled as screened (on every training sample, and pooled as
        such, without screening or when the screened fit fails)."""
        key = frozenset([*(e.name for e in effects), new.name])
        worth = screen is not None and not evaluates_every_sample([*effects, new])
        ratio = reference_scale(start) if worth else None
        if ratio is not None:
            try:
                result = fit_with(effects, new, start, screen)
            except PredictorError:
                pass
            else:
                pool[key] = ((*effects, new), result)
                screened[key] = (tuple(effects), new, start)
                scale[key] = ratio
                return result
        result = fit_with(effects, new, start)
        pool[key] = ((*effects, new), result)
        return result

    failures: dict[frozenset[str], str] = {}

    def confirmed(key: frozenset[str]) -> FitResult | None:
        """The pool's model ``key`` fitted on every training sample, as it is fitted without
        screening: fitted now when the pool holds a screened fit of it (its place in the pool
        kept). None when that fit fails (the reason in ``failures``; the model leaves the
        pool) or the model was never fitted."""
        if key not in screened:
            entry = pool.get(key)
            return entry[1] if entry is not None else None
        recipe = screened.pop(key)
        scale.pop(key, None)
        effects = pool[key][0]
        say(f"{' + '.join(e.name for e in effects)}: fitting on every training sample (its "
            "screened figures are near a decision)")
        if recipe is None:
            result = from_subsets(effects, exact=True)
        else:
            others, new, start = recipe
            try:
                result = fit_with(others, new, start)
            except PredictorError as exc:
                failures[key] = str(exc)
                say(f"{' + '.join(e.name for e in effects)}: fit failed ({exc})")
                result = None
        if result is None:
            pool.pop(key, None)
            return None
        pool[key] = (effects, result)
        return result

    def fitted_set(effects: Sequence[Effect], exact: bool = False) -> FitResult | None:
        """The fit of the model with ``effects`` (from the pool, else fitted now from the best
        fitted model that lacks one of them); None when its fit fails. ``exact``: on every
        training sample (a screened fit in the pool is fitted again), else the pool's fit
        as it is, and a new fit screened."""
        key = frozenset(e.name for e in effects)
        if key in pool:
            return confirmed(key) if exact else pool[key][1]
        return from_subsets(effects, exact)

    def from_subsets(effects: Sequence[Effect], exact: bool) -> FitResult | None:
        """``effects`` fitted from the best fitted model that lacks one of them (by training
        error over the whole training split), pooled; screened unless ``exact``. None when the
        fit fails."""
        key = frozenset(e.name for e in effects)
        best: tuple[Effect, FitResult] | None = None
        for effect in effects:
            others = [e for e in effects if e is not effect]
            smaller = fitted_set(others, exact)
            if smaller is not None and (
                best is None or _rss(smaller, data.train) < _rss(best[1], data.train)
            ):
                best = (effect, smaller)
        if best is None:
            return None
        new, start = best
        rest = [e for e in effects if e is not new]
        start_key = frozenset(e.name for e in rest)
        if not exact and screen is not None and not evaluates_every_sample(effects):
            ratio = (scale.get(start_key) if start_key in screened
                     else reference_scale(start))
            if ratio is None:  # fitted in full from full subsets, as without screening
                return from_subsets(effects, exact=True)
            try:
                result = fit_with(rest, new, start, screen)
            except PredictorError:
                return from_subsets(effects, exact=True)
            pool[key] = (tuple(effects), result)
            screened[key] = None
            scale[key] = ratio
            return result
        try:
            result = fit_with(rest, new, start)
        except PredictorError as exc:
            failures[key] = str(exc)
            say(f"{' + '.join(e.name for e in effects)}: fit failed ({exc})")
            return None
        pool[key] = (tuple(effects), result)
        return result

    def earns_place(with_it: FitResult, without: FitResult, n_eff: float) -> str:
        """Why the effect that makes ``without`` into ``with_it`` does not earn its place
        (empty: it does): it must lower ``H`` and cut the held-out RMSE by
        ``min_improvement``."""
        if _score(with_it, n_eff) >= _score(without, n_eff):
            return "does not lower the held-out criterion"
        gain = 1.0 - float(with_it.test_rmse or math.nan) / float(without.test_rmse or math.nan)
        if not gain >= settings.min_improvement:
            return f"cuts the held-out RMSE by {gain:.1%}, less than {settings.min_improvement:.0%}"
        return ""

    def credited(effect: Effect, effects: Sequence[Effect]) -> bool:
        """Whether ``effect`` may come into the set ``effects`` by a move: not when a dominant
        foreign regressor explains its signature's structure in the residual of the set
        without it (:func:`_beyond_foreign_structure`). A move judged by ``H`` alone may
        otherwise bring in a signature that shows little structure at low power (a load
        index over a few force levels)."""
        without = fitted_set([e for e in effects if e is not effect], exact=True)
        if without is None:
            return False
        eta2, foreign = _beyond_foreign_structure(effect, analyse(without),
                                                  without.residuals[used], used_regressors,
                                                  claimed, settings)
        return foreign is None or eta2 >= settings.signature_eta2

    def returns_to_own(key: frozenset[str], own: frozenset[str], n_eff: float) -> bool:
        """Whether a move from the set ``own`` (fitted in full) to the screened set ``key``
        would be undone by the pruning that follows it, whatever ``key``'s full fit: ``key``
        is ``own`` plus one effect whose held-out RMSE cannot fall by ``min_improvement``
        against ``own``'s (it does not earn its place), while with ``own``'s single effect
        the set beats that effect alone by ``H`` and by ``min_improvement`` for certain (it
        earns its place), all within the screening tolerance."""
        extra = key - own
        alone = frozenset(extra)
        if len(own) != 1 or not own < key or len(extra) != 1 or alone not in pool:
            return False
        rmse = held_out(key)
        if may_fall_to(rmse, (1.0 - settings.min_improvement) * held_out(own)):
            return False
        spread = SCREEN_TOLERANCE if alone in screened else 0.0
        other_low = criterion(alone, n_eff) - (criterion_band(n_eff) if spread else 0.0)
        if not criterion(key, n_eff) + criterion_band(n_eff) < other_low:
            return False
        gain = 1.0 - rmse * (1.0 + SCREEN_TOLERANCE) / (held_out(alone) * (1.0 - spread))
        return gain >= settings.min_improvement

    def revise(round_number: int, chosen: list[Effect], reference: ModelFit,
               size: int) -> list[Effect]:
        """The best set of ``size`` effects near ``chosen`` (every single effect or every pair
        of the usable effects for a size of one or two, else every swap of one accepted effect
        for an unused one), when it beats ``chosen`` by ``H``; then any effect that no longer
        earns its place against the same set without it is dropped. ``n_eff`` is that of the
        better of ``reference`` and ``chosen``'s held-out residual; ``reference`` (the round's
        current model) sets the changes shown in the candidate table."""
        chosen = list(chosen)
        n_eff = max(
            effective_samples(reference.fit.residuals[data.test]),
            effective_samples(pool[frozenset(e.name for e in chosen)][1].residuals[data.test]),
        )
        if size <= 2:
            alternatives = [list(group) for group in itertools.combinations(usable, size)]
            note = f"{'pair' if size == 2 else 'swap'}, every one of the library scored"
        else:
            alternatives = [
                [*(e for e in chosen if e is not out), swap]
                for out in chosen
                for swap in usable
                if swap not in chosen
            ]
            note = "swap of one accepted effect for an unused one"
        scores = {}
        fresh: list[tuple[frozenset[str], float]] = []
        for effects in alternatives:
            key = frozenset(e.name for e in effects)
            tic = time.perf_counter()
            known = key in pool
            result = fitted_set(effects)
            if result is None:
                continue
            scores[key] = (effects, result, criterion(key, n_eff))
            if not known:
                fresh.append((key, time.perf_counter() - tic))
        own = frozenset(e.name for e in chosen)
        own_score = _score(pool[own][1], n_eff)
        # a screened set that may beat the current one is fitted on every training sample
        # before the move is judged, unless every such set is the current one plus an
        # effect that pruning would take out again (`returns_to_own`): the current set stays
        band = criterion_band(n_eff)
        doubtful = [key for key, (_, _, score) in scores.items()
                    if key in screened and score - band < own_score]
        better = [key for key, (_, _, score) in scores.items()
                  if key not in screened and key != own and score < own_score]
        stay = (bool(doubtful) and not better
                and all(returns_to_own(key, own, n_eff) for key in doubtful))
        for key, (effects, _result, score) in list(scores.items()):
            if key in screened and score - band < own_score and not stay:
                tic = time.perf_counter()
                exact = confirmed(key)
                if exact is None:
                    del scores[key]
                else:
                    scores[key] = (effects, exact, _score(exact, n_eff))
                fresh = [(k, t + time.perf_counter() - tic if k == key else t)
                         for k, t in fresh]
        for key, seconds in fresh:
            if key not in scores:
                continue
            effects, result, score = scores[key]
            rmse = held_out(key)
            say(f"round {round_number}: {' + '.join(sorted(key))}: held-out RMSE "
                f"{format_error(rmse, unit)}{' (screened)' if key in screened else ''}")
            candidates.append(
                Candidate(round_number, " + ".join(e.name for e in effects), rmse,
                          1.0 - rmse / reference.test_rmse,
                          score - _score(reference.fit, n_eff),
                          sum(len(e.parameters) for e in effects), 0.0, False,
                          note, seconds, screened=key in screened)
            )
        for key in sorted(scores, key=lambda k: scores[k][2]):
            if stay or key == own or scores[key][2] >= own_score:
                break
            effects = scores[key][0]
            uncredited = [e.name for e in effects if e not in chosen and not credited(e, effects)]
            if uncredited:
                say(f"round {round_number}: not moved to {' + '.join(sorted(key))}: the "
                    f"structure against the signature of {', '.join(uncredited)} is a foreign "
                    "regressor's")
                continue
            chosen = list(effects)
            say(f"round {round_number}: moved to {' + '.join(e.name for e in chosen)}")
            break
        while chosen:
            whole = confirmed(frozenset(e.name for e in chosen))
            assert whole is not None  # the set moved to, or a subset that earned its place
            reasons = {}
            for effect in chosen:
                without = fitted_set([e for e in chosen if e is not effect], exact=True)
                if without is not None:
                    why = earns_place(whole, without, n_eff)
                    if why:
                        reasons[effect.name] = (why, _score(without, n_eff))
            if not reasons:
                break
            weakest = min(reasons, key=lambda name: reasons[name][1])
            chosen = [e for e in chosen if e.name != weakest]
            say(f"round {round_number}: removed {weakest}: {reasons[weakest][0]}")
        return chosen

    def is_screened(item: tuple[Candidate, FitResult | None]) -> bool:
        """Whether a candidate of the current round holds a screened fit."""
        cand, result = item
        return result is not None and frozenset(
            [*(e.name for e in added), cand.effect]) in screened

    def settle(tried: list[tuple[Candidate, FitResult | None]], index: int,
               round_number: int, n_eff: float, current_score: float) -> None:
        """Fit the screened candidate ``tried[index]`` of the current round on every training
        sample; its row takes the full fit's figures (or says the fit failed)."""
        cand = tried[index][0]
        key = frozenset([*(e.name for e in added), cand.effect])
        tic = time.perf_counter()
        exact = confirmed(key)
        seconds = cand.seconds + time.perf_counter() - tic
        if exact is None:
            tried[index] = (replace(cand, test_rmse=None, improvement=None, score_change=None,
                                    seconds=seconds,
                                    note=f"fit failed: {failures.get(key, '')}"), None)
            return
        rmse = float(exact.test_rmse or math.nan)
        gain = 1.0 - rmse / current.test_rmse
        tried[index] = (replace(cand, test_rmse=rmse, improvement=gain,
                                score_change=_score(exact, n_eff) - current_score,
                                seconds=seconds), exact)
        say(f"round {round_number}: {cand.effect}: held-out RMSE {format_error(rmse, unit)} "
            f"({-100 * gain:+.1f} %) on every training sample")

    for round_number in range(1, settings.max_effects + 1):
        remaining = [e for e in usable if e not in added]
        if not remaining:
            break
        n_eff = effective_samples(current.fit.residuals[current.fit.test])
        current_score = _score(current.fit, n_eff)
        tried: list[tuple[Candidate, FitResult | None]] = []
        for effect in remaining:
            eta2, _ = _beyond_foreign_structure(effect, current.analysis,
                                                current.fit.residuals[used], used_regressors,
                                                claimed, settings)
            tic = time.perf_counter()
            key = frozenset([*(e.name for e in added), effect.name])
            try:
                result: FitResult | None = (pool[key][1] if key in pool
                                            else screen_with(added, effect, current.fit))
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
            rmse = held_out(key)
            gain = 1.0 - rmse / current.test_rmse
            change = criterion(key, n_eff) - current_score
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
                f"({-100 * gain:+.1f} %){', screened' if key in screened else ''}"
            )
        # A screened candidate whose held-out RMSE may fall by min_improvement once fitted on
        # every training sample is fitted so before the round decides. The round's n_eff
        # (below) comes from the best-fitting candidate's residual: when some candidate may
        # pass, that one is then a full fit too, for every candidate left screened lies above
        # `target` by more than the tolerance.
        target = (1.0 - settings.min_improvement) * current.test_rmse
        for index, (cand, _) in enumerate(tried):
            if is_screened(tried[index]) and may_fall_to(float(_known(cand.test_rmse)), target):
                settle(tried, index, round_number, n_eff, current_score)
        fitted = [item for item in tried if item[1] is not None]
        # The round's effective sample count: from the best-fitting of the current model and
        # the candidates. The current residual of a model that lacks a strong effect is
        # correlated over whole strokes (n_eff ~ 1), and H then weighs only the parameter
        # count; the candidates are scored again at the better residual's n_eff.
        best_mse = min(fitted, key=lambda item: item[0].test_rmse or math.inf, default=None)
        if best_mse is not None and best_mse[1] is not None:
            wider = effective_samples(best_mse[1].residuals[best_mse[1].test])
            if wider > n_eff:
                n_eff = wider
                current_score = _score(current.fit, n_eff)
                tried = [
                    (replace(cand, score_change=None if result is None
                             else criterion(frozenset([*(e.name for e in added), cand.effect]),
                                            n_eff) - current_score), result)
                    for cand, result in tried
                ]
                fitted = [item for item in tried if item[1] is not None]

        def failure(cand: Candidate) -> str:
            """Why ``cand`` cannot be added (empty: it passes every check of the criterion)."""
            if _known(cand.score_change) >= 0:
                return "does not lower the held-out criterion"
            if _known(cand.improvement) < settings.min_improvement:
                return (
                    f"cuts the held-out RMSE by {cand.improvement:.1%}, less than "
                    f"{settings.min_improvement:.0%}"
                )
            if cand.signature_eta2 < settings.signature_eta2:
                return "the residual shows no structure against its signature"
            return ""

        passing = [item for item in fitted if not failure(item[0])]
        best = min(fitted, key=lambda item: _known(item[0].score_change), default=None)
        chosen = min(passing, key=lambda item: _known(item[0].score_change), default=None)
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
                    frozenset([*(e.name for e in added), cand.effect]) in screened,
                )
            )
        if accepted_name is None:
            # No single addition pays. Two effects whose errors cancel in part can each fail
            # alone and still explain the data together: with structure left and fewer than
            # two effects in the model, every pair is scored.
            if len(added) >= 2 or len(usable) < 2 or not _structure(
                current.analysis, settings, data.time_ordered, data.noise
            ).any:
                break
            revised = revise(round_number, list(added), current, 2)
            key = frozenset(e.name for e in revised)
            if len(revised) <= len(added) or key in visited:
                break
            added[:] = revised
            result = confirmed(key)
            assert result is not None  # revise moves only to sets fitted on every sample
            current = ModelFit(
                tuple(e.name for e in added), result, analyse(result), _score(result, n_eff)
            )
            steps.append(current)
            visited.add(key)
            say(f"round {round_number}: added the pair {' + '.join(current.effects)}")
            continue
        effect = next(e for e in remaining if e.name == accepted_name)
        result = next(r for c, r in tried if c.effect == accepted_name)
        # a candidate that passes was fitted on every training sample (may_fall_to)
        assert result is not None and frozenset(e.name for e in (*added, effect)) not in screened
        added.append(effect)
        say(f"round {round_number}: added {effect.name}")
        revised = revise(round_number, added, current, len(added))
        key = frozenset(e.name for e in revised)
        if revised != added:
            added[:] = revised
            result = confirmed(key)
            assert result is not None  # revise moves only to sets fitted on every sample
        current = ModelFit(
            tuple(e.name for e in added), result, analyse(result), _score(result, n_eff)
        )
        steps.append(current)
        if key in visited:
            break  # the revision went back to a model already accepted: nothing new to try
        visited.add(key)

    structure = _structure(current.analysis, settings, data.time_ordered, data.noise)
    before = steps[0]
    names = tuple(e.name for e in added)
    comparison = _runner_up(current, pool, data, used, settings, screened, confirmed, scale)
    if structure.any:
        verdict = NOT_EXPLAINED
    elif added and comparison is not None and comparison.ambiguous:
        verdict = AMBIGUOUS
    elif added:
        verdict = EXPLAINED
    else:
        verdict = NO_EFFECT
    summary = _summary(base.name, verdict, before, current, names, structure, unit)
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


def _runner_up(
    final: ModelFit,
    pool: Mapping[frozenset[str], tuple[tuple[Effect, ...], FitResult]],
    data: CalibrationData,
    used: np.ndarray,
    settings: LoopSettings,
    screened: Container[frozenset[str]] = frozenset(),
    confirmed: Callable[[frozenset[str]], FitResult | None] | None = None,
    scale: Mapping[frozenset[str], float] | None = None,
) -> Comparison | None:
    """The final model against its runner-up: the best other fitted model with as many effects
    (one effect when the final model has none) in which every effect earns its place (lowers
    ``H`` and cuts the held-out RMSE by ``min_improvement`` against the same model without it,
    where that was fitted; a pair of a real effect and one left at its neutral values is the
    single effect again, not a rival), else the best of them all; both scored at the final
    model's effective held-out sample count (:mod:`hcard.calibration.selection`).

    ``screened``: the pool's models fitted on the screening samples only, which
    ``confirmed(key)`` fits on every training sample (returning None when that fails), their
    held-out RMSE read multiplied by ``scale[key]`` (their start's full over screened). Every
    decision a screened figure could get wrong by :data:`SCREEN_TOLERANCE` is made on full
    fits: whether a rival earns its place, and, when some rival may come within the
    separation thresholds of the final model, which rival is best. When none can (or the
    final model is the base model, whose comparison decides nothing), the comparison is not
    ambiguous whichever rival it is: the runner-up is the rival of lowest ``H`` taking
    screened figures as they are, fitted in full, and fitted again while another screened
    rival looks better than its full fit. It is the runner-up without screening, or a rival
    whose ``H`` lies within the tolerance band (:func:`~hcard.calibration.screening.
    criterion_band`) of it."""
    size = max(len(final.effects), 1)
    own = frozenset(final.effects)
    n_eff = effective_samples(final.fit.residuals[final.fit.test])
    band = criterion_band(n_eff)
    final_score = _score(final.fit, n_eff)

    def score(key: frozenset[str]) -> tuple[float, float, float]:
        """``H`` of the pool's model ``key``, and the bounds within which its full fit's
        lies."""
        factor = (scale or {}).get(key, 1.0) if key in screened else 1.0
        value = _score(pool[key][1], n_eff) + 2.0 * n_eff * math.log(factor)
        spread = band if key in screened else 0.0
        return value, value - spread, value + spread

    def rmse(key: frozenset[str]) -> tuple[float, float]:
        """Bounds of the held-out RMSE of the pool's model ``key`` fitted in full."""
        factor = (scale or {}).get(key, 1.0) if key in screened else 1.0
        value = float(pool[key][1].test_rmse or math.nan) * factor
        spread = SCREEN_TOLERANCE if key in screened else 0.0
        return value * (1.0 - spread), value * (1.0 + spread)

    def settle(keys: Sequence[frozenset[str]]) -> None:
        """Fit the screened ones of ``keys`` on every training sample (failures leave the
        pool)."""
        for key in keys:
            if key in screened and key in pool and confirmed is not None:
                confirmed(key)

    def earns(key: frozenset[str]) -> bool | None:
        """Whether every effect of ``key`` earns its place against the pool's model without
        it; None when a full fit could decide otherwise."""
        _, low, high = score(key)
        fall, rise = rmse(key)
        verdict: bool | None = True
        for name in key:
            smaller = key - {name}
            if smaller not in pool:
                continue
            _, small_low, small_high = score(smaller)
            small_fall, small_rise = rmse(smaller)
            if low >= small_high or not (1.0 - fall / small_rise >= settings.min_improvement):
                return False
            if high >= small_low or not (1.0 - rise / small_fall >= settings.min_improvement):
                verdict = None
        return verdict

    def rivals() -> list[frozenset[str]]:
        return [key for key in pool if len(key) == size and key != own]

    for key in rivals():
        if key in pool and earns(key) is None:
            settle([key, *(key - {name} for name in key)])
    if not rivals():
        return None
    admissible = [key for key in rivals() if earns(key)]
    candidates = admissible or rivals()

    def may_be_close(key: frozenset[str]) -> bool:
        """Whether the full fit of ``key`` may lie within the separation thresholds."""
        return (score(key)[1] - final_score < settings.separation_criterion
                or rmse(key)[0] / final.test_rmse - 1.0 < settings.separation_rmse)

    # When a rival may make the comparison ambiguous, the best rival by full fits: every
    # screened one whose full fit may beat the best is fitted on every training sample. Else
    # the comparison is not ambiguous whichever rival it is: the best taking screened figures
    # as they are, fitted in full, again while another screened one looks better.
    exact = bool(final.effects) and any(may_be_close(key) for key in candidates)
    while True:
        candidates = [key for key in candidates if key in pool]
        if not candidates:
            return None
        best = min(candidates, key=lambda k: score(k)[0])
        doubtful = [key for key in candidates if key in screened and (
            score(key)[1] < score(best)[2] if exact else key == best)]
        if not doubtful or confirmed is None:
            break
        settle(doubtful)
    effects, rival = pool[best]
    observed = data.observed[used]
    return compare(
        final.effects,
        final_score,
        final.test_rmse,
        observed - final.fit.residuals[used],
        tuple(e.name for e in effects),
        _score(rival, n_eff),
        float(rival.test_rmse or math.nan),
        observed - rival.residuals[used],
        {name: values[used] for name, values in data.regressors.items()},
        settings.separation(),
        settings.bins,
        decides=bool(final.effects),
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
    small = structure.describe_small()
    left = (
        f"no structure above the practical threshold is left ({small})" if small
        else "no structure is left"
    )
    if verdict == NO_EFFECT:
        text += f"No effect needed: {model} explains the data; {left}."
    elif verdict == EXPLAINED:
        text += f"{left[0].upper()}{left[1:]} in the residual."
    elif verdict == AMBIGUOUS:
        text += (
            f"{left[0].upper()}{left[1:]} in the residual, but another model fits about as "
            "well."
        )
    else:
        text += f"Structured residual not explained by any known effect: {structure.describe()}."
        if small:
            text += f" Also {small}."
    return text
