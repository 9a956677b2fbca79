"""``hcard predict`` and the sweep / quantity parsing behind it."""

from __future__ import annotations

import csv
import functools
import json
import math

import click
import numpy as np
import pytest

from hcard.cli.predict_cmd import evaluate, make_figure, predict
from hcard.physics.profile import DeviceProfile
from hcard.physics.sweep import SweepError, parse_sweep, quantity, split_assignment
from hcard.plugins.registry import get_registry
from hcard.quantities import UnitError, display_unit
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from tests.helpers.cli import assert_one_line_error, run_hcard

DIMENSIONLESS = DimensionlessGroup.name
MU0, NU, PSI_STAR = 0.5, 0.33, 2.38


def closed_form(w, speed=0.02, f=27_500.0, psi_star=PSI_STAR, mu0=MU0):
    """Eqs. 2.30 and 2.33."""
    psi = speed / (np.asarray(w) * f * mu0 * (1 + NU))
    return 1 - np.exp(-psi / psi_star)


run = functools.partial(run_hcard, "predict")
"""``hcard predict ARGS``."""


def read_csv(path):
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array(rows[1:], dtype=float)


# ---------------------------------------------------------------------------- numbers


def test_sweep_to_csv_equals_the_closed_form(tmp_path):
    out = tmp_path / "out.csv"
    result = run(DIMENSIONLESS, "--sweep", "amplitude=1um:5um:5", "--input", "speed=20mm/s",
                 "--input", "frequency=27.5kHz", "--input", "normal_force=0.5N", "-o", out)
    assert result.exit_code == 0, result.output
    header, data = read_csv(out)
    assert header == ["amplitude [m]", "frequency [Hz]", "speed [m/s]", "normal_force [N]",
                      "relative_friction [-]"]
    np.testing.assert_allclose(data[:, 0], [1e-6, 2e-6, 3e-6, 4e-6, 5e-6], rtol=1e-12)
    np.testing.assert_allclose(data[:, 1:4], [[27_500.0, 0.02, 0.5]] * 5)
    np.testing.assert_allclose(data[:, 4], closed_form(data[:, 0]), rtol=1e-10)
    # mu'(1 um) = 1 - exp(-1.0937 / 2.38) = 0.3684
    assert data[0, 4] == pytest.approx(0.36841, abs=1e-5)
    assert "5 rows" in result.output


def test_table_has_unit_columns_and_the_fixed_inputs():
    result = run(DIMENSIONLESS, "--sweep", "amplitude=0:5um:6", "--input", "speed=50 mm/s")
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0] == (f"# {DIMENSIONLESS}: frequency = 27.5 kHz, speed = 50 mm/s, "
                        "normal_force = 0.5 N")
    # The table shows each column in a readable unit (the CSV stays in SI).
    assert lines[1].split() == ["amplitude", "[µm]", "relative_friction", "[-]"]
    values = np.array([line.split() for line in lines[2:]], dtype=float)
    assert values[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    assert values[0, 1] == 1.0  # no vibration, natural friction
    np.testing.assert_allclose(
        values[1:, 1], closed_form(values[1:, 0] * 1e-6, speed=0.05), rtol=1e-5
    )


def test_single_point_with_parameters_in_units():
    result = run("spring-slider", "--param", "normal_stiffness=3.9MN/m",
                 "--param", "lateral_stiffness=1500 kN/m", "--input", "amplitude=2um")
    assert result.exit_code == 0, result.output
    header, row = result.output.splitlines()
    assert header.split()[-2:] == ["relative_friction", "[-]"]
    # the spring-slider's relative friction at w = 2 um (Eqs. 2.19-2.28;
    # tests/builtins/test_ultrasonic.py)
    assert float(row.split()[-1]) == pytest.approx(0.247, abs=0.01)


def test_sweeping_a_parameter():
    result = run(DIMENSIONLESS, "--input", "amplitude=2um", "--sweep", "psi_star=1:4:4")
    assert result.exit_code == 0, result.output
    values = np.array([line.split() for line in result.output.splitlines()[2:]], dtype=float)
    np.testing.assert_allclose(values[:, 0], [1, 2, 3, 4])
    np.testing.assert_allclose(values[:, 1], closed_form(2e-6, psi_star=values[:, 0]), rtol=1e-5)


def test_log_sweep_and_the_unit_of_the_other_end():
    sweep = parse_sweep("frequency", "20:60kHz:3:log", "Hz")
    np.testing.assert_allclose(sweep.values(), [20e3, math.sqrt(20e3 * 60e3), 60e3])
    values = parse_sweep("amplitude", "0:5um:51", "m").values()
    assert values[[0, 10, 50]].tolist() == pytest.approx([0.0, 1e-6, 5e-6], rel=1e-12)
    assert parse_sweep("amplitude", "1:5um:5", "m").start == pytest.approx(1e-6)
    assert parse_sweep("amplitude", "1um:5e-6:5", "m").stop == pytest.approx(5e-12)
    assert parse_sweep("speed", "0.01:0.1:10", "m/s").stop == 0.1


def test_coupled_with_a_device_profile(tmp_path):
    path = tmp_path / "device.json"
    profile = DeviceProfile.coupled_stimulator()
    profile = DeviceProfile(profile.predictor.with_params(uv_psi_star=1.8), profile.limits)
    profile.save(path)
    # The UV sub-model of the profile's coupled predictor, by its own name.
    result = run(DIMENSIONLESS, "--profile", path, "--input", "amplitude=1um")
    assert result.exit_code == 0, result.output
    assert float(result.output.split()[-1]) == pytest.approx(
        float(closed_form(1e-6, psi_star=1.8)), rel=1e-5
    )
    # Without MODEL: the profile's predictor, the coupled model.
    result = run("--profile", path, "--input", "amplitude=1um", "--input", "voltage=0")
    assert result.exit_code == 0, result.output
    assert float(result.output.split()[-1]) == pytest.approx(
        float(closed_form(1e-6, f=38_220.0, psi_star=1.8)), rel=1e-5
    )
    # --param overrides the profile.
    result = run(DIMENSIONLESS, "--profile", path, "--param", "psi_star=4.69",
                 "--input", "amplitude=1um")
    assert float(result.output.split()[-1]) == pytest.approx(
        float(closed_form(1e-6, psi_star=4.69)), rel=1e-5
    )


def test_uv_device_profile(tmp_path):
    path = tmp_path / "dimensionless.json"
    DeviceProfile(DimensionlessGroup(mu0=1.0), None).save(path)
    result = run(DIMENSIONLESS, "--profile", path, "--input", "amplitude=1um")
    assert result.exit_code == 0, result.output
    assert float(result.output.split()[-1]) == pytest.approx(
        float(closed_form(1e-6, mu0=1.0)), rel=1e-5
    )


# ------------------------------------------------------------------------------- plot


def test_plot_is_written_with_labelled_axes(tmp_path):
    out = tmp_path / "sweep.png"
    result = run(DIMENSIONLESS, "--sweep", "amplitude=0.5um:5um:10", "--input", "speed=20mm/s",
                 "--plot", out)
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    prediction = evaluate(get_registry().get("predictor", DIMENSIONLESS), {},
                          {"speed": "20mm/s"}, "amplitude=0.5um:5um:10")
    axes = make_figure(prediction).axes[0]
    assert axes.get_xlabel() == "amplitude [µm]"
    assert axes.get_ylabel().startswith("relative friction") and "[-]" in axes.get_ylabel()
    assert DIMENSIONLESS in axes.get_title() and "speed = 20 mm/s" in axes.get_title()
    x, y = axes.lines[0].get_data()
    np.testing.assert_allclose(x, np.linspace(0.5, 5, 10))  # plotted in um
    np.testing.assert_allclose(y, closed_form(x * 1e-6), rtol=1e-9)


def test_display_units():
    assert display_unit("m", [5e-6]) == (1e-6, "µm")
    assert display_unit("m/s", [0.02]) == (1e-3, "mm/s")
    assert display_unit("Hz", [27_500.0]) == (1e3, "kHz")
    assert display_unit("N/m", [3.9e6]) == (1e6, "MN/m")
    assert display_unit("N", [0.5]) == (1.0, "N")
    assert display_unit("", [0.3]) == (1.0, "")


# ----------------------------------------------------------------------------- listing


def test_list_shows_every_model_with_parameters_and_inputs():
    for args in ((), ("--list",)):
        result = run(*args)
        assert result.exit_code == 0, result.output
        for name, model in get_registry().predictors.items():
            assert f"{name}: {model.description}" in result.output
        assert "NAME" in result.output and "BOUNDS" in result.output
    result = run(DIMENSIONLESS, "--list")
    lines = result.output.splitlines()
    assert lines[0].startswith(f"{DIMENSIONLESS}: ")
    assert any(line.strip().startswith("amplitude [m] (required)") for line in lines)
    assert any(line.strip().startswith("speed [m/s] (default 0.02)") for line in lines)
    row = next(line for line in lines if line.strip().startswith("psi_star "))
    assert row.split()[:4] == ["psi_star", "-", "2.38", "[0.001,"] and "Eq. 2.33" in row
    assert "inverse: amplitude" in result.output
    assert "spring-slider" not in result.output


def test_every_option_has_help():
    for param in predict.params:
        if isinstance(param, click.Option):
            assert param.help and len(param.help) > 15, param.name
    result = run("--help")
    assert result.exit_code == 0 and "--sweep NAME=START:STOP:COUNT" in result.output


# ------------------------------------------------------------------------------ errors


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (("nosuch",), ("no predictor plugin named 'nosuch'", DIMENSIONLESS)),
        ((DIMENSIONLESS, "--param", "kn=1"), ("unknown parameter 'kn'", "psi_star")),
        ((DIMENSIONLESS, "--input", "velocity=1"), ("unknown input 'velocity'", "speed")),
        ((DIMENSIONLESS, "--input", "speed=5Hz"), ("--input speed", "'Hz' is not a unit of m/s")),
        ((DIMENSIONLESS, "--input", "speed=5 furlong"), ("unknown unit 'furlong'",)),
        ((DIMENSIONLESS, "--input", "speed=fast"), ("'fast' is not a number",)),
        ((DIMENSIONLESS, "--param", "psi_star=-1"),
         ("psi_star = -1 is outside its bounds [0.001, 1000]",)),
        (("spring-slider", "--param", "normal_stiffness=5N/m", "--input", "amplitude=1um"),
         ("normal_stiffness = 5 N/m is outside its bounds",)),
        ((DIMENSIONLESS, "--input", "amplitude=-1um"), ("amplitude must be >= 0 m",)),
        ((DIMENSIONLESS,), ("input amplitude (m) is required", "--sweep amplitude=")),
        ((DIMENSIONLESS, "--sweep", "amplitude=0:5um"), ("expected START:STOP:COUNT",)),
        ((DIMENSIONLESS, "--sweep", "amplitude=0:5um:1"), ("COUNT must be between 2",)),
        ((DIMENSIONLESS, "--sweep", "amplitude=0:5um:x"), ("COUNT must be an integer",)),
        ((DIMENSIONLESS, "--sweep", "amplitude=1um:5kHz:5"), ("STOP", "not a unit of m")),
        ((DIMENSIONLESS, "--sweep", "amplitude=0:5um:5:log"), ("log sweep needs",)),
        ((DIMENSIONLESS, "--sweep", "mass=0:1:5"), ("cannot sweep 'mass'",)),
        ((DIMENSIONLESS, "--sweep", "amplitude"), ("expected NAME=VALUE",)),
        ((DIMENSIONLESS, "--input", "amplitude=1um", "--sweep", "amplitude=1um:2um:3"),
         ("both swept and set",)),
        ((DIMENSIONLESS, "--input", "amplitude=1um", "--input", "amplitude=2um"),
         ("given twice",)),
        ((DIMENSIONLESS, "--input", "amplitude=1um", "--plot", "x.png"),
         ("--plot needs --sweep",)),
        ((DIMENSIONLESS, "--sweep", "amplitude=0:5um:5", "--plot", "x.gif"),
         ("must end in .png",)),
    ],
)
def test_a_bad_option_value_is_a_one_line_usage_error(tmp_path, monkeypatch, args, fragments):
    """Every value given on the command line that cannot be used exits 2 (README: usage)."""
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(run(*args), *fragments, status=2)


def test_a_missing_profile_file_is_invalid_input(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(run(DIMENSIONLESS, "--profile", "missing.json"),
                          "missing.json: no such file", status=1)


def test_profile_errors_are_one_line(tmp_path):
    wrong_model = tmp_path / "kaczmarek.json"
    DeviceProfile(get_registry().get("predictor", "ev-kaczmarek"), None).save(wrong_model)
    assert_one_line_error(run(DIMENSIONLESS, "--profile", wrong_model, "--input", "amplitude=1um"),
                          "holds no parameters for model", "ev-kaczmarek")
    bad = tmp_path / "bad.json"
    raw = DeviceProfile.coupled_stimulator().to_dict()
    raw["limits"]["max_voltage"] = "2 kHz"
    bad.write_text(json.dumps(raw))
    assert_one_line_error(run("coupled", "--profile", bad), str(bad), "limits.max_voltage")
    unknown = tmp_path / "unknown.json"
    unknown.write_text(json.dumps({"format": "something/1"}))
    assert_one_line_error(run("--profile", unknown), "format: expected")


@pytest.mark.parametrize(("form", "advice"), [
    ("hcard-device-profile/1", "version 2 adds the effects"),
    ("hcard-calibrated-profile/1", "run 'hcard calibrate' on the recordings again"),
    ("hcard-predictor-profile/1", "now holds under 'predictor'"),
])
def test_old_profile_formats_are_a_clear_error(tmp_path, form, advice):
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"format": form, "model": "dimensionless-group",
                               "parameters": {}}))
    assert_one_line_error(run(DIMENSIONLESS, "--profile", old, "--input", "amplitude=1um"),
                          f"{old}: format: '{form}' is", advice)


def test_unwritable_output_is_a_one_line_error(tmp_path):
    result = run(DIMENSIONLESS, "--input", "amplitude=1um", "-o", tmp_path / "no" / "x.csv")
    assert_one_line_error(result, "cannot write")


# ---------------------------------------------------------------------- parsing helpers


def test_split_assignment_and_quantity():
    assert split_assignment(" speed = 20mm/s ", "--input") == ("speed", "20mm/s")
    with pytest.raises(SweepError, match="not a valid name"):
        split_assignment("2x=1", "--input")
    assert quantity("3.9MN/m", "N/m", "kn") == 3.9e6
    assert quantity("7 1/N", "1/N", "slope") == 7.0  # a unit the parser does not know
    with pytest.raises(UnitError, match=r"^kn: "):
        quantity("3.9 MHz", "N/m", "kn")
    with pytest.raises(UnitError, match="not a finite number"):
        quantity("1e999", "m", "amplitude")
    with pytest.raises(SweepError, match="START and STOP are equal"):
        parse_sweep("amplitude", "1um:1um:3", "m")
