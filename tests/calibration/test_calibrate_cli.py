"""``hcard calibrate``: the loop from the command line, its report, profile and user errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hcard.calibration.dataset import prepare
from hcard.calibration.measurement import read_measurement, write_measurement
from hcard.calibration.profile import fitted_model
from hcard.cli.main import cli
from hcard.physics.profile import DeviceProfile
from hcard_device.sim.tribometer import Protocol, synthesize


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 20 s UV tribometer recording with a hidden speed dependence (the tribometer
    simulation of :mod:`hcard_device.sim.tribometer`, independent of the calibration code)."""
    out = tmp_path_factory.mktemp("recordings")
    (recording,) = synthesize(
        "uv",
        {"ultrasonic-speed": {"speed_exponent": -0.6}},
        protocol=Protocol(duration_s=20.0),
        lateral_noise_n=1.5e-3,
        normal_noise_n=1.5e-3,
        drift_n=2e-3,
        seed=4,
    )
    write_measurement(recording, out / "rec_0.csv")
    return out


def test_calibrate_writes_a_report_that_leads_with_the_held_out_error(
    recorded: Path, tmp_path: Path
) -> None:
    out = tmp_path / "report"
    result = CliRunner().invoke(
        cli, ["calibrate", str(recorded), "--model", "dimensionless-group", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("held-out RMSE ") and "Added to dimensionless-group" in lines[0]
    effect_line = lines[1].strip()
    assert effect_line.startswith("ultrasonic-speed: speed_exponent = ")
    # the hidden law is (U / 20 mm/s)^-0.6: both its exponent and its anchor come back
    exponent = float(effect_line.split("speed_exponent = ")[1].split()[0])
    anchor = float(effect_line.split("reference_speed = ")[1].split()[0])
    assert exponent == pytest.approx(-0.6, abs=0.01)
    assert anchor == pytest.approx(0.020, rel=0.02)
    assert "round 1: ultrasonic-speed" in result.stderr  # progress, one line per fit
    report = json.loads((out / "report.json").read_text())
    before, after = report["held_out_rmse_n"]["before"], report["held_out_rmse_n"]["after"]
    assert after < 0.5 * before
    assert (
        (out / "report.md")
        .read_text()
        .splitlines()[2]
        .startswith(f"**Held-out RMSE: {before * 1e3:.4g} mN before, {after * 1e3:.4g} mN after")
    )
    assert "measured at" in (out / "report.md").read_text()  # the sensor zero, rule K4
    assert report["data"]["sensor_zero"][0]["lifts"] >= 3
    # Uncertainties from a stroke-block bootstrap by default (50 refits), stated as such; the
    # interval holds the hidden exponent, and its spread exceeds the Jacobian's.
    boot = report["bootstrap"]
    assert boot["samples"] == 50 and report["uncertainty_method"].startswith("stroke-block")
    low, high = boot["intervals_95"]["ultrasonic-speed.speed_exponent"]
    assert low <= -0.6 <= high
    sigma = boot["uncertainties"]["ultrasonic-speed.speed_exponent"]
    assert sigma > boot["jacobian_uncertainties"]["ultrasonic-speed.speed_exponent"]
    assert "Uncertainties: stroke-block bootstrap" in (out / "report.md").read_text()
    assert "bootstrap 50/50" in result.stderr
    for figure in ("residuals.png", "fit.png"):
        assert (out / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The fitted profile loads back into the same model.
    profile = DeviceProfile.load(out / "profile.json")
    assert profile.to_dict()["format"] == "hcard-device-profile/2"
    assert [f.name for f in profile.effects] == ["ultrasonic-speed"]
    model = fitted_model(profile)
    data = prepare([read_measurement(p) for p in sorted(recorded.glob("*.csv"))])
    residual = data.observed - model.forward(**data.inputs_for(model))
    # `hcard predict` evaluates the calibrated model like any other profile.
    point = CliRunner().invoke(
        cli,
        [
            "predict",
            "--profile",
            str(out / "profile.json"),
            "--input",
            "amplitude=1um",
            "--input",
            "speed=50mm/s",
            "--input",
            "normal_force=0.5N",
            "-o",
            str(tmp_path / "p.csv"),
        ],
    )
    assert point.exit_code == 0, point.output
    row = (tmp_path / "p.csv").read_text().splitlines()[-1].split(",")
    expected = model.forward(amplitude=1e-6, speed=0.05, normal_force=0.5)
    assert float(row[-1]) == pytest.approx(float(expected), rel=1e-9)
    assert np.sqrt(np.mean(residual[data.test] ** 2)) == pytest.approx(after, rel=1e-9)


def test_calibrate_strict_exits_1_when_structure_is_left(recorded: Path, tmp_path: Path) -> None:
    # Without the speed effect among the candidates the structure cannot be explained.
    result = CliRunner().invoke(
        cli,
        [
            "calibrate",
            str(recorded),
            "-m",
            "dimensionless-group",
            "--exclude",
            "ultrasonic-speed",
            "--strict",
            "--quiet",
            "--no-figures",
            "--no-rezero",
            "--bootstrap",
            "0",
            "-o",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 1, result.output
    assert "Structured residual not explained by any known effect: against speed" in result.stdout
    assert result.stderr == ""
    assert not (tmp_path / "fit.png").exists()
    assert "measured at" not in (tmp_path / "report.md").read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--model", "no-such-model"], "no-such-model"),
        (["--model", "dimensionless-group", "--effect", "magic"], "unknown effect(s) magic"),
        (
            ["--model", "dimensionless-group", "--free", "psi_star,wrong"],
            "unknown parameter(s) wrong",
        ),
        (["--model", "dimensionless-group", "--param", "mu0=abc"], "--param mu0"),
        (["--model", "dimensionless-group", "--test-fraction", "150%"], "between 0 and 1"),
        (["--model", "dimensionless-group", "--bootstrap", "1"], "--bootstrap needs at least 2"),
        (["--model", "dimensionless-group", "--contact-threshold", "-5mN"],
         "--contact-threshold '-5mN': must be a positive force"),
    ],
)
def test_calibrate_option_errors_are_one_line_usage_errors(
    recorded: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    result = CliRunner().invoke(cli, ["calibrate", str(recorded), *args, "-o", str(tmp_path)])
    assert result.exit_code == 2  # a bad option value (README: exit status)
    assert message in result.output
    assert "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())  # nothing written


def test_calibrate_names_the_bad_file(tmp_path: Path) -> None:
    bad = tmp_path / "rec.csv"
    bad.write_text("t_s,fn_n,fl_n,amplitude_um\n0,0.5,0.2,1\n0,0.5,0.2,1\n")
    (tmp_path / "rec.csv.json").write_text('{"device": "x"}')
    result = CliRunner().invoke(cli, ["calibrate", str(bad), "-m", "dimensionless-group"])
    assert result.exit_code == 1
    assert "rec.csv:3" in result.output and "time" in result.output
    missing = CliRunner().invoke(cli, ["calibrate", str(tmp_path / "nope.csv"), "-m", "coupled"])
    assert missing.exit_code == 1 and "no such file" in missing.output
    empty = tmp_path / "empty"
    empty.mkdir()
    none = CliRunner().invoke(cli, ["calibrate", str(empty), "-m", "coupled"])
    assert none.exit_code == 1 and "no .csv recordings" in none.output
