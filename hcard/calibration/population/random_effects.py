"""The second stage of a two-stage mixed-effects fit: a normal random-effects model of one
parameter over participants (spec/calibration.md K21-K23).

Each participant ``i`` gives an estimate ``y_i`` of its own true value ``theta_i`` with a
standard error ``s_i`` (from its own fit, ``sigma^2 (J^T J)^-1``); the true values are drawn
from the population::

    y_i ~ N(theta_i, s_i^2),    theta_i ~ N(mu, tau^2).

``mu`` (the population mean) and ``tau`` (the population's spread, the between-participant
standard deviation) are in the unit of the parameter.

- :func:`dersimonian_laird`: the moment estimate, closed form (DerSimonian & Laird 1986):
  ``w_i = 1/s_i^2``, ``mu_FE = sum w y / sum w``, ``Q = sum w (y - mu_FE)^2``,
  ``tau^2 = max(0, (Q - (k - 1)) / (sum w - sum w^2 / sum w))``.
- :func:`reml`: the restricted maximum likelihood estimate of ``tau^2``, maximising
  ``-1/2 [sum ln(s_i^2 + tau^2) + ln sum w_i + sum w_i (y_i - mu)^2]`` with
  ``w_i = 1/(s_i^2 + tau^2)`` and ``mu = sum w y / sum w`` (Viechtbauer 2005); what
  :func:`random_effects` reports.
- ``mu``'s 95 % interval: Knapp-Hartung (Hartung-Knapp-Sidik-Jonkman), ``mu +- t_{k-1, 0.975}
  sqrt(q / sum w)`` with ``q = max(1, sum w (y - mu)^2 / (k - 1))`` (the ``max(1, .)`` keeps it
  never narrower than the normal-theory interval, Jackson et al. 2017).
- ``tau``'s 95 % interval: the Q-profile (Viechtbauer 2007): the ``tau^2`` at which the
  generalised ``Q(tau^2) = sum (y - mu(tau^2))^2 / (s^2 + tau^2)`` equals the 97.5 % and 2.5 %
  points of chi^2 with ``k - 1`` degrees of freedom (0 where ``Q(0)`` lies below them).
- The prediction interval of a new participant's value: ``mu +- t_{k-2, 0.975}
  sqrt(tau^2 + se(mu)^2)`` (Higgins, Thompson & Spiegelhalter 2009), for ``k >= 3``.
- Empirical-Bayes shrinkage: ``theta_i = mu + B_i (y_i - mu)``, ``B_i = tau^2/(tau^2 + s_i^2)``,
  with standard error ``sqrt(B_i s_i^2 + (1 - B_i)^2 se(mu)^2)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize_scalar
from scipy.stats import chi2
from scipy.stats import t as student_t

from hcard.errors import InputError

LEVEL = 0.95
"""Coverage of every interval reported."""


class RandomEffectsError(InputError, ValueError):
    """Estimates that a random-effects model cannot pool (fewer than two, a non-positive or
    non-finite standard error): a study that cannot give a population, as bad input does."""


@dataclass(frozen=True)
class RandomEffects:
    """One parameter's population over ``k`` participants (the parameter's unit throughout).

    Attributes:
        mu: population mean (REML).
        mu_se: its Knapp-Hartung standard error.
        mu_interval: 95 % Knapp-Hartung interval of ``mu``.
        tau: population standard deviation (REML), ``sqrt(tau^2)``.
        tau_interval: 95 % Q-profile interval of ``tau``.
        prediction_interval: 95 % interval of a new participant's true value, or None for
            ``k < 3``.
        k: number of participants pooled.
        q: Cochran's ``Q`` at ``tau^2 = 0`` (dimensionless).
        i2: share of the estimates' spread due to the population, ``max(0, (Q-(k-1))/Q)``.
        tau_dl: the DerSimonian-Laird ``tau``, for comparison.
        shrunken: empirical-Bayes estimate of each participant's value, in input order.
        shrunken_se: its standard error.
        weights: ``1/(s_i^2 + tau^2)`` of each participant (1/unit^2).
    """

    mu: float
    mu_se: float
    mu_interval: tuple[float, float]
    tau: float
    tau_interval: tuple[float, float]
    prediction_interval: tuple[float, float] | None
    k: int
    q: float
    i2: float
    tau_dl: float
    shrunken: tuple[float, ...]
    shrunken_se: tuple[float, ...]
    weights: tuple[float, ...]


def _checked(estimates: Sequence[float], errors: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """``estimates`` and the variances ``errors^2`` as arrays, checked."""
    y = np.asarray(estimates, dtype=np.float64)
    s = np.asarray(errors, dtype=np.float64)
    if y.shape != s.shape or y.ndim != 1:
        raise RandomEffectsError(f"{y.size} estimates but {s.size} standard errors")
    if y.size < 2:
        raise RandomEffectsError(f"a population needs at least 2 participants, got {y.size}")
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(s)) and np.all(s > 0)):
        raise RandomEffectsError("every estimate must be finite and every standard error "
                                 "finite and positive")
    return y, s**2


def cochran_q(y: np.ndarray, v: np.ndarray, tau2: float = 0.0) -> float:
    """The generalised ``Q(tau^2) = sum (y - mu)^2 / (v + tau^2)``, ``mu`` the weighted mean
    with those weights (dimensionless)."""
    w = 1.0 / (v + tau2)
    mu = float(np.sum(w * y) / np.sum(w))
    return float(np.sum(w * (y - mu) ** 2))


def dersimonian_laird(estimates: Sequence[float], errors: Sequence[float]) -> tuple[float, float]:
    """The DerSimonian-Laird ``(mu, tau^2)`` (module docstring), in the parameter's unit and
    its square."""
    y, v = _checked(estimates, errors)
    w = 1.0 / v
    q = cochran_q(y, v)
    c = float(np.sum(w) - np.sum(w**2) / np.sum(w))
    tau2 = max(0.0, (q - (y.size - 1)) / c)
    ws = 1.0 / (v + tau2)
    return float(np.sum(ws * y) / np.sum(ws)), tau2


def _restricted_loglik(tau2: float, y: np.ndarray, v: np.ndarray) -> float:
    """The restricted log-likelihood of ``tau^2`` (module docstring), constants dropped."""
    w = 1.0 / (v + tau2)
    mu = np.sum(w * y) / np.sum(w)
    return float(-0.5 * (np.sum(np.log(v + tau2)) + math.log(np.sum(w))
                         + np.sum(w * (y - mu) ** 2)))


def reml(estimates: Sequence[float], errors: Sequence[float]) -> float:
    """The REML ``tau^2`` (unit squared): the restricted log-likelihood's maximum over
    ``tau^2 >= 0``, searched (bounded Brent) up to ten times the larger of the estimates'
    variance and the DerSimonian-Laird value."""
    y, v = _checked(estimates, errors)
    _, start = dersimonian_laird(estimates, errors)
    upper = 10.0 * max(float(np.var(y, ddof=1)), start, float(np.max(v)))
    found = minimize_scalar(lambda t2: -_restricted_loglik(t2, y, v), bounds=(0.0, upper),
                            method="bounded", options={"xatol": 1e-12 * upper + 1e-300})
    best = float(found.x)
    if _restricted_loglik(0.0, y, v) >= _restricted_loglik(best, y, v):
        return 0.0
    return best


def _q_profile(y: np.ndarray, v: np.ndarray, level: float) -> tuple[float, float]:
    """The Q-profile interval of ``tau^2`` (module docstring)."""
    k = y.size
    alpha = 1.0 - level
    targets = (chi2.ppf(1.0 - alpha / 2, k - 1), chi2.ppf(alpha / 2, k - 1))
    ends = []
    for target in targets:
        if cochran_q(y, v, 0.0) <= target:
            ends.append(0.0)
            continue
        high = max(float(np.var(y)), float(np.max(v)), 1e-300)
        while cochran_q(y, v, high) > target:
            high *= 4.0
        ends.append(float(brentq(lambda t2, goal=target: cochran_q(y, v, t2) - goal, 0.0, high,
                                 xtol=1e-14 * high)))
    return ends[0], ends[1]


def random_effects(estimates: Sequence[float], errors: Sequence[float],
                   level: float = LEVEL) -> RandomEffects:
    """Pool per-participant ``estimates`` with standard ``errors`` (same unit) under a normal
    population: REML ``mu``, ``tau``, their intervals and the shrunken estimates (module
    docstring).

    Raises:
        RandomEffectsError: fewer than 2 estimates, a non-finite value, or a standard error
            that is not positive.
    """
    y, v = _checked(estimates, errors)
    k = y.size
    tau2 = reml(estimates, errors)
    w = 1.0 / (v + tau2)
    mu = float(np.sum(w * y) / np.sum(w))
    q_scale = max(1.0, float(np.sum(w * (y - mu) ** 2)) / (k - 1))
    mu_se = math.sqrt(q_scale / float(np.sum(w)))
    half = float(student_t.ppf(0.5 + level / 2, k - 1)) * mu_se
    low2, high2 = _q_profile(y, v, level)
    prediction = None
    if k >= 3:
        spread = float(student_t.ppf(0.5 + level / 2, k - 2)) * math.sqrt(tau2 + mu_se**2)
        prediction = (mu - spread, mu + spread)
    q = cochran_q(y, v)
    shrink = tau2 / (tau2 + v)
    shrunken = mu + shrink * (y - mu)
    shrunken_se = np.sqrt(shrink * v + (1.0 - shrink) ** 2 * mu_se**2)
    return RandomEffects(
        mu=mu, mu_se=mu_se, mu_interval=(mu - half, mu + half),
        tau=math.sqrt(tau2), tau_interval=(math.sqrt(low2), math.sqrt(high2)),
        prediction_interval=prediction, k=k, q=q,
        i2=max(0.0, (q - (k - 1)) / q) if q > 0 else 0.0,
        tau_dl=math.sqrt(dersimonian_laird(estimates, errors)[1]),
        shrunken=tuple(float(x) for x in shrunken),
        shrunken_se=tuple(float(x) for x in shrunken_se),
        weights=tuple(float(x) for x in w),
    )
