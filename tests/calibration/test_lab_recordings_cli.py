"""``hcard calibrate --map`` and ``hcard calibrate map``, and one bad input of each class with
its one-line message (spec/lab-recordings.md LR12, LR13)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

from hcard.calibration.lab import source
from hcard.calibration.lab.column_map import read_column_map
from hcard.calibration.lab.reading import read_recording
from hcard.calibration.measurement import MeasurementError, write_measurement
from hcard.cli.main import cli
from hcard_device.sim.tribometer import Protocol, synthesize

GAIN_N_PER_V, OFFSET_V = 0.4, 0.25


def test_calibrating_a_mat_copy_gives_the_fit_of_the_csv(tmp_path: Path) -> None:
    (rec,) = synthesize("uv", {"ultrasonic-speed": {"speed_exponent": -0.6}},
                        protocol=Protocol(duration_s=20.0), lateral_noise_n=1.5e-3,
                        normal_noise_n=1.5e-3, drift_n=2e-3, seed=4)
    write_measurement(rec, tmp_path / "rec.csv")
    scipy.io.savemat(tmp_path / "rec.mat", {
        "t_s": rec.t, "Fn_mN": rec.normal_force * 1e3,
        "ai1": rec.lateral_force / GAIN_N_PER_V + OFFSET_V,
        "amp_um": rec.amplitude * 1e6, "v_mm_s": rec.speed * 1e3})
    rig = {"hcard_column_map": 1, "columns": {
        "t_s": {"quantity": "t", "unit": "s"}, "Fn_mN": {"quantity": "fn", "unit": "mn"},
        "ai1": {"quantity": "fl", "unit": "n", "gain": GAIN_N_PER_V, "offset": OFFSET_V},
        "amp_um": {"quantity": "amplitude", "unit": "um"},
        "v_mm_s": {"quantity": "speed", "unit": "mm_s"}},
        "conditions": {k: v for k, v in rec.conditions.items()}}
    (tmp_path / "rig.json").write_text(json.dumps(rig))
    reports = {}
    for form, args in (("csv", [str(tmp_path / "rec.csv")]),
                       ("mat", ["--map", str(tmp_path / "rig.json"), str(tmp_path / "rec.mat")])):
        out = tmp_path / form
        result = CliRunner().invoke(cli, ["calibrate", *args, "--model", "dimensionless-group",
                                          "--bootstrap", "0", "--no-figures", "-o", str(out)])
        assert result.exit_code == 0, result.output
        reports[form] = json.loads((out / "report.json").read_text())
    csv_rmse, mat_rmse = (reports[f]["held_out_rmse_n"] for f in ("csv", "mat"))
    assert mat_rmse["after"] == pytest.approx(csv_rmse["after"], rel=1e-6)
    assert mat_rmse["before"] == pytest.approx(csv_rmse["before"], rel=1e-6)
    assert mat_rmse["after"] < 0.5 * mat_rmse["before"]


def test_map_proposes_quantities_and_lists_what_it_could_not_decide(tmp_path: Path) -> None:
    t = np.arange(500) / 1000.0
    counts = np.mod(np.arange(500) * 300, 65536).astype(float)
    scipy.io.savemat(tmp_path / "lab.mat", {
        "time_ms": t * 1e3, "Fn_N": np.ones(500), "force_mN": np.ones(500),
        "pos_counts": counts, "ai3": np.zeros(500), "Volt_V": np.zeros(500)})
    out = tmp_path / "rig.json"
    result = CliRunner().invoke(cli, ["calibrate", "map", str(tmp_path / "lab.mat"),
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    proposed = json.loads(out.read_text())
    quantities = {k: (v["quantity"], v.get("unit")) for k, v in proposed["columns"].items()}
    assert quantities == {"time_ms": ("t", "ms"), "Fn_N": ("fn", "n"),
                          "force_mN": (None, "mn"), "pos_counts": ("x", "counts"),
                          "ai3": (None, None), "Volt_V": ("voltage", "v")}
    assert proposed["columns"]["pos_counts"]["wrap"] == 65536
    assert proposed["derive"] == {"speed": "x"}
    undecided = [line for line in result.stderr.splitlines() if line.startswith("undecided:")]
    assert undecided == [
        "undecided: channel force_mN: a force (mn), set quantity fn or fl",
        "undecided: channel pos_counts: counts, set counts_per_mm",
        "undecided: channel ai3: unknown quantity, set quantity",
        "undecided: fl: no channel found, set a channel's quantity to fl",
        "undecided: labels.device: set the device's name",
    ]
    assert "sample rate from the time variable: 1000 Hz" in result.stderr
    # the proposal is refused until the open questions are answered
    with pytest.raises(MeasurementError, match=r"columns\.force_mN\.quantity: not set"):
        read_column_map(out)


def _mat(tmp_path: Path, **variables: object) -> Path:
    path = tmp_path / "bad.mat"
    scipy.io.savemat(path, variables)
    return path


def _map(tmp_path: Path, columns: dict[str, object] | None = None, **extra: object) -> Path:
    data = {"hcard_column_map": 1, "columns": columns or {
        "t": {"quantity": "t", "unit": "s"}, "fn": {"quantity": "fn", "unit": "n"},
        "fl": {"quantity": "fl", "unit": "n"}, "a": {"quantity": "amplitude", "unit": "um"}},
        "labels": {"device": "d"}, **extra}
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(data) if "raw" not in extra else str(extra["raw"]))
    return path


GOOD = {"t": np.arange(10) / 100.0, "fn": np.ones(10), "fl": np.ones(10), "a": np.ones(10)}


def _cli_error(args: list[str]) -> str:
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_a_map_naming_a_variable_not_in_the_file(tmp_path: Path) -> None:
    mat = _mat(tmp_path, **{k: v for k, v in GOOD.items() if k != "fl"})
    line = _cli_error(["calibrate", "--map", str(_map(tmp_path)), str(mat)])
    assert line == f"Error: {mat}: variable 'fl': not in the file (it has: t, fn, a)"


def test_an_unknown_unit(tmp_path: Path) -> None:
    rig = _map(tmp_path, {"t": {"quantity": "t", "unit": "s"},
                          "fn": {"quantity": "fn", "unit": "lbf"}})
    line = _cli_error(["calibrate", "--map", str(rig), str(_mat(tmp_path, **GOOD))])
    assert line == f"Error: {rig}: columns.fn.unit: unknown unit 'lbf' for fn (known: n, mn)"


@pytest.mark.parametrize("gain, reason", [
    ("NaN", ": bad column map JSON (NaN is not JSON"),
    ("1e999", ": columns.fn.gain: must be a finite number, not inf"),
    ("0", ": columns.fn.gain: must not be 0"),
])
def test_a_gain_that_is_not_a_finite_non_zero_number(tmp_path: Path, gain: str,
                                                     reason: str) -> None:
    rig = tmp_path / "rig.json"
    rig.write_text('{"hcard_column_map": 1, "columns": {"fn": {"quantity": "fn", "gain": '
                   f'{gain}}}}}}}')
    line = _cli_error(["calibrate", "--map", str(rig), str(_mat(tmp_path, **GOOD))])
    assert line.startswith(f"Error: {rig}{reason}")


def test_time_that_does_not_increase(tmp_path: Path) -> None:
    t = GOOD["t"].copy()
    t[4] = t[3]
    mat = _mat(tmp_path, **{**GOOD, "t": t})
    line = _cli_error(["calibrate", "--map", str(_map(tmp_path)), str(mat)])
    assert line == (f"Error: {mat}: sample 4: variable 't': time not increasing, 0.03 s "
                    "follows 0.03 s")


def test_a_mat_struct_named_instead_of_its_field(tmp_path: Path) -> None:
    mat = _mat(tmp_path, rec={"inner": {"fn": np.ones(10)}}, **GOOD)
    columns = {"t": {"quantity": "t", "unit": "s"}, "rec.inner": {"quantity": "fn", "unit": "n"},
               "fl": {"quantity": "fl", "unit": "n"}, "a": {"quantity": "amplitude", "unit": "um"}}
    line = _cli_error(["calibrate", "--map", str(_map(tmp_path, columns)), str(mat)])
    assert line == (f"Error: {mat}: variable 'rec.inner': a struct (fields: fn); map a "
                    "field, e.g. rec.inner.fn")
    columns["rec.inner.fn"] = columns.pop("rec.inner")
    m = read_recording(mat, read_column_map(_map(tmp_path, columns)))
    assert m.normal_force.tolist() == [1.0] * 10


def test_a_variable_longer_than_the_limit_is_refused_before_it_is_read(tmp_path: Path) -> None:
    path = tmp_path / "huge.h5"
    with h5py.File(path, "w") as f:  # chunked and never written: 240 MB declared, ~0 on disk
        f.create_dataset("t", shape=(30_000_000,), dtype="f8", chunks=(65536,))
    line = _cli_error(["calibrate", "--map", str(_map(tmp_path)), str(path)])
    assert line == (f"Error: {path}: variable 't': 30000000 samples, more than "
                    f"{source.MAX_SAMPLES}")


def test_hdf5_nested_deeper_than_the_limit(tmp_path: Path) -> None:
    path = tmp_path / "deep.h5"
    with h5py.File(path, "w") as f:
        f["/".join(["g"] * 12) + "/fn"] = np.ones(3)
    line = _cli_error(["calibrate", "map", str(path)])
    assert line == (f"Error: {path}: group 'g/g/g/g/g/g/g/g': nested more than "
                    f"{source.MAX_DEPTH} deep")


def test_a_lab_file_without_a_map(tmp_path: Path) -> None:
    mat = _mat(tmp_path, **GOOD)
    line = _cli_error(["calibrate", str(mat)])
    assert line == (f"Error: {mat}: a lab file (mat); read it through a column map (--map "
                    "RIG.json; `hcard calibrate map FILE` proposes one)")


def test_a_matrix_where_one_channel_is_expected(tmp_path: Path) -> None:
    mat = _mat(tmp_path, **{**GOOD, "fn": np.ones((10, 2))})
    line = _cli_error(["calibrate", "--map", str(_map(tmp_path)), str(mat)])
    assert line == (f"Error: {mat}: variable 'fn': shape (10, 2) is not one column; map one "
                    "channel per variable, or a matrix's column K as NAME(:,K)")
