"""The experiment that separates two effects the data could not (spec/calibration.md section 9).

When the loop ends ambiguous between two effects (:mod:`hcard.calibration.selection`), the
recordings held no condition where the two differ beyond what the other parameters absorb: the
air layer (Eq. 3.17) and the flattening pad (Eq. 3.18) both scale the electrostatic force by a
function of the normal force only, and over 0.15-1.5 N one bends to mimic the other. This module
designs the measurement that tells them apart, as T-optimal discrimination does (Atkinson and
Fedorov, Biometrika 62, 1975):

1. the *reference* effect (the one the calibration chose, at its fitted values) and the base
   profile predict the lateral force; the *rival*'s parameters and the base's own parameter of
   that channel (``ev_area``, ``uv_psi_star``) are fitted by least squares so that the rival
   predicts the same over the conditions the recordings already hold (the protocol's, section
   6): what the data cannot separate;
2. over the conditions the device can play (normal force from a light touch of
   :data:`MIN_FORCE_N` to a firm :data:`MAX_FORCE_N`, target levels turned into voltage or
   amplitude by the device profile and clipped at its limits, the protocol's speeds) the
   conditions where the two predictions differ most are added one at a time, the rival refitted
   over the old and the new conditions together each time (the sequential T-optimal
   algorithm); what remains is where the rival cannot follow;
3. the duration: the loop separates two models when the runner-up's held-out criterion ``H``
   is :data:`~hcard.calibration.selection.Separation` ``min_criterion`` higher and its held-out
   RMSE ``min_rmse`` higher (K9-K10). With noise ``sigma`` and a mean squared difference
   ``D^2`` over the held-out samples, the RMSE ratio is ``sqrt(1 + D^2/sigma^2)`` and ``H``
   rises by ``n_eff ln(1 + D^2/sigma^2)``; the test of ``D = 0`` at level ``alpha`` with power
   ``1 - beta`` needs ``n_eff D^2/sigma^2 >= (z_{1-alpha/2} + z_{1-beta})^2``. The shortest
   separating recording meeting all three with the old recordings beside it is found by
   bisection.

Everything is in SI units; the card and track are written with :mod:`hcard.calibration.plan`'s
lane and session builders.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hcard.calibration.plan import (
    EV_SQUARE,
    EV_STAIRCASE,
    FORCES_N,
    PLAIN,
    PROTOCOL_TAXTEL_MM,
    SPEEDS_MM_S,
    STROKE_X_MM,
    UV_STAIRCASE,
    UV_STEPS,
    Plan,
    PlanError,
    lane_card,
    lift_after,
    session_track,
)
from hcard.physics import Predictor
from hcard.physics.effects import SEPARATOR, Effect, augment
from hcard.physics.profile import DeviceProfile, channels_of
from hcard.physics.profile_effects import channel_of

MIN_FORCE_N = 0.1
"""Lightest normal force of a separating session, N: a light touch (the thesis's EV
measurements start at about 0.1 N), and well clear of a recording's contact threshold (5
standard deviations of the lifted normal-force noise, about 0.04 N on the reference device).
Measured on the reference device: with sessions at 0.05 N the calibration of all recordings
together left a held-out RMSE of 11.6 mN against 7.9 mN of noise (about a fifth of those samples
fall below the threshold and read as lifts, whose sensor zero, K4, then carries friction); with
0.1 N, 7.9 mN."""
MAX_FORCE_N = 3.0
"""Firmest normal force of a separating session, N: twice the protocol's firmest, where the
finger pad is pressed flat (Fig. 1.7) and an air layer is pressed out (Eq. 3.17)."""
FORCE_GRID_POINTS = 25
"""Candidate normal forces, spaced geometrically over [MIN_FORCE_N, MAX_FORCE_N]."""
LEVELS = {
    "ev": (1.1, 1.3, 1.6, 2.0, 3.0, 4.0),
    "uv": (0.9, 0.7, 0.5, 0.3, 0.15, 0.05),
}
"""Candidate target levels per channel (relative friction); the device's profile turns each into
a voltage or amplitude at the session's force, clipped at its limits (4.0 asks for the full
2 kV even at 0.05 N on the coupled stimulator)."""
PLAYABLE_INPUTS = frozenset({"normal_force", "speed", "voltage", "amplitude", "frequency",
                             "reaction_force"})
"""Inputs an effect may take for the design to apply: what a session of strokes sets (an effect
of time, strokes or history needs a design over time, which this one is not)."""

ALPHA = 0.01
"""Significance level of the separating test (K9's F-tests use 0.01)."""
POWER = 0.8
"""Power of the separating test."""
SAFETY = 1.5
"""The default duration is the shortest that separates, times this (the noise and the fitted
values are estimates)."""
MIN_DURATION_S = 10.0
"""Shortest separating recording proposed, s."""
MAX_DURATION_S = 600.0
"""Longest separating recording searched for, s (a sim:// or served play's limit is longer)."""
DEFAULT_NOISE_N = 0.008
"""Lateral-force noise assumed without a previous report, N (the reference coupled device's
sensor noise measured over its lifts, about 7.9 mN)."""
DEFAULT_RATE_HZ = 1000.0
"""Recording rate assumed without a previous report, Hz (the reference device's report rate)."""
DEFAULT_HELD_OUT = 0.25
"""Share of samples held out (K2's default)."""
DEFAULT_PROTOCOL_S = 60.0
"""Length of the recordings already made, assumed without a previous report, s (the default
protocol)."""
LEVEL_SHARE = 0.5
"""Share of a separating lane at the designed level: it alternates with plain patches, which
carry the finger's own friction at the same force and speed (K15)."""


class SeparationError(PlanError):
    """A separating experiment that cannot be designed (the message says why)."""


@dataclass(frozen=True)
class Noise:
    """What a previous calibration measured about its recordings (or the stated defaults).

    Attributes:
        sigma_n: lateral-force noise, N.
        lag1: lag-1 autocorrelation of the residual.
        rate_hz: samples per second.
        held_out: share of samples held out.
        recorded_s: seconds of recording already made (their conditions are the protocol's).
        source: where the figures come from.
        observed_n2: the mean squared difference of the two models' held-out errors the
            previous calibration measured, ``RMSE_rival^2 - RMSE_reference^2``, N^2 (None: not
            measured); it stands for the model's figure over the recordings already made.
    """

    sigma_n: float = DEFAULT_NOISE_N
    lag1: float = 0.0
    rate_hz: float = DEFAULT_RATE_HZ
    held_out: float = DEFAULT_HELD_OUT
    recorded_s: float = DEFAULT_PROTOCOL_S
    source: str = "defaults (no previous report)"
    observed_n2: float | None = None

    @property
    def n_eff_per_sample(self) -> float:
        """Effective share of a sample (K9): ``(1 - rho)/(1 + rho)``, at most 1."""
        rho = min(max(self.lag1, 0.0), 0.99)
        return (1.0 - rho) / (1.0 + rho)


@dataclass(frozen=True)
class Conditions:
    """Conditions of a set of samples, one per entry, with the weight (seconds) of each.

    Attributes:
        normal_force: N.
        speed: m/s.
        level: target relative friction played.
        voltage: peak voltage envelope the device's profile sets for it, V.
        amplitude: peak-to-peak plate amplitude it sets, m.
        weight: seconds of recording at the condition.
    """

    normal_force: np.ndarray
    speed: np.ndarray
    level: np.ndarray
    voltage: np.ndarray
    amplitude: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return int(self.normal_force.size)

    def inputs(self) -> dict[str, np.ndarray]:
        """The model inputs (the finger in steady sliding)."""
        return {"normal_force": self.normal_force, "speed": self.speed,
                "voltage": self.voltage, "amplitude": self.amplitude}

    def take(self, index: np.ndarray | Sequence[int], weight: np.ndarray | None = None
             ) -> Conditions:
        """The entries ``index`` (with new weights)."""
        i = np.asarray(index, dtype=np.int64)
        return Conditions(self.normal_force[i], self.speed[i], self.level[i], self.voltage[i],
                          self.amplitude[i], self.weight[i] if weight is None else weight)

    @staticmethod
    def join(*parts: Conditions) -> Conditions:
        return Conditions(*(np.concatenate([getattr(p, name) for p in parts]) for name in (
            "normal_force", "speed", "level", "voltage", "amplitude", "weight")))


def conditions(profile: DeviceProfile, channel: str, forces: Sequence[float] | np.ndarray,
               levels: Sequence[float], speeds_mm_s: Sequence[float]) -> Conditions:
    """Every (force, level, speed) with the actuation the device's own profile renders it by
    (the inverse of its channel at that force and speed, clipped at its limits), weight 1."""
    f, lv, s = (a.ravel() for a in np.meshgrid(np.asarray(forces, dtype=np.float64),
                                              np.asarray(levels, dtype=np.float64),
                                              np.asarray(speeds_mm_s, dtype=np.float64) / 1e3,
                                              indexing="ij"))
    limits = profile.rendering_limits()
    voltage = np.zeros_like(f)
    amplitude = np.zeros_like(f)
    if channel == "ev":
        voltage = np.minimum(profile.voltage_for(np.maximum(lv - 1.0, 0.0) * f, f),
                             limits.max_voltage)
    elif channel == "uv":
        amplitude = np.minimum(profile.amplitude_for(np.clip(lv, 1e-3, 1.0), s, f),
                               limits.max_amplitude)
    return Conditions(f, s, lv, voltage, amplitude, np.ones_like(f))


def protocol_conditions(profile: DeviceProfile, channel: str) -> Conditions:
    """The conditions the protocol already holds on ``channel`` (section 6): its forces, the
    levels of its lanes on that channel (plain patches included), its speeds."""
    if channel == "ev":
        levels = sorted({*EV_STAIRCASE, *EV_SQUARE})
    elif channel == "uv":
        levels = sorted({*UV_STAIRCASE, *UV_STEPS})
    else:
        levels = [PLAIN]
    return conditions(profile, channel if channel != "finger" else "ev", FORCES_N, levels,
                      SPEEDS_MM_S)


# -- the two models ------------------------------------------------------------------------
@dataclass(frozen=True)
class Pair:
    """The two effects and the models that carry them.

    Attributes:
        reference: the effect whose prediction stands (fixed at ``reference_values``).
        rival: the effect fitted to mimic it.
        channel: the channel both act on.
        profile: the base profile (without either effect).
        finger: the bare finger's friction model (the lateral force is its friction times the
            relative friction, K15).
        reference_values: the reference effect's parameters.
        free_base: base parameters fitted with the rival's.
    """

    reference: Effect
    rival: Effect
    channel: str
    profile: DeviceProfile
    finger: Predictor
    reference_values: Mapping[str, float]
    free_base: tuple[str, ...]

    def model(self, effect: Effect, values: Mapping[str, float]) -> Predictor:
        """The lateral-force model of the base with ``effect`` at ``values`` (base parameters
        among them by their own names)."""
        from hcard.calibration.device_model import profile_model

        base = profile_model(self.profile, envelope=True, finger=self.finger)
        model = augment(base, [effect])
        return model.with_params(**{
            (name if name in base.params else f"{effect.name}{SEPARATOR}{name}"): value
            for name, value in values.items()})

    def reference_model(self) -> Predictor:
        return self.model(self.reference, self.reference_values)


def check_pair(a: Effect, b: Effect, profile: DeviceProfile) -> str:
    """The channel both effects act on.

    Raises:
        SeparationError: the same effect twice; effects on different channels; an effect that
            takes an input a session of strokes does not set (time, strokes, pressure); a
            profile that does not render the channel.
    """
    if a.name == b.name:
        raise SeparationError(f"--separate {a.name},{b.name}: one effect twice; name two "
                              "different effects")
    channels = {a.name: channel_of(a), b.name: channel_of(b)}
    if channels[a.name] != channels[b.name]:
        raise SeparationError(
            f"{a.name} acts on the {channels[a.name]} channel and {b.name} on the "
            f"{channels[b.name]} channel: effects on different channels are told apart by "
            "playing one channel at a time (the protocol's bipolar lane), not by this design")
    for effect in (a, b):
        other = sorted({v.name for v in effect.inputs} - PLAYABLE_INPUTS)
        if other:
            raise SeparationError(
                f"{effect.name} depends on {', '.join(other)}, which a session of strokes does "
                "not set: this design chooses forces, levels and speeds, not a history in time")
    channel = channels[a.name]
    uv, ev = channels_of(profile.predictor)
    if (channel == "ev" and ev is None) or (channel == "uv" and uv is None):
        raise SeparationError(f"{a.name} and {b.name} act on the {channel.upper()} channel, "
                              f"which profile {profile.name!r} does not render")
    return channel


FINGER_FREE = ("finger.load_index",)
"""Finger parameters fitted with the rival: a base bends its load index to a missing effect of
the normal force (section 3 of the spec), so the rival may too."""


def _free_base(profile: DeviceProfile, channel: str, finger: Predictor) -> tuple[str, ...]:
    calibrated = tuple(profile.predictor.calibrated)
    prefixed = tuple(n for n in calibrated if n.startswith(f"{channel}_"))
    own = prefixed if prefixed else (calibrated if channel != "finger" else ())
    bent = tuple(n for n in FINGER_FREE if n.removeprefix("finger.") in finger.params)
    return own + bent


def make_pair(reference: Effect, rival: Effect, profile: DeviceProfile, finger: Predictor,
              reference_values: Mapping[str, float] | None = None) -> Pair:
    """The pair on ``profile`` with the other effects it carries kept and these two removed;
    ``reference_values``: the reference effect's (default: its defaults)."""
    channel = check_pair(reference, rival, profile)
    bare = profile.replace(effects=tuple(f for f in profile.effects
                                         if f.name not in (reference.name, rival.name)))
    values = {p.name: p.default for p in reference.parameters}
    values.update(reference_values or {})
    return Pair(reference, rival, channel, bare, finger, values,
                _free_base(bare, channel, finger))


# -- fitting the rival to mimic the reference ---------------------------------------------
@dataclass(frozen=True)
class Mimic:
    """The rival fitted to the reference's prediction over some conditions.

    Attributes:
        values: the rival's parameters and the free base parameters.
        difference: reference minus rival, N, over the conditions fitted on.
    """

    values: dict[str, float]
    difference: np.ndarray


def _rival_parameters(pair: Pair) -> list[tuple[str, float, tuple[float, float], list[float]]]:
    """(name, scale, bounds, starts) of the fitted parameters: the rival's own (from its
    default and its neutral value) and the free base ones (from their profile values)."""
    out = []
    for p in pair.rival.parameters:
        low, high = p.bounds
        starts = [p.default]
        neutral = pair.rival.neutral.get(p.name)
        if neutral is not None and neutral != p.default:
            starts.append(0.5 * (p.default + neutral) if neutral != low else p.default / 4)
        out.append((p.name, abs(p.default) or (high - low) or 1.0, (low, high), starts))
    base = pair.model(pair.rival, {})
    for name in pair.free_base:
        value = base[name]
        bounds = next(p.bounds for p in base.parameters if p.name == name)
        out.append((name, abs(value) or 1.0, bounds, [value]))
    return out


def fit_rival(pair: Pair, where: Conditions, start: Mapping[str, float] | None = None) -> Mimic:
    """The rival's parameters (and the free base ones) minimising the weighted squared
    difference from the reference's prediction over ``where`` (bounded least squares, from
    each start and ``start``; the best kept)."""
    from scipy.optimize import least_squares

    inputs = where.inputs()
    target = pair.reference_model().forward(**inputs)
    root = np.sqrt(where.weight / where.weight.sum())
    spec = _rival_parameters(pair)
    names = [name for name, _, _, _ in spec]
    scale = np.array([s for _, s, _, _ in spec])
    low = np.array([b[0] for _, _, b, _ in spec]) / scale
    high = np.array([b[1] for _, _, b, _ in spec]) / scale

    def residual(x: np.ndarray) -> np.ndarray:
        model = pair.model(pair.rival, dict(zip(names, x * scale, strict=True)))
        return root * (model.forward(**inputs) - target)

    starts = [np.array([s[0] for _, _, _, s in spec])]
    for k, (_, _, _, options) in enumerate(spec):
        for option in options[1:]:
            x = starts[0].copy()
            x[k] = option
            starts.append(x)
    if start:
        starts.append(np.array([start.get(n, starts[0][k]) for k, n in enumerate(names)]))
    best: tuple[float, np.ndarray] | None = None
    for x0 in starts:
        x0 = np.clip(x0 / scale, low, high)
        fitted = least_squares(residual, x0, bounds=(low, high), x_scale="jac")
        if best is None or fitted.cost < best[0]:
            best = (float(fitted.cost), fitted.x)
    assert best is not None
    values = dict(zip(names, (best[1] * scale).tolist(), strict=True))
    model = pair.model(pair.rival, values)
    return Mimic(values, target - model.forward(**inputs))


# -- the design -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Design:
    """A separating experiment.

    Attributes:
        pair: the two effects.
        chosen: the conditions chosen, with the seconds of recording at each (at the level;
            the lane alternates it with plain patches).
        duration_s: length of the separating recording (strokes and rests), s.
        shortest_s: the shortest that separates, s (nan: none up to MAX_DURATION_S).
        noise: the noise and sample figures used.
        rival_on_protocol: the rival fitted to the reference over the protocol's conditions.
        rival_on_both: the rival fitted over the protocol's and the chosen conditions.
        protocol_rms_n: RMS difference of the two over the protocol's conditions, N (the
            rival fitted there).
        chosen_rms_n: RMS difference over the chosen conditions, N (the rival fitted there too).
        chosen_difference_n: difference at each chosen condition, N (rival fitted to both).
        expected: the expected margins of the calibration on all recordings together.
    """

    pair: Pair
    chosen: Conditions
    duration_s: float
    shortest_s: float
    noise: Noise
    rival_on_protocol: Mimic
    rival_on_both: Mimic
    protocol_rms_n: float
    chosen_rms_n: float
    chosen_difference_n: np.ndarray
    expected: dict[str, float] = field(default_factory=dict)

    def describe(self) -> list[str]:
        """The design in a few lines: the conditions chosen and why, the expected separation."""
        pair = self.pair
        lines = [
            f"separating {pair.reference.name} (reference, {_values_text(pair.reference_values)})"
            f" from {pair.rival.name} (fitted to mimic it: "
            f"{_values_text(self.rival_on_protocol.values)}): over the protocol's conditions "
            f"they differ by {1e3 * self.protocol_rms_n:.2f} mN RMS, below the "
            f"{1e3 * self.noise.sigma_n:.1f} mN noise",
        ]
        for k in range(len(self.chosen)):
            lines.append(
                f"  {self.chosen.normal_force[k]:.3g} N at level {self.chosen.level[k]:g} "
                f"({_actuation_text(self.chosen, k)}): {self.chosen.weight[k]:.1f} s, "
                f"difference {1e3 * self.chosen_difference_n[k]:+.2f} mN")
        e = self.expected
        lines.append(
            f"expected on all recordings together: held-out criterion +{e['criterion_margin']:.1f}"
            f" (needs {e['criterion_needed']:.1f}), held-out RMSE +{100 * e['rmse_margin']:.2f} %"
            f" (needs {100 * e['rmse_needed']:.1f} %), with {self.duration_s:.0f} s of separating "
            f"recording (shortest that separates: {_seconds_text(self.shortest_s)})")
        return lines

    def to_dict(self) -> dict[str, Any]:
        """design.json's content."""
        pair = self.pair
        c = self.chosen
        return {
            "format": "hcard-separation-design/1",
            "reference": {"effect": pair.reference.name, "values": dict(pair.reference_values)},
            "rival": {"effect": pair.rival.name,
                      "fitted_on_protocol": self.rival_on_protocol.values,
                      "fitted_on_protocol_and_design": self.rival_on_both.values},
            "channel": pair.channel,
            "profile": pair.profile.name,
            "method": ("T-optimal discrimination (Atkinson & Fedorov 1975): the rival fitted by "
                       "least squares to the reference over the protocol's conditions, then the "
                       "conditions of largest difference added one at a time with the rival "
                       "refitted over old and new together"),
            "candidates": {"normal_force_n": [MIN_FORCE_N, MAX_FORCE_N],
                           "levels": list(LEVELS.get(pair.channel, (PLAIN,))),
                           "speeds_mm_s": list(SPEEDS_MM_S)},
            "protocol_rms_difference_n": self.protocol_rms_n,
            "chosen_rms_difference_n": self.chosen_rms_n,
            "conditions": [
                {"normal_force_n": float(c.normal_force[k]), "level": float(c.level[k]),
                 "voltage_v": float(c.voltage[k]), "amplitude_m": float(c.amplitude[k]),
                 "seconds_at_level": float(c.weight[k]),
                 "difference_n": float(self.chosen_difference_n[k])}
                for k in range(len(c))],
            "noise": {"sigma_n": self.noise.sigma_n, "lag1": self.noise.lag1,
                      "rate_hz": self.noise.rate_hz, "held_out": self.noise.held_out,
                      "recorded_s": self.noise.recorded_s, "source": self.noise.source},
            "test": {"alpha": ALPHA, "power": POWER, "noncentrality_needed": _needed_lambda()},
            "duration_s": self.duration_s,
            "shortest_s": None if not math.isfinite(self.shortest_s) else self.shortest_s,
            "expected": dict(self.expected),
            "spec": "spec/calibration.md section 9",
        }


def _values_text(values: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in values.items())


def _actuation_text(c: Conditions, k: int) -> str:
    if c.voltage[k] > 0:
        return f"{c.voltage[k]:.0f} V"
    if c.amplitude[k] > 0:
        return f"{1e6 * c.amplitude[k]:.2f} um"
    return "plain"


def _seconds_text(seconds: float) -> str:
    return f"{seconds:.0f} s" if math.isfinite(seconds) else f"none up to {MAX_DURATION_S:g} s"


def _needed_lambda() -> float:
    from scipy.stats import norm

    return float((norm.ppf(1 - ALPHA / 2) + norm.ppf(POWER)) ** 2)


def _support(pair: Pair, protocol: Conditions, candidates: Conditions, share: float,
             steps: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Sequential T-optimal design (Atkinson and Fedorov): candidate indices and weights (sum
    1) of the new conditions, the new ones holding ``share`` of all samples."""
    counts: dict[int, float] = {}
    start: dict[str, float] | None = None
    for step in range(steps):
        if counts:
            index = np.array(sorted(counts))
            weights = np.array([counts[i] for i in index])
            new = candidates.take(index, share * weights / weights.sum())
            both = Conditions.join(protocol.take(np.arange(len(protocol)),
                                                 (1 - share) * protocol.weight
                                                 / protocol.weight.sum()), new)
        else:
            both = protocol
        mimic = fit_rival(pair, both, start)
        start = mimic.values
        reference = pair.reference_model().forward(**candidates.inputs())
        rival = pair.model(pair.rival, mimic.values).forward(**candidates.inputs())
        best = int(np.argmax((reference - rival) ** 2))
        counts[best] = counts.get(best, 0.0) + 1.0 / (step + 1)
    index = np.array(sorted(counts))
    weights = np.array([counts[i] for i in index])
    keep = weights >= 0.1 * weights.sum()
    return index[keep], weights[keep] / weights[keep].sum()


def _contact_share() -> float:
    """Share of a session's time in contact (strokes there and back at the protocol's mean
    speed pair, then the mean lift: a short one and a rest every pair)."""
    length = (STROKE_X_MM[1] - STROKE_X_MM[0]) / 1e3
    mean = float(np.mean([length / (s / 1e3) for s in SPEEDS_MM_S])) * 2
    lift = (lift_after(0) + lift_after(1)) / 2.0
    return mean / (mean + lift)


def _expected(pair: Pair, protocol: Conditions, chosen: Conditions, noise: Noise,
              duration_s: float, alone: Mimic) -> tuple[dict[str, float], Mimic]:
    """The margins a calibration on the old recordings plus ``duration_s`` s of the design
    would find (the rival refitted over both)."""
    at_level = duration_s * _contact_share() * LEVEL_SHARE
    old = noise.recorded_s * _contact_share()
    new = chosen.take(np.arange(len(chosen)), at_level * chosen.weight / chosen.weight.sum())
    both = Conditions.join(protocol.take(np.arange(len(protocol)),
                                         old * protocol.weight / protocol.weight.sum()), new)
    mimic = fit_rival(pair, both, alone.values)
    total = old + duration_s * _contact_share()  # plain patches: no difference
    squares = both.weight * mimic.difference**2
    old_part = float(np.sum(squares[:len(protocol)]))
    if noise.observed_n2 is not None:
        # what was measured on the old recordings, plus what refitting over both adds there
        before = float(np.sum(both.weight[:len(protocol)] * alone.difference**2))
        old_part = old * max(noise.observed_n2, 0.0) + max(old_part - before, 0.0)
    mean_square = (old_part + float(np.sum(squares[len(protocol):]))) / total
    ratio = mean_square / noise.sigma_n**2
    n_eff = total * noise.rate_hz * noise.held_out * noise.n_eff_per_sample
    return {
        "mean_square_difference_n2": mean_square,
        "criterion_margin": n_eff * math.log1p(ratio),
        "criterion_needed": 0.0,
        "rmse_margin": math.sqrt(1.0 + ratio) - 1.0,
        "rmse_needed": 0.0,
        "noncentrality": n_eff * ratio,
        "held_out_effective_samples": n_eff,
    }, mimic


def design(pair: Pair, noise: Noise, *, duration_s: float | None = None,
           min_criterion: float = 10.0, min_rmse: float = 0.01) -> Design:
    """The separating experiment of ``pair`` (module docstring); ``duration_s`` None: the
    shortest that separates times :data:`SAFETY` (at least :data:`MIN_DURATION_S`)."""
    protocol = protocol_conditions(pair.profile, pair.channel)
    forces = np.geomspace(MIN_FORCE_N, MAX_FORCE_N, FORCE_GRID_POINTS)
    candidates = conditions(pair.profile, pair.channel, forces,
                            LEVELS.get(pair.channel, (PLAIN,)), SPEEDS_MM_S)
    # the design's share of all samples, at about the duration it will have
    guess = duration_s if duration_s is not None else noise.recorded_s / 2
    share = guess * LEVEL_SHARE / (guess + noise.recorded_s)
    index, weights = _support(pair, protocol, candidates, share)
    chosen = candidates.take(index, weights)
    needed = {"criterion_needed": max(min_criterion, _needed_lambda()),
              "rmse_needed": min_rmse}

    on_protocol = fit_rival(pair, protocol)

    def separates(seconds: float) -> tuple[bool, dict[str, float], Mimic]:
        figures, mimic = _expected(pair, protocol, chosen, noise, seconds, on_protocol)
        figures.update(needed)
        ok = (figures["criterion_margin"] >= needed["criterion_needed"]
              and figures["noncentrality"] >= _needed_lambda()
              and figures["rmse_margin"] >= min_rmse)
        return ok, figures, mimic

    low, high = 0.0, MIN_DURATION_S
    while not separates(high)[0] and high < MAX_DURATION_S:
        low, high = high, min(2 * high, MAX_DURATION_S)
    shortest = math.nan
    if separates(high)[0]:
        for _ in range(8):
            middle = 0.5 * (low + high)
            if separates(middle)[0]:
                high = middle
            else:
                low = middle
        shortest = high
    if duration_s is None:
        duration_s = max(MIN_DURATION_S, SAFETY * shortest) if math.isfinite(shortest) \
            else MAX_DURATION_S
    _, expected, both = separates(duration_s)
    seconds = duration_s * _contact_share() * LEVEL_SHARE * chosen.weight / chosen.weight.sum()
    chosen = chosen.take(np.arange(len(chosen)), seconds)
    reference = pair.reference_model().forward(**chosen.inputs())
    difference = reference - pair.model(pair.rival, both.values).forward(**chosen.inputs())
    chosen_rms = float(np.sqrt(np.sum(chosen.weight * difference**2) / chosen.weight.sum()))
    protocol_rms = float(np.sqrt(np.sum(protocol.weight * on_protocol.difference**2)
                                 / protocol.weight.sum()))
    return Design(pair, chosen, float(duration_s), float(shortest), noise, on_protocol, both,
                  protocol_rms, chosen_rms, difference, expected)


# -- the card and track -----------------------------------------------------------------------
def separating_plan(result: Design, *, seed: int = 0, rate_hz: float = 100.0) -> Plan:
    """The card (one lane per chosen level: plain patches between patches of the level) and
    the track (sessions at the chosen forces, as many as their share of the duration, in an
    order drawn from ``seed``) of a design."""
    chosen = result.chosen
    channel = result.pair.channel if result.pair.channel != "finger" else "ev"
    levels = sorted({float(v) for v in chosen.level})
    cols = round(80.0 / PROTOCOL_TAXTEL_MM)
    lanes = [(f"separate-{channel}-{level:g}",
              tuple(PLAIN if k % 2 == 0 else level for k in range(cols)), channel)
             for level in levels]
    card = lane_card(lanes, PROTOCOL_TAXTEL_MM, "hcard separating experiment",
                     f"{result.pair.reference.name} against {result.pair.rival.name} "
                     "(spec/calibration.md section 9).")
    pairs = [(SPEEDS_MM_S[i], SPEEDS_MM_S[(i + 1) % len(SPEEDS_MM_S)])
             for i in range(len(SPEEDS_MM_S))]
    length = STROKE_X_MM[1] - STROKE_X_MM[0]
    rng = np.random.default_rng(seed)
    owed = chosen.weight / chosen.weight.sum() * result.duration_s
    sessions: list[tuple[int, float, tuple[float, float]]] = []
    elapsed, k = 0.0, 0
    while elapsed < result.duration_s:
        pick = int(np.argmax(owed + 1e-9 * rng.random(owed.size)))
        pair = pairs[k % len(pairs)]
        seconds = length / pair[0] + length / pair[1] + lift_after(k)
        owed[pick] -= seconds
        sessions.append((levels.index(float(chosen.level[pick])),
                         float(chosen.normal_force[pick]), pair))
        elapsed += seconds
        k += 1
    from hcard.track import make_track

    t, x, y, fn, contact = session_track(sessions, rate_hz)
    track = make_track(t, x, y, fn, contact, source="separating experiment")
    names = tuple(name for name, _, _ in lanes)
    return Plan(card, track, names,
                tuple((names[row], force, pair) for row, force, pair in sessions))

