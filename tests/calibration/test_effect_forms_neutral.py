"""Neutral values are exactly neutral: every built-in effect at its neutral
values gives the base model to 1e-12 relative, on every protocol: constant inputs, a slow square
wave of the voltage (whose DC a 10 s "neutral" leakage used to strip), ramps, and strokes with
lifts. The base is evaluated on its own; nothing here goes through the effect's transform."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from hcard.physics import Predictor
from hcard.physics.effects import augment
from hcard_builtins.effects import BUILTIN_EFFECTS, ChargeLeakage
from hcard_builtins.physics.electrovibration import Kaczmarek
from hcard_builtins.physics.finger import FingerFriction
from hcard_builtins.physics.ultrasonic import DimensionlessGroup, SpringSlider

RATE_HZ = 200.0
N = 4000  # 20 s


def constant() -> dict[str, np.ndarray]:
    return {
        "amplitude": np.full(N, 2e-6), "voltage": np.full(N, 300.0),
        "normal_force": np.full(N, 0.6), "speed": np.full(N, 0.04),
        "pressure": np.full(N, 101_325.0), "stroke": np.zeros(N), "contact": np.ones(N),
    }


def slow_square_wave() -> dict[str, np.ndarray]:
    """The voltage switches polarity every 5 s (0.1 Hz): its envelope is DC for seconds."""
    data = constant()
    data["voltage"] = 400.0 * np.where((np.arange(N) // int(5 * RATE_HZ)) % 2 == 0, 1.0, -1.0)
    return data


def ramps() -> dict[str, np.ndarray]:
    x = np.linspace(0.0, 1.0, N)
    return {
        "amplitude": 4e-6 * x, "voltage": -500.0 + 1000.0 * x, "normal_force": 0.1 + 1.4 * x,
        "speed": 0.005 + 0.1 * x, "pressure": 101_325.0 * (1.0 - 0.6 * x),
        "stroke": np.floor(10 * x), "contact": np.ones(N),
    }


def strokes_with_lifts() -> dict[str, np.ndarray]:
    """Contacts of 1.5 s and lifts of 0.5 s (force 0, stroke -1, contact 0); the drive stays on."""
    rng = np.random.default_rng(2)
    phase = np.arange(N) % int(2 * RATE_HZ)
    on = phase < int(1.5 * RATE_HZ)
    stroke = np.where(on, np.arange(N) // int(2 * RATE_HZ) % 4, -1).astype(float)
    return {
        "amplitude": np.repeat(rng.uniform(0.0, 3e-6, N // 40), 40),
        "voltage": np.repeat(rng.uniform(-600.0, 600.0, N // 40), 40),
        "normal_force": np.where(on, rng.uniform(0.2, 1.5, N), 0.0),
        "speed": np.where(on, rng.uniform(0.01, 0.1, N), 0.0),
        "pressure": np.full(N, 101_325.0),
        "stroke": stroke,
        "contact": on.astype(float),
    }


PROTOCOLS: dict[str, Callable[[], dict[str, np.ndarray]]] = {
    "constant": constant, "slow-square-wave": slow_square_wave, "ramps": ramps,
    "strokes-with-lifts": strokes_with_lifts,
}

BASES: dict[str, Callable[[], Predictor]] = {
    "finger-friction": lambda: FingerFriction(load_index=1.0),
    "dimensionless-group": DimensionlessGroup,
    "spring-slider": SpringSlider,
    "ev-kaczmarek": Kaczmarek,
}


def pairs() -> list[tuple[type, str]]:
    """Every built-in effect on every base among :data:`BASES` it applies to."""
    out = []
    for cls in BUILTIN_EFFECTS:
        for name, make in BASES.items():
            if cls().applies_to(make()) is None:
                out.append((cls, name))
    return out


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
@pytest.mark.parametrize(
    ("effect_cls", "base_name"), pairs(), ids=[f"{c.name}-on-{b}" for c, b in pairs()]
)
def test_neutral_values_give_the_base_exactly(effect_cls: type, base_name: str,
                                              protocol: str) -> None:
    effect = effect_cls()
    base = BASES[base_name]()
    data = PROTOCOLS[protocol]()
    if base_name == "spring-slider":  # 512 phase samples per point: keep it short
        data = {k: v[::20] for k, v in data.items()}
    data["time"] = np.arange(next(iter(data.values())).size) / RATE_HZ
    if base_name == "finger-friction":
        data["normal_force"] = np.maximum(data["normal_force"], 0.0)
    neutral = augment(base, [effect]).with_params(
        **{f"{effect.name}.{k}": v for k, v in effect.neutral.items()}
    )
    inputs = {k: v for k, v in data.items() if k in {var.name for var in neutral.inputs}}
    base_inputs = {k: v for k, v in inputs.items() if k in {var.name for var in base.inputs}}
    expected = base.forward(**base_inputs)
    np.testing.assert_allclose(neutral.forward(**inputs), expected, rtol=1e-12, atol=0)


def test_every_effect_is_checked_on_at_least_one_base() -> None:
    assert {c for c, _ in pairs()} == set(BUILTIN_EFFECTS)


def test_a_slow_leakage_is_not_neutral_on_a_slow_square_wave() -> None:
    """The protocol that exposed the old 10 s "neutral": a leakage of 1 s (inside the bounds,
    not neutral) changes the force of a 0.1 Hz square wave by tens of percent, so the exact
    equality above is a real constraint."""
    data = slow_square_wave()
    data["time"] = np.arange(N) / RATE_HZ
    model = augment(Kaczmarek(), [ChargeLeakage()]).with_params(
        **{"charge-leakage.time_constant": 1.0}
    )
    base = Kaczmarek().forward(voltage=data["voltage"])
    ratio = model.forward(voltage=data["voltage"], time=data["time"]) / base
    assert np.min(ratio) < 0.1  # the force of a held voltage leaks away within seconds
