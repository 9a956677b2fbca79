"""The coupled UV + EV model (Eq. 4.1, section 4.3) and the registration of the built-in
predictors through the entry point."""

from __future__ import annotations

import importlib
import inspect
import json
import math
import sys
import warnings

import numpy as np
import pytest

from hcard.physics import Predictor, PredictorError
from hcard.plugins.records import HcardPluginWarning
from hcard.plugins.registry import PluginRegistry, get_registry
from hcard.quantities import EPSILON_0
from hcard_builtins.physics.coupled import Coupled, coupled_class
from hcard_builtins.physics.electrovibration import AirLayer, ChargeLeakage, Kaczmarek
from hcard_builtins.physics.ultrasonic import DimensionlessGroup, SpringSlider

EPS0 = EPSILON_0  # the value the code uses whatever the SciPy (tests/card/test_quantities.py)

# Section 3.6.1 film of the chapter-4 stimulator and the Fig. 2.24 FE group (defaults).
AREA, D_SC, EPS_SC, D_I, EPS_I = 1e-4, 200e-6, 1560.0, 90e-6, 3.35
MU0, NU, PSI_STAR = 0.5, 0.33, 2.38
FN, SPEED, PLATE = 0.5, 0.020, 38_220.0


def kaczmarek_force(v: np.ndarray | float) -> np.ndarray:
    """Eq. 3.12 written out, N."""
    denominator = 2 * (D_SC / EPS_SC + D_I / EPS_I) * (D_SC + D_I)
    return np.asarray(EPS0 * AREA * np.square(v) / denominator)


def dimensionless_mu(w: np.ndarray | float, speed: float = SPEED, f: float = PLATE) -> np.ndarray:
    """Eqs. 2.30 and 2.33 written out."""
    psi = speed / (np.asarray(w) * f * MU0 * (1 + NU))
    return 1 - np.exp(-psi / PSI_STAR)


# ------------------------------------------------------------------------------- Eq. 4.1


def test_forward_is_eq_4_1_with_the_closed_forms():
    model = Coupled()
    amplitude = np.array([0.5e-6, 1e-6, 2e-6, 2e-6])
    voltage = np.array([0.0, 500.0, 1000.0, 2000.0])
    got = model.forward(amplitude=amplitude, voltage=voltage, speed=SPEED, normal_force=FN)
    expected = dimensionless_mu(amplitude) * (FN + kaczmarek_force(voltage)) / FN
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_factors_against_thesis_statements():
    model = Coupled()
    # Section 3.7 (Fig. 3.17): at v_e = 1000 V and ~0.5 N "the increase in the friction ... is
    # in order of 10-20 %" for the parallel-plate Eq. 3.23 finger.
    _, ev = model.factors(amplitude=0.0, voltage=1000.0, speed=SPEED, normal_force=FN)
    assert 1.10 <= float(ev) <= 1.20
    # Eq. 2.33: at Psi = Psi* (2.38, Fig. 2.24) mu' = 1 - 1/e; the amplitude that makes the
    # Eq. 2.30 group equal Psi* at 20 mm/s and 38.22 kHz is worked out here.
    w = SPEED / (2.38 * PLATE * 0.5 * (1 + 0.33))
    uv, _ = model.factors(amplitude=w, voltage=0.0, speed=SPEED, normal_force=FN)
    assert float(uv) == pytest.approx(1 - math.exp(-1), rel=1e-9)
    # Section 4.3: the product of the two (Eq. 4.1), no cross term.
    both = model.forward(amplitude=w, voltage=1000.0, speed=SPEED, normal_force=FN)
    assert float(both) == pytest.approx((1 - math.exp(-1)) * float(ev), rel=1e-12)


def test_factors_split_uv_below_one_and_ev_above_one():
    uv, ev = Coupled().factors(amplitude=1e-6, voltage=1500.0, speed=SPEED, normal_force=FN)
    assert float(uv) == pytest.approx(float(dimensionless_mu(1e-6)), rel=1e-12)
    assert float(ev) == pytest.approx(1 + float(kaczmarek_force(1500.0)) / FN, rel=1e-12)
    assert uv < 1 < ev


def test_defaults_are_the_chapter_4_stimulator():
    model = Coupled()
    inputs = {v.name: v for v in model.inputs}
    assert [v.name for v in model.inputs] == [
        "amplitude", "voltage", "speed", "normal_force", "frequency"
    ]
    assert inputs["frequency"].default == 38_220.0
    assert model["ev_area"] == AREA and model["ev_insulator_thickness"] == D_I
    assert model["uv_psi_star"] == PSI_STAR
    assert model.uv.name == DimensionlessGroup.name and model.ev.name == Kaczmarek.name


def test_without_actuation_the_relative_friction_is_one():
    value = Coupled().forward(amplitude=0.0, voltage=0.0, speed=SPEED, normal_force=FN)
    assert float(value) == 1.0


def test_normal_force_must_be_positive():
    with pytest.raises(PredictorError, match="normal_force"):
        Coupled().forward(amplitude=1e-6, voltage=100.0, normal_force=0.0)


# ---------------------------------------------------------------- section 4.3 behaviour


def _section_4_3_signals(model: Coupled, a: float, opposition: bool):
    """Actuation for UV target 1 - a(1 + cos) and EV target 1 + a(1 +/- cos): each effect
    alone changes F_t by the same +/- 2 a mu0 Fn swing (they are "tuned" as in section 4.3)."""
    t = np.linspace(0.0, 1.0, 2001)
    c = np.cos(2 * np.pi * 5.0 * t)
    x_uv = a * (1 + c)
    x_ev = a * (1 - c) if opposition else a * (1 + c)
    amplitude = model.uv.inverse(1 - x_uv, speed=SPEED, frequency=PLATE, normal_force=FN)
    voltage = model.ev.inverse(x_ev * FN)
    return amplitude, voltage


def _peak_to_peak(values: np.ndarray) -> float:
    return float(np.max(values) - np.min(values))


@pytest.mark.parametrize("a", [0.05, 0.1])
def test_in_phase_the_effects_cancel_and_in_opposition_they_double(a):
    model = Coupled()
    state = {"speed": SPEED, "normal_force": FN, "frequency": PLATE}
    for opposition in (False, True):
        amplitude, voltage = _section_4_3_signals(model, a, opposition)
        uv_alone = model.forward(amplitude=amplitude, voltage=0.0, **state)
        ev_alone = model.forward(amplitude=0.0, voltage=voltage, **state)
        both = model.forward(amplitude=amplitude, voltage=voltage, **state)
        # Each effect alone swings the friction by 2a (tuned to the same +/- change).
        assert _peak_to_peak(uv_alone) == pytest.approx(2 * a, rel=0.01)
        assert _peak_to_peak(ev_alone) == pytest.approx(2 * a, rel=0.01)
        if opposition:
            # (1 - a - a cos)(1 + a - a cos): swing exactly 4a, twice either effect.
            assert _peak_to_peak(both) == pytest.approx(4 * a, rel=0.01)
        else:
            # (1 - x)(1 + x) = 1 - x^2: only a second-order residue (2a)^2 is left ...
            assert _peak_to_peak(both) == pytest.approx((2 * a) ** 2, rel=0.01)
            assert _peak_to_peak(both) < 0.25 * _peak_to_peak(uv_alone)
            # ... and the phase ratio 1 - mu(EV, UV)/mu(0, 0) is 1.5 a^2 (Table 4.1: ~1%).
            assert 1 - float(np.mean(both)) == pytest.approx(1.5 * a**2, rel=0.01)


def test_ev_tuned_to_compensate_gives_constant_friction():
    """Fig. 4.6: a level of EV fully compensates the UV modulation (EV factor 1/(1 - x))."""
    model = Coupled()
    t = np.linspace(0.0, 1.0, 1001)
    x = 0.1 * (1 + np.cos(2 * np.pi * 3.0 * t))
    amplitude = model.uv.inverse(1 - x, speed=SPEED, frequency=PLATE, normal_force=FN)
    voltage = model.ev.inverse((1 / (1 - x) - 1) * FN)
    both = model.forward(amplitude=amplitude, voltage=voltage, speed=SPEED, normal_force=FN)
    assert _peak_to_peak(model.forward(amplitude=amplitude, voltage=0.0)) > 0.19
    np.testing.assert_allclose(both, 1.0, atol=1e-9)


# ------------------------------------------------------------------------------ inverse


def test_inverse_gives_the_amplitude_for_a_total_at_a_voltage():
    model = Coupled()
    target = np.array([0.3, 0.6, 0.9, 1.05])
    amplitude = model.inverse(target, voltage=1000.0, speed=0.05, normal_force=FN)
    back = model.forward(amplitude=amplitude, voltage=1000.0, speed=0.05, normal_force=FN)
    np.testing.assert_allclose(back, target, rtol=1e-9)
    # Closed form: mu' = target / (1 + Fe/Fn), then w from Eq. 2.33.
    mu = target / (1 + float(kaczmarek_force(1000.0)) / FN)
    psi = -PSI_STAR * np.log(1 - mu)
    np.testing.assert_allclose(amplitude, 0.05 / (psi * PLATE * MU0 * (1 + NU)), rtol=1e-9)


def test_inverse_refuses_a_total_that_needs_uv_above_one():
    # 1000 V adds 11.3 % friction: a total of 1.2 would need mu'(w) = 1.08.
    with pytest.raises(PredictorError, match="only lower friction"):
        Coupled().inverse(1.2, voltage=1000.0, normal_force=FN)


# ------------------------------------------------------------------- other sub-models


def test_compose_keeps_sub_model_classes_and_parameters():
    uv = SpringSlider(normal_stiffness=2e6)
    ev = AirLayer(area=50e-6)
    model = Coupled.compose(uv, ev)
    assert type(model) is coupled_class(SpringSlider, AirLayer)
    assert model["uv_normal_stiffness"] == 2e6 and model["ev_area"] == 50e-6
    assert "air_gap" in {v.name for v in model.inputs}
    assert model.inverse_input == "amplitude"  # the spring-slider's numerical inverse
    state = {"speed": SPEED, "normal_force": FN, "frequency": 27_500.0, "air_gap": 0.0}
    expected = uv.forward(amplitude=2e-6, speed=SPEED, normal_force=FN, frequency=27_500.0) * (
        1 + ev.forward(voltage=800.0) / FN
    )
    got = model.forward(amplitude=2e-6, voltage=800.0, **state)
    assert float(got) == pytest.approx(float(expected), rel=1e-12)
    changed = model.with_params(uv_mu0=1.0)
    assert type(changed) is type(model) and changed.uv["mu0"] == 1.0


def test_an_ev_drive_frequency_does_not_collide_with_the_plate_frequency():
    """ChargeLeakage's input ``frequency`` (of the EV drive) becomes ``ev_frequency``."""
    model = Coupled.compose(ev=ChargeLeakage())
    assert [v.name for v in model.inputs] == [
        "amplitude", "voltage", "speed", "normal_force", "frequency", "ev_frequency"
    ]
    got = model.forward(amplitude=1e-6, voltage=1000.0, speed=SPEED, normal_force=FN,
                        frequency=PLATE, ev_frequency=440.0)
    # Eq. 3.22 gain at 440 Hz with tau_d(f) = 7.7 ms (f / 10 Hz)^-0.7 (Figs. 3.13, 3.16).
    omega_tau = 2 * math.pi * 440.0 * 7.7e-3 * 44.0**-0.7
    force = kaczmarek_force(1000.0) * omega_tau**2 / (1 + omega_tau**2)
    assert float(got) == pytest.approx(float(dimensionless_mu(1e-6) * (1 + force / FN)), rel=1e-9)


def test_compose_refuses_settings_it_cannot_keep():
    with pytest.raises(PredictorError, match="beyond its parameters"):
        Coupled.compose(ev=ChargeLeakage(tau_d_curve=[(10.0, 7e-3), (1e3, 3e-4)]))


def test_profile_round_trip_keeps_components_and_values():
    model = Coupled.compose(SpringSlider(mu0=0.8), AirLayer(area=40e-6))
    loaded = Coupled.from_profile(json.loads(json.dumps(model.to_profile())))
    assert type(loaded) is type(model)
    assert loaded.params == model.params
    default = Coupled(uv_psi_star=1.8)
    assert Coupled.from_profile(default.to_profile()).params == default.params


def test_profile_with_unknown_component_is_a_clear_error():
    profile = Coupled().to_profile()
    profile["components"] = {"uv": "no-such-model", "ev": "ev-kaczmarek"}
    with pytest.raises(PredictorError, match=r"components.*no-such-model"):
        Coupled.from_profile(profile, source="dev.json")


def test_components_must_be_a_uv_and_an_ev_model():
    with pytest.raises(PredictorError, match="EV model must map voltage to a force"):
        coupled_class(DimensionlessGroup, SpringSlider)
    with pytest.raises(PredictorError, match="UV model must map amplitude"):
        coupled_class(Kaczmarek, Kaczmarek)


# ------------------------------------------------------------------ registration (item 1)

BUILTIN_MODULES = (
    "hcard_builtins.physics.ultrasonic",
    "hcard_builtins.physics.electrovibration",
    "hcard_builtins.physics.finger",
    "hcard_builtins.physics.coupled",
)


def _public_models(module_name: str) -> set[str]:
    module = importlib.import_module(module_name)
    return {
        obj.name
        for obj in vars(module).values()
        if inspect.isclass(obj) and issubclass(obj, Predictor) and obj.__dict__.get("name")
    }


def test_every_builtin_model_is_registered_through_the_entry_point():
    registry = get_registry(refresh=True)
    predictors = registry.predictors
    expected = set().union(*(_public_models(m) for m in BUILTIN_MODULES))
    assert expected >= {"coupled", "ev-kaczmarek", "ev-charge-leakage", "finger-friction",
                        "spring-slider", "squeeze-film", DimensionlessGroup.name}
    assert expected <= set(predictors)
    for name in expected:
        info = registry.info("predictor", name)
        assert info.entry_point == "builtin-predictors" and info.package == "hcard"
        assert isinstance(info.obj, Predictor) and info.obj.name == name
    assert [b for b in registry.broken if "builtin-predictors" in b.entry_point] == []


def test_a_broken_model_module_is_reported_and_the_others_still_register(monkeypatch):
    monkeypatch.setitem(sys.modules, "hcard_builtins.physics.finger", None)
    registry = PluginRegistry()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        registry.load_entry_points()
        registry.collect()  # hooks are called when their kind is first asked for
    problems = [b.reason for b in registry.broken if b.entry_point == "builtin-predictors"]
    assert len(problems) == 1
    assert "raised ModuleNotFoundError" in problems[0]
    assert "hcard_builtins.physics.finger" in problems[0] and "predictors.py" in problems[0]
    assert any(issubclass(w.category, HcardPluginWarning) for w in caught)
    names = set(registry.predictors)
    assert "finger-friction" not in names
    assert {"coupled", "ev-kaczmarek", DimensionlessGroup.name} <= names


def test_default_instances_evaluate():
    """Every registered default instance can be described and listed (name, unit, bounds)."""
    for name, model in get_registry().predictors.items():
        assert model.name == name and model.description
        for parameter in model.parameters:
            low, high = parameter.bounds
            assert low <= parameter.default <= high and parameter.source
            assert math.isfinite(parameter.default)
