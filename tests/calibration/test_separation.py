"""The separating experiment (spec/calibration.md section 9, K31-K34): the design on its own,
`hcard calibrate plan --separate`, and the run that settles an ambiguous verdict on a device
with an air layer hidden in its hardware."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hcard.calibration.separation import MIN_FORCE_N, Noise, design, make_pair, protocol_conditions
from hcard.physics.profile import DeviceProfile
from hcard.plugins.registry import get_registry
from tests.helpers.cli import run_hcard

D_E = 200e-6 / 1560.0 + 90e-6 / 3.35
"""d_sc/eps_sc + d_i/eps_i of the section 3.6.1 contact, m (written here apart from the
plugin)."""
D = 290e-6


def air_factor(fn: np.ndarray, gap_1n: float) -> np.ndarray:
    """Eq. 3.17's scaling of the EV force with an air gap d_a1 (1 N / Fn), eps_a = 1."""
    gap = gap_1n / fn
    return D_E * D / ((D_E + gap) * (D + gap))


@pytest.fixture(scope="module")
def found():
    registry = get_registry()
    effects = registry.calibration_effects
    pair = make_pair(effects["air-layer"], effects["finger-geometry"],
                     DeviceProfile.coupled_stimulator(),
                     registry.get("predictor", "finger-friction"), {"air_gap": 6e-6})
    return design(pair, Noise(sigma_n=0.0079, recorded_s=30.75))


def test_the_design_goes_where_the_air_layer_differs_most(found):
    forces = found.chosen.normal_force
    # the lightest touch is chosen: the air layer takes most of the EV force there
    assert forces.min() == pytest.approx(MIN_FORCE_N)
    assert air_factor(np.array([MIN_FORCE_N]), 6e-6)[0] < 0.5 * air_factor(
        np.array([0.35]), 6e-6)[0]
    # at full voltage there
    assert found.chosen.voltage.max() == pytest.approx(2000.0)
    # the rival fitted to mimic the air layer follows it over the protocol, not there
    assert found.protocol_rms_n < np.max(np.abs(found.chosen_difference_n))
    assert found.expected["rmse_margin"] >= 0.01
    assert found.expected["criterion_margin"] >= 10.0


def test_the_air_layer_factor_matches_eq_3_17():
    effect = get_registry().calibration_effects["air-layer"]
    fn = np.array([0.1, 0.35, 1.5, 3.0])
    out = effect.transform_output(np.ones(4), {"normal_force": fn}, {"air_gap": 6e-6})
    assert np.allclose(out, air_factor(fn, 6e-6), rtol=1e-9)
    assert out[0] < 0.4 < 0.8 < out[-1]


def test_protocol_conditions_span_the_protocol_forces():
    c = protocol_conditions(DeviceProfile.coupled_stimulator(), "ev")
    assert set(np.round(c.normal_force, 3)) == {0.15, 0.35, 0.7, 1.5}


def test_plan_separate_writes_the_card_track_and_design(tmp_path):
    result = run_hcard("calibrate", "plan", "--device", "coupled", "--separate",
                       "air-layer,finger-geometry", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    for name in ("separate.hcard", "separate.csv", "design.json"):
        assert (tmp_path / name).is_file()
    content = json.loads((tmp_path / "design.json").read_text())
    assert content["reference"]["effect"] == "air-layer"
    assert content["rival"]["effect"] == "finger-geometry"
    assert content["conditions"] and content["sessions"]
    assert "expected" in content and content["noise"]["source"].startswith("defaults")


@pytest.mark.parametrize(("args", "words"), [
    (["--separate", "air-layer,nope"], "unknown effect(s) nope; installed:"),
    (["--separate", "air-layer,air-layer"], "one effect twice"),
    (["--separate", "air-layer,ultrasonic-speed"], "different channels"),
    (["--separate", "occlusion-drift,skin-recovery"], "does not set"),
    (["--separate", "air-layer,finger-geometry", "--from", "NOFOLDER"], "no profile.json"),
])
def test_plan_separate_errors(tmp_path, args, words):
    args = [str(tmp_path / "none") if a == "NOFOLDER" else a for a in args]
    result = run_hcard("calibrate", "plan", "--device", "coupled", *args, "-o", tmp_path / "o")
    assert result.exit_code != 0
    assert words in result.output
    assert "Traceback" not in result.output


def test_a_device_class_that_cannot_render_the_channel(tmp_path):
    result = run_hcard("calibrate", "plan", "--device", "uv", "--separate",
                       "air-layer,finger-geometry", "-o", tmp_path)
    assert result.exit_code != 0 and "cannot render the EV channel" in result.output


@pytest.mark.wall_clock
def test_the_separating_experiment_settles_the_air_layer(tmp_path):
    uri = "sim://coupled?seed=8&effect=air-layer&air-layer.air_gap=6e-06"
    plan = tmp_path / "plan"
    assert run_hcard("calibrate", "plan", "--device", "ev", "--duration", "30s",
                     "--verify-duration", "16s", "-o", plan).exit_code == 0
    rec = tmp_path / "rec.csv"
    assert run_hcard("play", plan / "protocol.hcard", "--track", plan / "protocol.csv",
                     "--device", uri, "-o", rec).exit_code == 0
    result = run_hcard("calibrate", rec, "-o", tmp_path / "calib", "--quiet", "--no-figures",
                       "--bootstrap", "0", "--verify", uri, "--verify-card",
                       plan / "verify.hcard", "--verify-track", plan / "verify.csv", "--settle")
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "calib" / "report.json").read_text())
    separation = report["separation"]
    assert separation["before"]["ambiguous"]
    after = separation["after"]
    assert after["effects"] == ["air-layer"], after
    assert not after["ambiguous"], after
    assert after["rmse_margin"] >= 0.01 and after["criterion_margin"] >= 10.0
    assert (tmp_path / "calib" / "separate" / "design.json").exists()
    assert separation["experiments"][0]["recording"] == "separate-recording.csv"
    assert sum(e["duration_s"] for e in separation["experiments"]) <= 120.0  # --settle-time


@pytest.mark.parametrize(("value", "words"), [("0s", "must be a duration > 0"),
                                               ("soon", "--settle-time 'soon'")])
def test_a_bad_settle_time_is_a_usage_error(tmp_path, value, words):
    rec = tmp_path / "rec.csv"
    rec.write_text("t_s,fn_n,fl_n,voltage_v\n0,0.5,0.2,0\n0.001,0.5,0.2,10\n")
    result = run_hcard("calibrate", rec, "-o", tmp_path / "calib", "--settle", "--settle-time",
                       value, "--verify", "sim://coupled")
    assert result.exit_code == 2, result.output
    assert words in result.output and "Traceback" not in result.output
