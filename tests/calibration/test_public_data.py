"""The calibration loop on public real measurements (a lab's own data), with the figures
examples/public_data/*/README.md reports, and the matrix-column addressing (``NAME(:,K)``,
spec/lab-recordings.md LR10) their DAQ files need."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

from hcard.calibration.lab.errors import LabRecordingError
from hcard.calibration.lab.hdf5_files import Hdf5File
from hcard.calibration.lab.mat_files import MatFile
from hcard.calibration.lab.source import split_column
from hcard.cli.main import cli
from tests.helpers.public_samples import fetched_sample

REPO = Path(__file__).resolve().parents[2]
GRIGORII = REPO / "examples" / "public_data" / "grigorii-tribometer"


def test_split_column_reads_matlab_style_indices() -> None:
    assert split_column("dataQ(:,2)") == ("dataQ", 2)
    assert split_column("s.daq(:, 12)") == ("s.daq", 12)
    assert split_column("dataQ") == ("dataQ", None)
    assert split_column("dataQ(:,0)") == ("dataQ(:,0)", None)  # counted from 1


def test_mat_matrix_column_is_that_channel(tmp_path: Path) -> None:
    path = tmp_path / "daq.mat"
    matrix = np.arange(12.0).reshape(4, 3)  # 4 samples by 3 channels
    scipy.io.savemat(path, {"dataQ": matrix})
    lab = MatFile(path)
    assert lab.array("dataQ(:,2)").tolist() == [1.0, 4.0, 7.0, 10.0]
    with pytest.raises(LabRecordingError, match="has 3 columns, not 4"):
        lab.array("dataQ(:,4)")
    with pytest.raises(LabRecordingError, match=r"NAME\(:,K\)"):
        lab.array("dataQ")


def test_hdf5_matrix_column_plain_and_matlab_transposed(tmp_path: Path) -> None:
    matrix = np.arange(12.0).reshape(4, 3)
    plain = tmp_path / "daq.h5"
    with h5py.File(plain, "w") as f:
        f["dataQ"] = matrix
    assert Hdf5File(plain).array("dataQ(:,3)").tolist() == [2.0, 5.0, 8.0, 11.0]
    v73 = tmp_path / "daq73.mat"
    with h5py.File(v73, "w") as f:
        f["dataQ"] = matrix.T  # MATLAB writes an N-by-k matrix as k-by-N
    lab = Hdf5File(v73, matlab=True)  # as detect.py opens a file starting "MATLAB "
    assert lab.array("dataQ(:,3)").tolist() == [2.0, 5.0, 8.0, 11.0]


def test_grigorii_tribometer_loop_reports_the_readme_figures(tmp_path: Path) -> None:
    """examples/public_data/grigorii-tribometer/README.md: 85000 samples, 41427 sliding in
    contact (MS5), held-out RMSE 178.5 mN before and after, no effect added, friction_occluded
    0.181 +- 0.027, force_offset -4.32 +- 1.3 mN, friction_initial at its bound 0.01."""
    data = fetched_sample("romangrigorii/data-driven-playback-of-natural-tactile-texture",
                          "matlab/DAQ/data/data_temp.mat", "its project states no licence")
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, [
        "calibrate", "-q", "--map", str(GRIGORII / "rig.json"), str(data),
        "-o", str(out), "--model", "finger-friction"])
    assert result.exit_code == 0, result.output
    report = json.loads((out / "report.json").read_text())
    before, after = report["held_out_rmse_n"]["before"], report["held_out_rmse_n"]["after"]
    assert before == pytest.approx(0.1785, abs=0.0005)
    assert after == pytest.approx(0.1785, abs=0.0005)
    assert report["effects_added"] == []
    assert report["verdict"].startswith("structured residual")
    params = report["after"]["parameters"]
    assert params["friction_initial"]["value"] == pytest.approx(0.01, abs=1e-6)
    assert params["friction_occluded"]["value"] == pytest.approx(0.181, abs=0.005)
    assert params["friction_occluded"]["uncertainty"] == pytest.approx(0.027, abs=0.001)
    assert params["force_offset"]["value"] == pytest.approx(-0.00432, abs=0.0002)
    assert params["force_offset"]["uncertainty"] == pytest.approx(0.00128, abs=0.0001)
    assert report["after"]["train_rmse_n"] == pytest.approx(0.0603, abs=0.0005)
    assert "held-out model error: 178.5 mN before, 178.5 mN after" in result.output
