"""A study recorded on two rigs, each with its own files and column names, calibrated as one
population in one command (spec/lab-recordings.md LR14): the same numbers as the same study in
the project's own format."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import scipy.io
from click.testing import CliRunner

from hcard.calibration.population.synthetic import make_study
from hcard.cli.main import cli

N = 6
ARGUMENTS = ["-m", "dimensionless-group", "--effect", "load-index", "--no-figures", "--json",
             "--workers", "0"]


def _columns(csv: Path) -> dict[str, np.ndarray]:
    names = csv.read_text().splitlines()[0].split(",")
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    return {name: data[:, i] for i, name in enumerate(names)}


def _rig_a(csv: Path, folder: Path) -> None:
    """Rig A: a .mat of raw volts (normal force 2.5 N/V with 0.12 V offset, lateral force
    0.8 N/V with -0.05 V offset), amplitude in nm, time in ms; participant in the file name."""
    c = _columns(csv)
    scipy.io.savemat(folder / f"trial_{csv.stem.upper()}_.mat", {
        "time_ms": c["t_s"] * 1e3, "ai0": c["fn_n"] / 2.5 + 0.12,
        "ai1": c["fl_n"] / 0.8 - 0.05, "amp_nm": c["amplitude_m"] * 1e9,
        "vel_mm_s": c["speed_m_s"] * 1e3})


def _rig_b(csv: Path, folder: Path) -> None:
    """Rig B: a TSV in mN and um with its own names; participant in the file name."""
    c = _columns(csv)
    rows = ["Time\tNormal\tLateral\tAmp\tSpeed"] + [
        "\t".join(repr(float(v)) for v in values) for values in zip(
            c["t_s"], c["fn_n"] * 1e3, c["fl_n"] * 1e3, c["amplitude_m"] * 1e6,
            c["speed_m_s"], strict=True)]
    (folder / f"{csv.stem.upper()}.tsv").write_text("\n".join(rows) + "\n")


RIG_A = {"hcard_column_map": 1, "columns": {
    "time_ms": {"quantity": "t", "unit": "ms"},
    "ai0": {"quantity": "fn", "unit": "n", "gain": 2.5, "offset": 0.12},
    "ai1": {"quantity": "fl", "unit": "n", "gain": 0.8, "offset": -0.05},
    "amp_nm": {"quantity": "amplitude", "unit": "nm"},
    "vel_mm_s": {"quantity": "speed", "unit": "mm_s"}},
    "labels": {"device": "rig-a", "participant": {"filename": "_(P\\d+)_"}},
    "conditions": {"plate_frequency_hz": 27500.0}}
RIG_B = {"hcard_column_map": 1, "delimiter": "\t", "columns": {
    "Time": {"quantity": "t", "unit": "s"}, "Normal": {"quantity": "fn", "unit": "mn"},
    "Lateral": {"quantity": "fl", "unit": "mn"}, "Amp": {"quantity": "amplitude", "unit": "um"},
    "Speed": {"quantity": "speed", "unit": "m_s"}},
    "labels": {"device": "rig-b", "participant": {"filename": "(P\\d+)\\.tsv"}},
    "conditions": {"plate_frequency_hz": 27500.0}}


def _two_rig_study(tmp_path: Path) -> tuple[Path, Path, Path]:
    own = tmp_path / "own"
    make_study(own, N, seed=5)
    rig_a, rig_b = tmp_path / "rig_a", tmp_path / "rig_b"
    rig_a.mkdir(), rig_b.mkdir()
    for index, csv in enumerate(sorted(own.glob("p*.csv"))):
        (_rig_a if index % 2 == 0 else _rig_b)(csv, rig_a if index % 2 == 0 else rig_b)
        # the participant label of the project's own files, as the rigs' file names give it
        sidecar = Path(f"{csv}.json")
        conditions = json.loads(sidecar.read_text())
        conditions["participant"] = csv.stem.upper()
        sidecar.write_text(json.dumps(conditions))
    (tmp_path / "a.json").write_text(json.dumps(RIG_A))
    (tmp_path / "b.json").write_text(json.dumps(RIG_B))
    return own, rig_a, rig_b


def test_a_study_on_two_rigs_is_one_population_with_the_numbers_of_its_own_format(
        tmp_path: Path) -> None:
    own, rig_a, rig_b = _two_rig_study(tmp_path)
    runner = CliRunner()
    mapped = runner.invoke(cli, [
        "calibrate", "population", str(rig_a), str(rig_b), "-o", str(tmp_path / "mapped"),
        "--map", f"{rig_a}/*={tmp_path / 'a.json'}", "--map", f"*.tsv={tmp_path / 'b.json'}",
        *ARGUMENTS])
    assert mapped.exit_code == 0, mapped.output
    plain = runner.invoke(cli, ["calibrate", "population", str(own), "-o",
                                str(tmp_path / "plain"), *ARGUMENTS])
    assert plain.exit_code == 0, plain.output
    got, expected = json.loads(mapped.stdout), json.loads(plain.stdout)
    assert sorted(p["label"] for p in got["participants"]) == [f"P{i:03d}" for i in range(N)]
    for name, population in expected["population"].items():
        for key in ("mu", "tau"):
            # volts and milli-units scaled back differ from the CSV's values in the last bits
            assert np.isclose(got["population"][name][key], population[key], rtol=1e-6,
                              atol=1e-9), (name, key)
    assert got["effects"]["added"] == expected["effects"]["added"]
    trial, expected_trial = got["effects"]["trials"][0], expected["effects"]["trials"][0]
    assert trial["earns_place_for"] == expected_trial["earns_place_for"]
    assert np.isclose(trial["summed_criterion_change"],
                      expected_trial["summed_criterion_change"], rtol=1e-5)


def test_a_recording_no_pattern_matches_is_named_before_any_fit(tmp_path: Path) -> None:
    _own, rig_a, rig_b = _two_rig_study(tmp_path)
    done = CliRunner().invoke(cli, [
        "calibrate", "population", str(rig_a), str(rig_b), "-o", str(tmp_path / "out"),
        "--map", f"{rig_a}/*={tmp_path / 'a.json'}", *ARGUMENTS])
    assert done.exit_code == 1
    assert "P001.tsv: no --map pattern matches this file (patterns: " in done.output
    assert "Traceback" not in done.output and not (tmp_path / "out").exists()
    missing = CliRunner().invoke(cli, [
        "calibrate", "population", str(rig_a), "-o", str(tmp_path / "out"),
        "--map", f"*={tmp_path / 'nowhere.json'}", *ARGUMENTS])
    assert missing.exit_code == 1
    assert "nowhere.json: no such file" in missing.output


def test_the_command_keeps_no_recordings_samples_while_it_groups(tmp_path: Path) -> None:
    """What the client keeps of each recording to group and choose the base: its conditions,
    its source and one sample (its 840 samples are read again by its task)."""
    from hcard.calibration.lab.rigs import RecordingFile
    from hcard.calibration.population.grouping import label_of, without_samples

    own, _rig_a, _rig_b = _two_rig_study(tmp_path)
    full = RecordingFile(str(own / "p002.csv")).read()
    kept = without_samples(full)
    assert (len(full), len(kept)) == (840, 1)
    assert kept.conditions == full.conditions and kept.source == full.source
    assert label_of(kept, "participant") == "P002"
