"""Effects on the base model's parameters per sample: occlusion raises the dry
friction coefficient mu0 inside the ultrasonic group Psi = U / (w f mu0 (1 + nu)) (Eq. 2.30).

The recordings here are written from the thesis formulas in this file (Eqs. 2.30, 2.33 and the
first-order occlusion rise of Fig. 1.11), not by the effect's own transform.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.constants

from hcard.calibration.dataset import accumulated_contact_time
from hcard.calibration.fit import fit_predictor
from hcard.calibration.observation import lateral_force_model
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import augment
from hcard.physics.per_sample import SAMPLEWISE_PARAMETERS, forward_per_sample
from hcard.plugins.registry import get_registry
from hcard_builtins.effects import LoadIndex, OcclusionDrift
from hcard_builtins.physics.coupled import Coupled
from hcard_builtins.physics.electrovibration import Kaczmarek
from hcard_builtins.physics.ultrasonic import DimensionlessGroup

PLATE_HZ = 27_500.0
POISSON = 0.33


def _inputs_for(model: Predictor, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Plausible inputs (SI) for the built-in predictors' input names."""
    pool = {
        "amplitude": rng.uniform(0.5e-6, 4e-6, n),
        "frequency": np.full(n, PLATE_HZ),
        "speed": rng.uniform(0.01, 0.1, n),
        "normal_force": rng.uniform(0.2, 1.5, n),
        "contact_time": rng.uniform(0.0, 60.0, n),
        "voltage": rng.uniform(-200.0, 200.0, n),
        "air_gap": rng.uniform(0.0, 20e-6, n),
    }
    return {v.name: pool[v.name] for v in model.inputs if v.name in pool}


@pytest.mark.parametrize("name", sorted(SAMPLEWISE_PARAMETERS))
def test_registered_predictors_broadcast_parameters_per_sample(name: str) -> None:
    """Every parameter declared per-sample gives, sample by sample, the output of the model
    built with that sample's value (one scalar evaluation per sample, the reference)."""
    base = get_registry().get("predictor", name)
    rng = np.random.default_rng(4)
    n = 7
    inputs = _inputs_for(base, n, rng)
    values = {}
    for p in base.parameters:
        if p.name not in SAMPLEWISE_PARAMETERS[name]:
            continue
        low, high = p.bounds
        centre = base[p.name]
        spread = rng.uniform(-0.2, 0.2, n) * (abs(centre) if centre else 0.01 * (high - low))
        values[p.name] = np.clip(centre + spread, low, high)
    assert set(values) == SAMPLEWISE_PARAMETERS[name]
    got = forward_per_sample(base, values, inputs)
    expected = [
        float(
            base.with_params(**{k: float(v[i]) for k, v in values.items()}).forward(
                **{k: v[i] for k, v in inputs.items()}
            )
        )
        for i in range(n)
    ]
    assert np.allclose(got, expected, rtol=1e-12, atol=0)
    # the values vary the output: the check above can fail
    assert np.ptp(np.asarray(expected) / base.forward(**inputs)) > 1e-3


def test_a_base_that_does_not_broadcast_is_evaluated_per_distinct_value() -> None:
    """The coupled model builds its sub-models at construction (scalar parameters), so a
    per-sample ``uv_mu0`` goes through one evaluation per distinct value; compared with the
    product of Eq. 4.1 written out here."""
    base = Coupled()
    rng = np.random.default_rng(8)
    n = 9
    inputs = _inputs_for(base, n, rng)
    inputs["frequency"] = np.full(n, 38_220.0)
    mu0 = np.repeat([0.4, 0.55, 0.7], 3)
    got = forward_per_sample(base, {"uv_mu0": mu0}, inputs)
    psi = inputs["speed"] / (inputs["amplitude"] * 38_220.0 * mu0 * (1 + base["uv_poisson_ratio"]))
    uv = 1.0 - np.exp(-psi / base["uv_psi_star"])
    eps0 = scipy.constants.epsilon_0
    electrical = (
        base["ev_sc_thickness"] / base["ev_sc_permittivity"]
        + base["ev_insulator_thickness"] / base["ev_insulator_permittivity"]
    )
    mechanical = base["ev_sc_thickness"] + base["ev_insulator_thickness"]
    fe = eps0 * base["ev_area"] * inputs["voltage"] ** 2 / (2 * electrical * mechanical)
    assert np.allclose(got, uv * (1 + fe / inputs["normal_force"]), rtol=1e-12, atol=0)


def test_unchanged_parameters_give_the_base_forward_map_exactly() -> None:
    base = DimensionlessGroup()
    inputs = {"amplitude": np.array([1e-6, 2e-6]), "speed": np.array([0.02, 0.05])}
    assert np.array_equal(forward_per_sample(base, base.params, inputs), base.forward(**inputs))


# -- occlusion on mu0, data from the thesis formulas ------------------------------------------
TRUTH = {"mu0": 0.45, "psi_star": 2.38, "gain": 0.6, "time_constant": 15.0}
RATE_HZ = 50.0
N = 3000  # 60 s


def thesis_recording(seed: int, noise_n: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Lateral force (N) of a finger whose dry friction rises by occlusion, written from the
    thesis: ``mu0(t) = mu0 (1 + g (1 - exp(-t / tau)))`` (Fig. 1.11), ``Psi = U / (w f mu0(t)
    (1 + nu))`` (Eq. 2.30), ``mu' = 1 - exp(-Psi / Psi*)`` (Eq. 2.33), ``F = mu0(t) Fn mu'``
    (Eq. 4.1 without EV), plus white noise ``noise_n``."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / RATE_HZ
    level = np.repeat(rng.uniform(1e-6, 4e-6, N // 25), 25)  # m, held for 0.5 s
    amplitude = np.where(np.repeat(rng.random(N // 25) < 0.2, 25), 0.0, level)
    speed = np.repeat(rng.uniform(0.01, 0.1, N // 25), 25)
    force = rng.uniform(0.3, 1.2, N)
    mu0_t = TRUTH["mu0"] * (1.0 + TRUTH["gain"] * (1.0 - np.exp(-t / TRUTH["time_constant"])))
    reduction = np.ones(N)
    vibrating = amplitude > 0
    psi = speed[vibrating] / (amplitude[vibrating] * PLATE_HZ * mu0_t[vibrating] * (1 + POISSON))
    reduction[vibrating] = 1.0 - np.exp(-psi / TRUTH["psi_star"])
    lateral = mu0_t * force * reduction + rng.normal(0.0, noise_n, N)
    # the finger never lifts: its occlusion time is the recording time
    inputs = {"occlusion_time": t, "amplitude": amplitude, "speed": speed, "normal_force": force}
    return inputs, lateral


def held_out_blocks(n: int) -> np.ndarray:
    """Every fifth block of 100 samples (2 s): time blocks, never random samples."""
    return (np.arange(n) // 100) % 5 == 2


def fit_occlusion(inputs, observed, share: float | None):
    """Fit the lateral-force model of the dimensionless group with occlusion; ``share``: the
    ``psi_share`` held fixed (0: the output-only form), or None to fit it."""
    model = lateral_force_model(augment(DimensionlessGroup(), [OcclusionDrift()]))
    start = {"mu0": 0.5, "psi_star": 2.0, "occlusion-drift.gain": 1.0,
             "occlusion-drift.time_constant": 20.0}
    free = ["mu0", "psi_star", "occlusion-drift.gain", "occlusion-drift.time_constant"]
    if share is None:
        start["occlusion-drift.psi_share"] = 0.5
        free.append("occlusion-drift.psi_share")
    else:
        start["occlusion-drift.psi_share"] = share
    return fit_predictor(
        model.with_params(**start), inputs, observed, free=free, test=held_out_blocks(N),
        dynamic=True,
    )


@pytest.mark.parametrize("noise_n", [2e-3, 6e-3])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_occlusion_on_mu0_reaches_the_noise_floor_where_the_output_form_does_not(
    seed: int, noise_n: float
) -> None:
    inputs, observed = thesis_recording(seed, noise_n)
    right = fit_occlusion(inputs, observed, share=1.0)
    output_only = fit_occlusion(inputs, observed, share=0.0)
    assert right.test_rmse is not None and output_only.test_rmse is not None
    # the form where the physics acts reaches the noise floor ...
    assert right.test_rmse == pytest.approx(noise_n, rel=0.10)
    # ... and recovers the truth (stated tolerances: 2 % on mu0 and Psi*, 5 % on the gain,
    # 15 % on the occlusion time constant, and within 4 standard uncertainties)
    tolerance = {"mu0": 0.02, "psi_star": 0.02, "gain": 0.05, "time_constant": 0.15}
    for name, rel in tolerance.items():
        key = name if name in ("mu0", "psi_star") else f"occlusion-drift.{name}"
        value, sigma = right.params[key], right.uncertainties[key]
        assert value == pytest.approx(TRUTH[name], rel=rel), key
        assert abs(value - TRUTH[name]) < 4 * sigma + 1e-3 * TRUTH[name], key
    # the output-only form is left well above the noise
    assert output_only.test_rmse > 1.3 * noise_n
    excess_right = right.test_rmse**2 - noise_n**2
    excess_output = output_only.test_rmse**2 - noise_n**2
    assert excess_output > 5 * max(excess_right, 0.05 * noise_n**2)


def test_the_fitted_share_says_mu0_enters_psi() -> None:
    """With the share free, thesis-form data give ``psi_share`` near 1."""
    inputs, observed = thesis_recording(5, 2e-3)
    fitted = fit_occlusion(inputs, observed, share=None)
    assert fitted.params["occlusion-drift.psi_share"] == pytest.approx(1.0, abs=0.08)
    assert fitted.test_rmse == pytest.approx(2e-3, rel=0.10)
    assert math.isfinite(fitted.uncertainties["occlusion-drift.gain"])


def test_bad_per_sample_values_are_refused_naming_the_parameter() -> None:
    base = DimensionlessGroup()
    inputs = {"amplitude": np.array([1e-6, 2e-6]), "speed": np.array([0.02, 0.05])}
    with pytest.raises(PredictorError, match="mu0 per sample must be finite"):
        forward_per_sample(base, {"mu0": np.array([0.5, np.nan])}, inputs)
    with pytest.raises(PredictorError, match="unknown parameter"):
        forward_per_sample(base, {"friction": 0.5}, inputs)
    with pytest.raises(PredictorError, match=r"mu0 per sample must be >= 0\.01, got -0\.1"):
        forward_per_sample(base, {"mu0": np.array([0.5, -0.1])}, inputs)
    # above the upper bound (a fit's search range) a drifting value is allowed
    high = forward_per_sample(base, {"mu0": np.array([6.0, 6.0])}, inputs)
    psi = inputs["speed"] / (inputs["amplitude"] * PLATE_HZ * 6.0 * (1 + POISSON))
    assert np.allclose(high, 1.0 - np.exp(-psi / base["psi_star"]), rtol=1e-12, atol=0)


def test_occlusion_keeps_the_output_form_on_a_base_that_holds_mu0_as_one_number() -> None:
    """The coupled model's sub-models hold ``uv_mu0`` as one number: occlusion scales its
    output (Eq. 4.1 times the occlusion factor) instead of crawling one evaluation per
    sample."""
    base = Coupled()
    model = augment(base, [OcclusionDrift()]).with_params(
        **{"occlusion-drift.gain": 0.5, "occlusion-drift.time_constant": 10.0}
    )
    t = np.array([0.0, 5.0, 30.0])
    inputs = {"amplitude": np.full(3, 2e-6), "speed": np.full(3, 0.05),
              "normal_force": np.full(3, 0.5), "voltage": np.full(3, 200.0)}
    factor = 1.0 + 0.5 * (1.0 - np.exp(-t / 10.0))
    assert np.allclose(model.forward(occlusion_time=t, **inputs), base.forward(**inputs) * factor,
                       rtol=1e-12, atol=0)


@pytest.mark.parametrize("index", [0.67, 0.85, 1.2])
def test_the_load_index_on_an_electrostatic_base_is_a_power_of_the_whole_reaction(index):
    """Eq. 2.35 on R = Fn + F_e (Eq. 3.1): the lateral force of an EV model with a load index
    is k R^n; the output-only form mu (Fn + F_e Fn^(n-1)) is off by several per cent here."""
    base = Kaczmarek()
    model = lateral_force_model(augment(base, [LoadIndex()])).with_params(
        **{"load-index.load_index": index, "friction_coefficient": 0.6})
    voltage = np.array([0.0, 200.0, 500.0, 1000.0, 1500.0])
    fn = np.array([0.05, 0.1, 0.08, 0.15, 0.3])  # N, light touches
    attraction = base.forward(voltage=voltage)
    assert np.max(attraction / fn) > 0.2  # the attraction is a large share of the reaction
    expected = 0.6 * np.power(fn + attraction, index)  # k R^n, with 1 N as the force unit
    got = model.forward(voltage=voltage, normal_force=fn)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    output_only = 0.6 * (fn + attraction * np.power(fn, index - 1.0))
    assert np.max(np.abs(output_only / expected - 1.0)) > 0.02


def test_the_occlusion_clock_stops_while_the_finger_is_lifted():
    """Accumulated contact time (Fig. 1.11b's dynamic occlusion time), counted by hand: 0.1 s
    samples, in contact for 3 intervals, lifted for 4, in contact again for 2."""
    t = np.arange(10) * 0.1
    contact = np.array([1, 1, 1, 1, 0, 0, 0, 0, 1, 1], dtype=bool)
    clock = accumulated_contact_time(t, contact)
    np.testing.assert_allclose(clock, [0, 0.1, 0.2, 0.3, 0.3, 0.3, 0.3, 0.3, 0.4, 0.5],
                               atol=1e-12)
    model = augment(DimensionlessGroup(), [OcclusionDrift()]).with_params(
        **{"occlusion-drift.gain": 1.0, "occlusion-drift.time_constant": 1.0,
           "occlusion-drift.psi_share": 0.0})
    steady = {"amplitude": np.zeros(10), "speed": np.full(10, 0.05),
              "normal_force": np.full(10, 0.5), "frequency": np.full(10, 30e3)}
    drift = model.forward(occlusion_time=clock, **steady) / model.base.forward(**steady)
    np.testing.assert_allclose(drift, 2.0 - np.exp(-clock), rtol=1e-12)
