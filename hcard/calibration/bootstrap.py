"""Parameter uncertainties from a stroke-block bootstrap.

The fit's own uncertainties, ``sigma^2 (J^T J)^-1`` (:mod:`hcard.calibration.fit`), take every
training sample as an independent draw of white noise. A recording's residual is neither: the
samples of one stroke share its finger state, and a model that misses part of the physics leaves
a residual correlated over whole strokes; the Jacobian interval then shrinks with the sample
rate (a fitted gain of 0.433 +- 0.002 against a truth far outside it).

:func:`stroke_bootstrap` resamples whole training strokes with replacement (each stroke keeps
its samples and their order; a stroke drawn k times weighs k in the sum of squares), refits the
model from its fitted values, and repeats ``samples`` times with a seeded generator. Each
parameter's standard uncertainty is the standard deviation of its refits, and its 95 % interval
the 2.5-97.5 percentiles. Strokes are the blocks because the split holds out whole strokes too
(spec/measurement-format.md section 4); the correlation of the residual from one stroke to the
next is not resampled.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hcard.calibration.blas_threads import on_one_blas_thread
from hcard.calibration.dataset import CalibrationData
from hcard.calibration.fit import FitResult, fit_predictor
from hcard.physics import PredictorError

DEFAULT_SAMPLES = 50
"""Bootstrap refits by default."""
REFIT_EVALUATIONS = 200
"""Most model evaluations of one refit (a Jacobian counts once, as in
:func:`~hcard.calibration.fit.fit_predictor`). A refit starts at the fitted optimum and, with
the parameters the data never move held (:attr:`FitResult.held`), converges in a few tens on
the coupled stimulator's nine-parameter EV model of an 8 s recording (29 of 30 refits; a cap of
40 stopped 7 of them and made the spread of three finger parameters 20-40 % too small). A refit
still crawling here stops; its values still sample the spread, which along that direction is
then a lower bound, and :attr:`BootstrapResult.capped` counts them."""

METHOD = (
    "stroke-block bootstrap: the training strokes resampled with replacement {samples} times "
    "(seed {seed}), the model refitted each time from its fitted values; standard uncertainty "
    "= standard deviation of the refits, 95 % interval = their 2.5-97.5 percentiles"
)
CAPPED = (
    "; {capped} of the refits stopped at {evaluations} model evaluations, along a direction "
    "the data barely constrain (the spread there is a lower bound)"
)


@dataclass(frozen=True)
class BootstrapResult:
    """Uncertainties of a fit's free parameters from refits on resampled strokes.

    Attributes:
        samples: refits that ended with values (of ``requested``; a refit the model cannot
            evaluate is left out).
        requested: refits asked for.
        capped: refits (of ``samples``) that stopped at :data:`REFIT_EVALUATIONS` before
            converging.
        held: the fit's parameters that the data never move (:attr:`FitResult.held`): not
            refitted, uncertainty ``inf``, no interval.
        seed: seed of the stroke draws.
        strokes: training strokes resampled.
        values: refitted parameter name -> its refitted values, shape (samples,) (its unit).
        uncertainties: parameter name -> standard deviation of the refits (parameter unit;
            ``inf`` for a held one).
        intervals: refitted parameter name -> ``(low, high)``, the 2.5 and 97.5 percentiles.
        seconds: wall time, s.
    """

    samples: int
    requested: int
    capped: int
    held: tuple[str, ...]
    seed: int
    strokes: int
    values: dict[str, np.ndarray]
    uncertainties: dict[str, float]
    intervals: dict[str, tuple[float, float]]
    seconds: float

    def method(self) -> str:
        """How the uncertainties were computed, in words."""
        text = METHOD.format(samples=self.samples, seed=self.seed)
        if self.capped:
            text += CAPPED.format(capped=self.capped, evaluations=REFIT_EVALUATIONS)
        return text


@on_one_blas_thread  # the refits' linear algebra is on narrow matrices (fit_predictor)
def stroke_bootstrap(
    fit: FitResult,
    data: CalibrationData,
    *,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> BootstrapResult:
    """Refit ``fit``'s model ``samples`` times on training strokes of ``data`` drawn with
    replacement (module docstring) and return the spread of its free parameters.

    Raises:
        PredictorError: ``samples`` below 2, fewer than 2 training strokes, or every refit
            failing.
    """
    if samples < 2:
        raise PredictorError(f"bootstrap samples must be at least 2, got {samples}")
    started = time.perf_counter()
    labels = data.stroke_labels()
    train_labels = labels[data.train]
    strokes = np.unique(train_labels[train_labels >= 0])
    if strokes.size < 2:
        raise PredictorError(
            f"a stroke bootstrap needs at least 2 training strokes, the data have {strokes.size}"
        )
    refitted = [name for name in fit.free if name not in fit.held]
    if not refitted:
        raise PredictorError("no parameter to bootstrap: the data move none of the fit's free "
                             f"parameters ({', '.join(fit.free)})")
    model = fit.predictor
    inputs = data.inputs_for(model)
    dynamic = "time" in {v.name for v in model.inputs}
    fitted = data.train & (labels >= 0)  # the samples a refit weighs
    index = np.searchsorted(strokes, labels[fitted])  # each one's training stroke
    rng = np.random.default_rng(seed)
    values: dict[str, list[float]] = {name: [] for name in refitted}
    capped = 0
    say = progress or (lambda _text: None)
    report_every = max(1, samples // 10)
    for b in range(samples):
        counts = np.bincount(rng.integers(0, strokes.size, strokes.size), minlength=strokes.size)
        weights = np.zeros(labels.shape[0])
        weights[fitted] = counts[index]
        try:
            refit = fit_predictor(model, inputs, data.observed, free=refitted,
                                  train=data.train, test=data.test, dynamic=dynamic,
                                  weights=weights, max_evaluations=REFIT_EVALUATIONS)
        except PredictorError as exc:
            say(f"bootstrap {b + 1}/{samples}: refit failed ({exc})")
            continue
        capped += not refit.success  # the optimiser stopped at the evaluation cap
        for name in refitted:
            values[name].append(refit.params[name])
        if (b + 1) % report_every == 0 or b + 1 == samples:
            say(f"bootstrap {b + 1}/{samples} ({time.perf_counter() - started:.0f} s)")
    done = len(next(iter(values.values()), []))
    if done == 0:
        raise PredictorError("every bootstrap refit failed")
    arrays = {name: np.asarray(v) for name, v in values.items()}
    return BootstrapResult(
        samples=done,
        requested=samples,
        capped=capped,
        held=tuple(fit.held),
        seed=seed,
        strokes=int(strokes.size),
        values=arrays,
        uncertainties={
            **{name: float(np.std(v, ddof=1)) if v.size > 1 else math.inf
               for name, v in arrays.items()},
            **{name: math.inf for name in fit.held},
        },
        intervals={
            name: (float(np.percentile(v, 2.5)), float(np.percentile(v, 97.5)))
            for name, v in arrays.items()
        },
        seconds=time.perf_counter() - started,
    )
