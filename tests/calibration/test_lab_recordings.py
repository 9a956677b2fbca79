"""Lab recordings read through a column map (spec/lab-recordings.md): files written here by
scipy.io.savemat, h5py and by hand from a known ground truth, read back and compared with that
ground truth (not with the reader's own output)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from hcard.calibration.lab.column_map import read_column_map
from hcard.calibration.lab.detect import file_kind
from hcard.calibration.lab.reading import read_recording

N = 3000
RATE_HZ = 2000.0
SPEED_M_S = 0.05
COUNTS_PER_MM = 1000.0
FN_GAIN_N_PER_V, FN_OFFSET_V = 2.5, 0.12
FL_GAIN_N_PER_V, FL_OFFSET_V = 0.8, -0.05


def truth() -> dict[str, np.ndarray]:
    """A ramp of the finger at 50 mm/s over 75 mm: 74 975 counts, past a 16-bit counter's
    65 536, so the counter wraps once."""
    t = np.arange(N) / RATE_HZ
    rng = np.random.default_rng(3)
    return {
        "t": t,
        "fn": 0.5 + 0.1 * np.sin(2 * np.pi * 2 * t),
        "fl": 0.3 + 0.05 * rng.standard_normal(N),
        "amplitude": 1e-6 * (1 + np.sin(2 * np.pi * 5 * t)),
        "x": SPEED_M_S * t,
    }


def lab_channels(g: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The rig's raw channels: volts = force / gain + offset, counts wrapping at 2^16."""
    counts = np.round(g["x"] * 1e3 * COUNTS_PER_MM)
    return {
        "time_ms": g["t"] * 1e3,
        "ai0": g["fn"] / FN_GAIN_N_PER_V + FN_OFFSET_V,
        "ai1": g["fl"] / FL_GAIN_N_PER_V + FL_OFFSET_V,
        "amp_nm": g["amplitude"] * 1e9,
        "enc": np.mod(counts, 65536),
    }


def rig_map(**extra: object) -> dict[str, object]:
    return {
        "hcard_column_map": 1,
        "columns": {
            "time_ms": {"quantity": "t", "unit": "ms"},
            "ai0": {"quantity": "fn", "unit": "n", "gain": FN_GAIN_N_PER_V,
                    "offset": FN_OFFSET_V},
            "ai1": {"quantity": "fl", "unit": "n", "gain": FL_GAIN_N_PER_V,
                    "offset": FL_OFFSET_V},
            "amp_nm": {"quantity": "amplitude", "unit": "nm"},
            "enc": {"quantity": "x", "unit": "counts", "wrap": 65536,
                    "counts_per_mm": COUNTS_PER_MM},
        },
        "derive": {"speed": "x"},
        "labels": {"device": "rig-7", "participant": {"filename": r"_(P\d+)_"}},
        "conditions": {"plate_frequency_hz": 27500},
        **extra,
    }


def write_map(path: Path, data: dict[str, object]) -> Path:
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def assert_matches_truth(m: object, g: dict[str, np.ndarray]) -> None:
    np.testing.assert_allclose(m.t, g["t"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.normal_force, g["fn"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.lateral_force, g["fl"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.amplitude, g["amplitude"], rtol=0, atol=1e-18)
    # 1 count is 1 um: the unwrapped encoder is within half a count of the truth, and goes
    # past 65.536 mm, where the raw counter wrapped
    np.testing.assert_allclose(m.x, g["x"], rtol=0, atol=0.5e-6)
    assert m.x[-1] == pytest.approx(0.074975, abs=1e-9)
    # the speed derived from x by numpy.gradient: 50 mm/s to the counter's resolution
    assert np.median(m.speed) == pytest.approx(SPEED_M_S, rel=1e-3)
    assert np.abs(m.speed - SPEED_M_S).max() < 1e-6 * RATE_HZ


def test_mat_v5_volts_and_a_wrapping_encoder_come_back_in_si(tmp_path: Path) -> None:
    g = truth()
    raw = lab_channels(g)
    assert raw["enc"].max() < 65536 and raw["enc"][-1] == 74975 - 65536
    path = tmp_path / "run_P03_a.mat"
    scipy.io.savemat(path, {k: v.reshape(-1, 1) for k, v in raw.items()})
    assert file_kind(path) == "mat"
    m = read_recording(path, read_column_map(write_map(tmp_path / "rig.json", rig_map())))
    assert_matches_truth(m, g)
    assert m.conditions == {"device": "rig-7", "participant": "P03",
                            "plate_frequency_hz": 27500}


def _write_v73(path: Path, data: dict[str, np.ndarray], participant: str) -> None:
    """A MATLAB v7.3 file as MATLAB lays it out: a 512-byte text header before the HDF5
    superblock, a struct as a group, an N-by-1 vector as a 1-by-N dataset, text as uint16
    with MATLAB_class 'char'."""
    with h5py.File(path, "w", userblock_size=512) as f:
        group = f.create_group("rec")
        group.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, values in data.items():
            dataset = group.create_dataset(key, data=values.reshape(1, -1))
            dataset.attrs["MATLAB_class"] = np.bytes_("double")
        chars = f.create_dataset("subject", data=np.array([[ord(c)] for c in participant],
                                                          dtype=np.uint16))
        chars.attrs["MATLAB_class"] = np.bytes_("char")
    with path.open("r+b") as stream:
        stream.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema")


def test_mat_v73_is_read_through_h5py(tmp_path: Path) -> None:
    g = truth()
    path = tmp_path / "session.mat"
    _write_v73(path, lab_channels(g), "P11")
    assert file_kind(path) == "mat73"
    data = rig_map(labels={"device": "rig-7", "participant": {"variable": "subject"}})
    data["columns"] = {f"rec.{k}": v for k, v in data["columns"].items()}  # type: ignore
    m = read_recording(path, read_column_map(write_map(tmp_path / "rig.json", data)))
    assert_matches_truth(m, g)
    assert m.conditions["participant"] == "P11"


def test_hdf5_without_a_time_column_takes_the_sample_rate(tmp_path: Path) -> None:
    g = truth()
    raw = lab_channels(g)
    path = tmp_path / "day2_P05_.h5"
    with h5py.File(path, "w") as f:
        for key, values in raw.items():
            if key != "time_ms":
                f[f"daq/{key}"] = values
    data = rig_map(sample_rate_hz=RATE_HZ)
    columns = data["columns"]
    assert isinstance(columns, dict)
    data["columns"] = {f"daq/{k}": v for k, v in columns.items() if k != "time_ms"}
    m = read_recording(path, read_column_map(write_map(tmp_path / "rig.json", data)))
    assert_matches_truth(m, g)
    assert m.t[1] == 1 / RATE_HZ and m.conditions["participant"] == "P05"


@pytest.mark.parametrize("separator, suffix", [("\t", ".tsv"), (",", ".csv")])
def test_delimited_files_with_the_labs_column_names(tmp_path: Path, separator: str,
                                                    suffix: str) -> None:
    g = truth()
    raw = lab_channels(g)
    names = list(raw)
    lines = ["# exported by the rig", separator.join(names)]
    lines += [separator.join(repr(float(raw[n][i])) for n in names) for i in range(N)]
    path = tmp_path / f"x_P01_{suffix}"
    path = path.with_suffix(suffix)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    m = read_recording(path, read_column_map(write_map(tmp_path / "rig.json", rig_map())))
    assert_matches_truth(m, g)
