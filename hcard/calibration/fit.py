"""Bounded nonlinear least-squares fit of any predictor's parameters (spec/calibration.md).

:func:`fit_predictor` fits the free parameters of a :class:`~hcard.physics.Predictor` to observed
outputs with :func:`scipy.optimize.least_squares`, inside the parameters' bounds, on a training
split, and reports the error on a held-out split. Inputs are plain arrays in SI units (the units of
the predictor's input variables); the observed output is in the unit of the predictor's output.
Split by stroke or by time block, never by random sample, so that correlated samples do not leak
from the training split into the held-out one: the split masks are the caller's choice.

A fit runs on one BLAS thread (:mod:`hcard.calibration.blas_threads`): its linear algebra is on
a Jacobian a dozen columns wide, where OpenBLAS's threads only compete with the model
evaluations for the cores.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from hcard.calibration.blas_threads import on_one_blas_thread
from hcard.calibration.forward_cache import caching_forwards
from hcard.physics import Predictor, PredictorError

UNIDENTIFIABLE = 1e-8
"""Relative singular value of the scaled Jacobian below which a direction is not identifiable."""
COST_TOLERANCE = 1e-8
"""A fit stops when an iteration lowers the training cost by less than this fraction of it."""
PROBE_STEP = 1e-3
"""Relative step (of the parameter's scale) with which :func:`fit_predictor` probes whether a
free parameter moves any training residual before it fits."""


@dataclass(frozen=True)
class FitResult:
    """The outcome of :func:`fit_predictor`.

    Attributes:
        predictor: the predictor with the fitted parameters.
        params: all parameter values after the fit (unit of each parameter).
        free: names of the fitted parameters, in fit order.
        uncertainties: standard uncertainty of each free parameter (its unit), from
            ``sigma^2 (J^T J)^-1`` with ``sigma^2 = RSS / (n_train - n_free)``; ``inf`` for a
            parameter the data do not identify (see :attr:`identifiable`).
        covariance: covariance matrix of the free parameters, in ``free`` order.
        residuals: ``observed - predicted`` for every sample (output unit), training and
            held-out alike, in the order given.
        train: boolean mask of the training samples.
        test: boolean mask of the held-out samples (all False without a held-out split).
        train_rmse: root-mean-square residual on the training split (output unit).
        test_rmse: root-mean-square residual on the held-out split (output unit), or None.
        at_bounds: free parameters that ended on (within 1e-9 relative of) a bound; their
            uncertainties are not meaningful.
        condition_number: condition number of the scaled Jacobian; above
            ``1 / UNIDENTIFIABLE`` some free parameters are not separately identifiable.
        success: whether the optimiser reported convergence.
        message: the optimiser's message.
        held: free parameters that move no training residual at all (a UV parameter on a
            recording without plate vibration, say): held at their start values, not counted
            as fitted, uncertainty ``inf``.
    """

    predictor: Predictor
    params: dict[str, float]
    free: tuple[str, ...]
    uncertainties: dict[str, float]
    covariance: np.ndarray
    residuals: np.ndarray
    train: np.ndarray
    test: np.ndarray
    train_rmse: float
    test_rmse: float | None
    at_bounds: tuple[str, ...]
    condition_number: float
    success: bool
    message: str
    held: tuple[str, ...] = ()

    @property
    def n_free(self) -> int:
        """Number of fitted parameters (the free ones less those :attr:`held`)."""
        return len(self.free) - len(self.held)

    @property
    def identifiable(self) -> bool:
        """Whether every free parameter is determined by the data (all uncertainties finite)."""
        return all(math.isfinite(u) for u in self.uncertainties.values())

    @property
    def n_train(self) -> int:
        """Number of training samples."""
        return int(np.count_nonzero(self.train))

    @property
    def n_test(self) -> int:
        """Number of held-out samples."""
        return int(np.count_nonzero(self.test))

    @property
    def train_rss(self) -> float:
        """Residual sum of squares on the training split (output unit squared)."""
        return float(np.sum(self.residuals[self.train] ** 2))

    def aic(self) -> float:
        """Akaike information criterion of the training fit, Gaussian errors.

        ``n ln(RSS/n) + 2k`` with ``n`` training samples and ``k`` free parameters (constant
        terms dropped, so only differences between fits on the same data mean anything).
        """
        n = self.n_train
        return n * math.log(max(self.train_rss, np.finfo(float).tiny) / n) + 2 * self.n_free

    def bic(self) -> float:
        """Bayesian information criterion of the training fit: ``n ln(RSS/n) + k ln n``."""
        n = self.n_train
        return (
            n * math.log(max(self.train_rss, np.finfo(float).tiny) / n)
            + self.n_free * math.log(n)
        )


def _mask(name: str, split: np.ndarray, n: int) -> np.ndarray:
    """A boolean mask of length ``n`` from a boolean mask or an array of indices."""
    split = np.asarray(split)
    if split.dtype == bool:
        if split.shape != (n,):
            raise PredictorError(f"{name} mask has shape {split.shape}, expected ({n},)")
        return split.copy()
    if split.size and not np.issubdtype(split.dtype, np.integer):
        raise PredictorError(f"{name} must be a boolean mask or integer indices")
    mask = np.zeros(n, dtype=bool)
    index = split.astype(np.intp).ravel()
    if index.size and (index.min() < -n or index.max() >= n):
        raise PredictorError(f"{name} indices out of range for {n} samples")
    mask[index] = True
    return mask


def _splits(
    train: np.ndarray | None, test: np.ndarray | None, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Training and held-out masks; a missing one is the complement of the other."""
    if train is None:
        if test is None:
            return np.ones(n, dtype=bool), np.zeros(n, dtype=bool)
        test_mask = _mask("test", test, n)
        return ~test_mask, test_mask
    train_mask = _mask("train", train, n)
    test_mask = ~train_mask if test is None else _mask("test", test, n)
    overlap = int(np.count_nonzero(train_mask & test_mask))
    if overlap:
        raise PredictorError(
            f"train and test splits share {overlap} sample(s); a held-out split must be disjoint"
        )
    return train_mask, test_mask


def _scale(value: float, bounds: tuple[float, float]) -> float:
    """A positive scale for a parameter: its start value, else the larger finite bound, else 1."""
    if value != 0 and math.isfinite(value):
        return abs(value)
    finite = [abs(b) for b in bounds if math.isfinite(b) and b != 0]
    return max(finite) if finite else 1.0


def _covariance(jac_scaled: np.ndarray, scales: np.ndarray) -> tuple[np.ndarray, float]:
    """``(J^T J)^-1`` in physical units (before the ``sigma^2`` factor) and the condition number.

    ``jac_scaled`` is the Jacobian in the optimiser's scaled coordinates. Directions whose
    singular value is below :data:`UNIDENTIFIABLE` times the largest are not determined by the
    data: the parameters with a weight in them get an infinite variance (and NaN covariances)
    instead of the deceptively small value a pseudo-inverse would give.
    """
    _, singular, vt = np.linalg.svd(jac_scaled, full_matrices=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else math.inf
    keep = singular > UNIDENTIFIABLE * singular[0]
    inverse = (vt[keep].T / singular[keep] ** 2) @ vt[keep]
    covariance = inverse * np.outer(scales, scales)  # J_physical = J_scaled / scale
    loose = np.any(np.abs(vt[~keep]) > 1e-6, axis=0)
    covariance[loose, :] = np.nan
    covariance[:, loose] = np.nan
    covariance[loose, loose] = math.inf
    return covariance, condition


@on_one_blas_thread  # its linear algebra is on narrow matrices, and threads only compete
def fit_predictor(
    predictor: Predictor,
    inputs: Mapping[str, np.ndarray],
    observed: np.ndarray,
    *,
    free: Sequence[str] | None = None,
    train: np.ndarray | None = None,
    test: np.ndarray | None = None,
    dynamic: bool = False,
    max_evaluations: int | None = None,
    weights: np.ndarray | None = None,
) -> FitResult:
    """Fit ``predictor``'s free parameters to ``observed`` by bounded least squares.

    Args:
        predictor: the model; its current parameter values are the starting point and the
            fixed values of the parameters not in ``free``.
        inputs: input name -> array in the input's SI unit, each broadcastable to the shape
            of ``observed`` (a scalar is a constant input). Inputs not given take the
            predictor's defaults.
        observed: 1-D array of measured outputs, in the unit of the predictor's output.
        free: the parameters to fit (default: all of them).
        train: boolean mask or indices of the training samples (default: every sample not in
            ``test``).
        test: boolean mask or indices of the held-out samples (default: every sample not in
            ``train``; none when neither is given).
        dynamic: evaluate the model on every sample, in the order given, and compare it with
            the training samples only. Needed for a model with memory (a filter over time),
            whose state at a training sample depends on the inputs of the samples between
            (held-out strokes, rests); those samples' inputs are used, never their observed
            outputs. Default: evaluate on the training samples alone (faster).
        max_evaluations: most evaluations of the model (each Jacobian counts once); the fit
            ends there, converged or not (default: scipy's, 100 per free parameter).
        weights: non-negative weight of each sample in the training sum of squares, shape
            ``(n,)`` (default: 1 each); samples of weight 0 leave the training split. A
            stroke-block bootstrap (:mod:`hcard.calibration.bootstrap`) passes how many times
            each stroke was drawn. ``train_rmse`` and the uncertainties are then of the
            weighted sum.

    Returns:
        A :class:`FitResult`.

    Raises:
        PredictorError: unknown free parameter or input, empty or non-finite data, mismatched
            lengths, overlapping splits, fewer training samples than free parameters, or a
            model that fails to evaluate during the fit.
    """
    known = {p.name: p for p in predictor.parameters}
    names = tuple(known) if free is None else tuple(free)
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise PredictorError(
            f"{predictor.name}: unknown free parameter(s) {', '.join(unknown)}; "
            f"parameters: {', '.join(known) or 'none'}"
        )
    if len(set(names)) != len(names):
        raise PredictorError(f"{predictor.name}: free parameters repeat: {', '.join(names)}")
    if not names:
        raise PredictorError(f"{predictor.name}: no free parameters to fit")

    y = np.asarray(observed, dtype=np.float64)
    if y.ndim != 1:
        raise PredictorError(f"observed must be a 1-D array, got shape {y.shape}")
    n = y.size
    if n == 0:
        raise PredictorError("no data: observed is empty")
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        raise PredictorError(
            f"observed has {bad.size} non-finite value(s) (NaN or inf), first at sample {bad[0]}"
        )
    arrays: dict[str, np.ndarray] = {}
    for key, value in inputs.items():
        array = np.asarray(value, dtype=np.float64)
        try:
            array = np.broadcast_to(array, (n,))
        except ValueError:
            raise PredictorError(
                f"input {key} has shape {array.shape}, not broadcastable to {n} samples"
            ) from None
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            raise PredictorError(
                f"input {key} has {bad.size} non-finite value(s) (NaN or inf), "
                f"first at sample {bad[0]}"
            )
        arrays[key] = array
    predictor._inputs(arrays)  # unknown or missing input names fail here, before fitting

    train_mask, test_mask = _splits(train, test, n)
    root_weight = np.ones(n)
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise PredictorError(f"weights has shape {w.shape}, expected ({n},)")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise PredictorError("weights must be finite and non-negative")
        train_mask &= w > 0
        root_weight = np.sqrt(w)
    n_train = int(np.count_nonzero(train_mask))
    if n_train <= len(names):
        raise PredictorError(
            f"{n_train} training sample(s) for {len(names)} free parameter(s): "
            "need more samples than parameters"
        )
    train_inputs = {key: value[train_mask] for key, value in arrays.items()}
    y_train = y[train_mask]
    w_train = root_weight[train_mask]

    start = predictor.params
    scales = np.array([_scale(start[name], known[name].bounds) for name in names])
    low = np.array([known[name].bounds[0] for name in names]) / scales
    high = np.array([known[name].bounds[1] for name in names]) / scales
    x0 = np.clip(np.array([start[name] for name in names]) / scales, low, high)

    def physical(x: np.ndarray) -> dict[str, float]:
        """Scaled optimiser coordinates -> parameter values in their units."""
        values = np.clip(x, low, high) * scales
        return {name: float(values[i]) for i, name in enumerate(names)}

    def model(x: np.ndarray, given: Mapping[str, np.ndarray], size: int) -> np.ndarray:
        values = physical(x)
        try:
            out = predictor.with_params(**values).forward(**given)
        except PredictorError as exc:
            shown = ", ".join(f"{k}={v:.6g}" for k, v in values.items())
            raise PredictorError(f"fit failed: model does not evaluate at {shown}: {exc}") from None
        return np.broadcast_to(np.asarray(out, dtype=np.float64), (size,))

    def residual(x: np.ndarray) -> np.ndarray:
        if dynamic:
            r = model(x, arrays, n)[train_mask] - y_train
        else:
            r = model(x, train_inputs, n_train) - y_train
        if not np.all(np.isfinite(r)):
            shown = ", ".join(f"{k}={v:.6g}" for k, v in physical(x).items())
            raise PredictorError(f"fit failed: model gives non-finite output at {shown}")
        return r * w_train

    with caching_forwards():  # a Jacobian's steps re-evaluate only the parts they move
        active = ~_held_parameters(residual, x0, low, high)
        held = tuple(name for name, on in zip(names, active, strict=True) if not on)

        def active_residual(xa: np.ndarray) -> np.ndarray:
            x = x0.copy()
            x[active] = xa
            return residual(x)

        if active.any():
            solution = least_squares(active_residual, x0[active],
                                     bounds=(low[active], high[active]), method="trf",
                                     x_scale=1.0, ftol=COST_TOLERANCE, max_nfev=max_evaluations)
            x = x0.copy()
            x[active] = np.clip(solution.x, low[active], high[active])
            success, message = bool(solution.success), str(solution.message)
            jac = np.asarray(solution.jac, dtype=np.float64)
        else:
            x, success, message = x0.copy(), True, "no free parameter moves the training residual"
            jac = np.zeros((n_train, 0))
        fitted = predictor.with_params(**physical(x))

        residuals = y - model(x, arrays, n)
    rss = float(np.sum((residuals[train_mask] * w_train) ** 2))
    dof = n_train - int(np.count_nonzero(active))
    covariance = np.full((len(names), len(names)), np.nan)
    np.fill_diagonal(covariance, math.inf)
    condition = math.inf
    if active.any():
        inner, condition = _covariance(jac, scales[active])
        covariance[np.ix_(active, active)] = inner * (rss / dof)
        if held:
            condition = math.inf
    uncertainties = {
        name: float(math.sqrt(covariance[i, i])) if np.isfinite(covariance[i, i]) else math.inf
        for i, name in enumerate(names)
    }
    at_bounds = tuple(
        name
        for i, name in enumerate(names)
        if min(abs(x[i] - low[i]), abs(x[i] - high[i])) <= 1e-9 * max(1.0, abs(x[i]))
    )
    test_rmse = (
        float(math.sqrt(np.mean(residuals[test_mask] ** 2))) if test_mask.any() else None
    )
    return FitResult(
        predictor=fitted,
        params=fitted.params,
        free=names,
        uncertainties=uncertainties,
        covariance=covariance,
        residuals=residuals,
        train=train_mask,
        test=test_mask,
        train_rmse=float(math.sqrt(rss / n_train)),
        test_rmse=test_rmse,
        at_bounds=at_bounds,
        condition_number=condition,
        success=success,
        message=message,
        held=held,
    )


def _held_parameters(residual: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
                     low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Which parameters (scaled optimiser coordinates ``x0`` inside ``[low, high]``) move no
    training residual at all: a step of :data:`PROBE_STEP` changes no residual, both at ``x0``
    and at a second point with every other parameter stepped too. The second point keeps free
    a parameter that only matters once another moves (a time constant behind a gain that starts
    at 0); a parameter of a physics the data never exercise (a UV parameter on a recording
    without plate vibration) moves nothing at either, and a least-squares fit that keeps it
    free crawls along its flat direction for hundreds of iterations without converging.
    """
    step = np.where(x0 + PROBE_STEP <= high, PROBE_STEP, -PROBE_STEP)
    step = np.where((x0 + step >= low) & (x0 + step <= high), step, 0.0)
    moved = np.clip(x0 + step, low, high)

    def inert_at(base: np.ndarray) -> np.ndarray:
        """Parameters whose step changes no residual at ``base`` (none if it fails there)."""
        out = np.zeros(x0.size, dtype=bool)
        try:
            reference = residual(base)
            for i in np.flatnonzero(step != 0.0):
                probe = base.copy()
                probe[i] = moved[i] if base[i] == x0[i] else x0[i]
                out[i] = bool(np.array_equal(residual(probe), reference))
        except PredictorError:  # a probe the model cannot evaluate: keep everything free
            out[:] = False
        return out

    inert = inert_at(x0)
    if inert.any():
        inert &= inert_at(moved)
    return inert
