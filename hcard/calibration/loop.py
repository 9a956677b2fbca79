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

**Steps.** :func:`calibrate` checks its arguments (:func:`check_arguments`), sorts the library
(:func:`usable_effects`, :func:`claimed_regressors`) and fits every model once through a
:class:`~hcard.calibration.model_pool.ModelPool` (screening included). A round
(:meth:`EffectSearch.run_round`) fits each remaining effect added to the current model
(:meth:`EffectSearch.try_candidates`), fits in full those near the threshold
(:meth:`EffectSearch.settle_near_target`), scores them at the best residual's ``n_eff``
(:meth:`EffectSearch.rescored`), decides (:func:`judge_round`, :func:`criterion_failure`) and lets
the selection undo itself (:meth:`EffectSearch.revise`: :func:`alternative_sets`, a move to a
credited set, :meth:`EffectSearch.prune` with :func:`earns_place`). The end: what structure is left
(:func:`residual_structure`), the runner-up (:func:`runner_up`), :func:`verdict_of` and
:func:`summarise`.

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
(:func:`beyond_foreign_structure`).

**Screening** (:mod:`hcard.calibration.screening`). Candidate models (steps 2 and 4) are first
fitted on one training sample in ``k`` (about ``screen_samples`` of them); one whose screened
figures come within :data:`~hcard.calibration.screening.SCREEN_TOLERANCE` of a threshold of the
criterion, or of a rival it must be ranked against, is fitted again on every training sample,
from the same start, before the loop decides on it. The effects chosen, the verdict and every
accepted model's fit are those the loop reaches without screening (``screen_samples = 0``), and
so is the runner-up whenever it may come within the separation thresholds of the final model;
the figures of candidates far from every decision are the screened fits' (marked in the
candidate table), and among rivals far from the final model the one named runner-up may be
another within the tolerance of the best (:func:`runner_up`).

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
from hcard.calibration.effects import Effect
from hcard.calibration.fit import FitResult
from hcard.calibration.model_pool import (
    EffectSet,
    ModelPool,
    held_out_criterion,
)
from hcard.calibration.noise import NoiseModel, detectable_eta2, time_structure_threshold
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
is judged with the foreign structure taken out (:func:`beyond_foreign_structure`)."""

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


def beyond_foreign_structure(
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


def residual_structure(
    analysis: ResidualReport,
    settings: LoopSettings,
    time_ordered: bool,
    noise: NoiseModel | None = None,
) -> Structure:
    """Where the residual analysed in ``analysis`` is still structured (:class:`Structure`):
    regressors with p < ``alpha`` and ``eta^2 >= min_eta2`` (those below it as ``small``), the
    detectable ``eta^2`` of each regressor's F-test, and structure in time when
    ``time_ordered`` and the lag-1 autocorrelation reaches the threshold set by the sensor
    ``noise`` (:func:`~hcard.calibration.noise.time_structure_threshold`)."""
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


def check_arguments(
    data: CalibrationData, base: Predictor, free: Sequence[str] | None, observation: str
) -> tuple[str, ...]:
    """The base parameters a calibration of ``base`` on ``data`` fits (``free``, default
    :func:`default_free`), once the arguments are checked.

    Raises:
        PredictorError: ``observation`` not one of :data:`OBSERVATIONS`, ``data`` without
            held-out samples, a name in ``free`` that is not a parameter of ``base``, or an
            input of ``base`` without a default that ``data`` do not provide.
    """
    if observation not in OBSERVATIONS:
        raise PredictorError(
            f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}"
        )
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
    return base_free


def usable_effects(
    library: Sequence[Effect], base: Predictor, varying: Container[str]
) -> tuple[list[Effect], dict[str, str]]:
    """The effects of ``library`` the loop can try on ``base``, in library order, and why
    each other one cannot be tried (effect name -> reason): it does not apply to ``base``
    (:meth:`~hcard.calibration.effects.Effect.applies_to`), or none of its signature
    regressors is in ``varying`` (the regressors that vary in the data), so that it cannot be
    identified."""
    skipped: dict[str, str] = {}
    usable: list[Effect] = []
    for effect in library:
        why = effect.applies_to(base)
        if why is None and not any(name in varying for name in effect.signature):
            why = (
                f"its signature ({', '.join(effect.signature)}) does not vary in these data, "
                "so it cannot be identified"
            )
        if why:
            skipped[effect.name] = why
        else:
            usable.append(effect)
    return usable, skipped


def claimed_regressors(base: Predictor, usable: Sequence[Effect]) -> frozenset[str]:
    """What the models can act on: the inputs of ``base`` and every input and signature
    regressor of the ``usable`` effects. Structure against any other regressor (the sliding
    direction, the position, the recording) is *foreign* (:func:`beyond_foreign_structure`)."""
    return frozenset(
        {v.name for v in base.inputs}
        | {name for effect in usable for name in effect.signature}
        | {v.name for effect in usable for v in effect.inputs}
    )


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


def criterion_failure(candidate: Candidate, settings: LoopSettings) -> str:
    """Why a fitted ``candidate`` cannot be added (empty: it passes every check of the
    criterion, module docstring): (a) its ``score_change`` of ``H`` must be negative, (b) its
    ``improvement`` (relative fall of the held-out RMSE) at least ``min_improvement``, (c) its
    ``signature_eta2`` at least ``signature_eta2``; the first check it fails is named."""
    assert candidate.score_change is not None and candidate.improvement is not None
    if candidate.score_change >= 0:
        return "does not lower the held-out criterion"
    if candidate.improvement < settings.min_improvement:
        return (
            f"cuts the held-out RMSE by {candidate.improvement:.1%}, less than "
            f"{settings.min_improvement:.0%}"
        )
    if candidate.signature_eta2 < settings.signature_eta2:
        return "the residual shows no structure against its signature"
    return ""


def judge_round(
    tried: Sequence[tuple[Candidate, bool]], settings: LoopSettings
) -> tuple[str | None, list[Candidate]]:
    """The decision of one round on its candidates ``tried`` (each with whether it was fitted):
    the name of the effect added, the passing candidate (:func:`criterion_failure`) of lowest
    ``score_change``, or None; and every candidate again, in order, marked ``accepted`` or not
    with its ``note`` saying why (a candidate not fitted keeps its own note)."""
    fitted = [cand for cand, ok in tried if ok]
    passing = [cand for cand in fitted if not criterion_failure(cand, settings)]
    best = min(fitted, key=lambda cand: _known(cand.score_change), default=None)
    chosen = min(passing, key=lambda cand: _known(cand.score_change), default=None)
    accepted = chosen.effect if chosen is not None else None
    reason = criterion_failure(best, settings) if best is not None else ""
    rows = []
    for cand, _ok in tried:
        if cand.effect == accepted:
            note = (
                "added: best held-out criterion"
                if best is not None and cand is best
                else "added: best held-out criterion of the candidates that pass every check"
            )
        elif cand.test_rmse is None:
            note = cand.note
        elif accepted is None and best is not None and cand is best:
            note = f"best of the round, not added: {reason}"
        elif criterion_failure(cand, settings):
            note = f"not added: {criterion_failure(cand, settings)}"
        else:
            note = "a better candidate in this round"
        rows.append(replace(cand, accepted=cand.effect == accepted, note=note))
    return accepted, rows


def earns_place(with_it: FitResult, without: FitResult, n_eff: float,
                min_improvement: float) -> str:
    """Why the effect that makes the fit ``without`` into ``with_it`` does not earn its place
    (empty: it does): it must lower ``H`` at ``n_eff`` (:func:`held_out_criterion`) and cut the
    held-out RMSE by ``min_improvement`` (a fraction)."""
    if held_out_criterion(with_it, n_eff) >= held_out_criterion(without, n_eff):
        return "does not lower the held-out criterion"
    gain = 1.0 - float(with_it.test_rmse or math.nan) / float(without.test_rmse or math.nan)
    if not gain >= min_improvement:
        return f"cuts the held-out RMSE by {gain:.1%}, less than {min_improvement:.0%}"
    return ""


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


def verdict_of(structure: Structure, added: Sequence[str], comparison: Comparison | None) -> str:
    """The loop's verdict (module docstring): :data:`NOT_EXPLAINED` while ``structure`` is
    left, else :data:`AMBIGUOUS` when effects were ``added`` and the ``comparison`` with the
    runner-up is ambiguous, :data:`EXPLAINED` when effects were added, :data:`NO_EFFECT`
    when none was."""
    if structure.any:
        return NOT_EXPLAINED
    if added and comparison is not None and comparison.ambiguous:
        return AMBIGUOUS
    return EXPLAINED if added else NO_EFFECT


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
        without it (:func:`beyond_foreign_structure`). A move judged by ``H`` alone may
        otherwise bring in a signature that shows little structure at low power (a load
        index over a few force levels)."""
        without = self.pool.fitted_set([e for e in effects if e is not effect], exact=True)
        if without is None:
            return False
        eta2, foreign = beyond_foreign_structure(
            effect, self.analyse(without), without.residuals[self.analyse.used],
            self.analyse.regressors, self.claimed, self.settings)
        return foreign is None or eta2 >= self.settings.signature_eta2

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
            chosen = self._move(round_number, chosen, scores, own, own_score)
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
    ) -> list[Effect]:
        """The set of ``scores`` of lowest ``H`` below ``own_score`` whose every new effect is
        :meth:`credited` (``chosen`` when there is none)."""
        for key in sorted(scores, key=lambda k: scores[k][2]):
            if key == own or scores[key][2] >= own_score:
                break
            effects = scores[key][0]
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
        """``chosen`` without the effects that do not earn their place (:func:`earns_place`
        at ``n_eff``), taken out one at a time, the one whose removal leaves the lowest ``H``
        first."""
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
        (:func:`beyond_foreign_structure`); a failed fit gives a row without figures."""
        current, pool = self.current, self.pool
        tried: list[tuple[Candidate, FitResult | None]] = []
        for effect in remaining:
            eta2, _ = beyond_foreign_structure(effect, current.analysis,
                                                current.fit.residuals[self.analyse.used],
                                                self.analyse.regressors, self.claimed,
                                                self.settings)
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
            if screened and may_fall_to(float(_known(cand.test_rmse)), target):
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
        (:func:`judge_round`) and revise the set (:meth:`revise`), or, with none passing,
        try the pairs; False when the loop stops."""
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
    for round_number in range(1, settings.max_effects + 1):
        if not search.run_round(round_number):
            break

    current = search.current
    structure = residual_structure(current.analysis, settings, data.time_ordered, data.noise)
    names = tuple(e.name for e in search.added)
    comparison = runner_up(current, pool, data, settings)
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


def summarise(
    model: str,
    verdict: str,
    before: ModelFit,
    after: ModelFit,
    added: tuple[str, ...],
    structure: Structure,
    unit: str,
) -> str:
    """The result in one paragraph: the held-out RMSE ``before`` and ``after`` (in mN for a
    force ``unit`` of N), the effects ``added`` to ``model``, and what the ``verdict`` says is
    left in the residual (``structure``, small structure included)."""
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
