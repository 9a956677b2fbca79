"""Population calibration (spec/calibration.md K19-K25, measurement-format MF14).

The studies are generated here, independently of hcard: each participant's recording is the
forward model of thesis Eqs. 2.30 and 2.33 (``Psi = U / (w f mu0 (1 + nu))``,
``F_l = mu0 Fn (1 - exp(-Psi / Psi*))``) evaluated with numpy plus white sensor noise, with
``Psi*`` and ``mu0`` of each participant drawn from a known normal population (Fig. 2.38 shows
two participants' Psi* of 1.89 +- 0.18 and 0.78 +- 0.046: participants differ).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hcard.calibration.measurement import read_measurement
from hcard.calibration.population.grouping import PopulationError, group_recordings
from hcard.calibration.population.population_fit import PopulationResult, fit_population
from hcard.calibration.population.random_effects import dersimonian_laird, random_effects, reml
from hcard.cli.main import cli
from hcard.plugins.registry import get_registry

NU, F_PLATE = 0.33, 27_500.0
PSI_MEAN, PSI_SPREAD = 1.3, 0.2
MU0_MEAN, MU0_SPREAD = 0.5, 0.08
ODD = 3
"""The participant whose friction has a load index n = 0.5 (Eq. 2.35), the others n = 1."""


def write_recording(path: Path, participant: str | None, psi_star: float, mu0: float,
                    noise: float, rng: np.random.Generator, load_index: float = 1.0,
                    strokes: int = 12) -> None:
    """One participant's recording: strokes of 0.4 s at 100 Hz over speeds 20-80 mm/s,
    amplitudes 0-4 um and forces 0.3-1.2 N, lifts of 0.3 s between (forward model in the
    module docstring, noise N(0, noise^2) in N on the lateral force)."""
    speeds, amps, forces = [0.02, 0.04, 0.08], [0.0, 1e-6, 2e-6, 4e-6], [0.3, 0.7, 1.2]
    rows, t = [], 0.0
    for k in range(strokes):
        u = speeds[k % 3] * (1 if k % 2 == 0 else -1)
        w, fn = amps[(k // 3) % 4], forces[(k // 2) % 3]
        psi = abs(u) / (w * F_PLATE * mu0 * (1 + NU)) if w > 0 else math.inf
        force = mu0 * fn * (1 - math.exp(-psi / psi_star)) * fn ** (load_index - 1)
        for _ in range(40):
            rows.append((t, fn, math.copysign(force, u) + rng.normal(0, noise), w, u))
            t += 0.01
        for _ in range(30):
            rows.append((t, 0.0, rng.normal(0, noise), 0.0, 0.0))
            t += 0.01
    lines = ["t_s,fn_n,fl_n,amplitude_m,speed_m_s"]
    lines += [",".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    side: dict[str, object] = {"device": "tribometer", "plate_frequency_hz": F_PLATE}
    if participant is not None:
        side["participant"] = participant
    Path(f"{path}.json").write_text(json.dumps(side))


def make_study(folder: Path, n: int, seed: int) -> np.ndarray:
    """``n`` participants' recordings in ``folder``; returns their true (psi_star, mu0)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    psi = rng.normal(PSI_MEAN, PSI_SPREAD, n)
    mu0 = rng.normal(MU0_MEAN, MU0_SPREAD, n)
    noise = rng.uniform(0.01, 0.05, n)
    for i in range(n):
        write_recording(folder / f"p{i:03d}.csv", f"p{i:03d}", psi[i], mu0[i], noise[i], rng,
                        load_index=0.5 if i == ODD else 1.0)
    return np.stack([psi, mu0])


def run_study(folder: Path) -> PopulationResult:
    registry = get_registry()
    base = registry.get("predictor", "dimensionless-group")
    measurements = [read_measurement(p) for p in sorted(folder.glob("*.csv"))]
    return fit_population(group_recordings(measurements), base,
                          [registry.calibration_effects["load-index"]])


@pytest.fixture(scope="module")
def study100(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, PopulationResult]:
    folder = tmp_path_factory.mktemp("study100")
    truth = make_study(folder, 100, seed=1)
    return truth, run_study(folder)


# -- the random-effects model against hand computations -------------------------------------
Y = [1.0, 1.5, 2.0, 0.8, 1.2]
S = [0.1, 0.2, 0.1, 0.2, 0.1]


def test_dersimonian_laird_matches_a_hand_computation() -> None:
    # w = 100, 25, 100, 25, 100; sum w = 350; mu_FE = 477.5 / 350 = 1.3642857
    # Q = 13.27041 + 0.460459 + 40.41327 + 7.96046 + 2.69898 = 64.80357
    # C = 350 - 31250 / 350 = 260.714286; tau^2 = (64.80357 - 4) / 260.714286 = 0.233219
    # mu = (4.111520 * 4.2 + 3.660068 * 2.3) / (3 * 4.111520 + 2 * 3.660068) = 1.306891
    mu, tau2 = dersimonian_laird(Y, S)
    assert tau2 == pytest.approx(0.233219, rel=1e-5)
    assert mu == pytest.approx(1.306891, rel=1e-5)
    # no spread beyond the errors: Q < k - 1 gives tau^2 = 0 and the fixed-effect mean
    mu0, zero = dersimonian_laird([1.0, 1.05, 0.98], [0.1, 0.1, 0.1])
    assert zero == 0.0
    assert mu0 == pytest.approx((1.0 + 1.05 + 0.98) / 3, rel=1e-12)


def test_reml_is_the_maximum_of_the_restricted_likelihood_on_a_grid() -> None:
    y, v = np.array(Y), np.array(S) ** 2
    grid = np.linspace(0.0, 2.0, 200_001)
    w = 1.0 / (v[None, :] + grid[:, None])
    mu = (w * y).sum(1) / w.sum(1)
    loglik = -0.5 * (np.log(v[None, :] + grid[:, None]).sum(1) + np.log(w.sum(1))
                     + (w * (y - mu[:, None]) ** 2).sum(1))
    assert reml(Y, S) == pytest.approx(grid[np.argmax(loglik)], abs=2e-5)
    pooled = random_effects(Y, S)
    # Knapp-Hartung: mu +- t(4, 0.975) sqrt(max(1, q) / sum w), t(4, 0.975) = 2.776445
    wr = 1.0 / (v + pooled.tau**2)
    q = max(1.0, float(np.sum(wr * (y - pooled.mu) ** 2)) / 4)
    half = 2.776445 * math.sqrt(q / wr.sum())
    assert pooled.mu_interval[0] == pytest.approx(pooled.mu - half, rel=1e-5)
    assert pooled.tau_interval[0] < pooled.tau < pooled.tau_interval[1]
    # shrinkage: B = tau^2 / (tau^2 + s^2) pulls the precise estimates least
    b = pooled.tau**2 / (pooled.tau**2 + v)
    assert pooled.shrunken[1] == pytest.approx(pooled.mu + b[1] * (1.5 - pooled.mu), rel=1e-9)


# -- studies ---------------------------------------------------------------------------------
def test_a_100_participant_study_recovers_the_population(
        study100: tuple[np.ndarray, PopulationResult]) -> None:
    truth, result = study100
    assert len(result.fitted) == 100
    psi, mu0 = result.population["psi_star"], result.population["mu0"]
    # the true population values lie in the reported 95 % intervals
    assert psi.mu_interval[0] < PSI_MEAN < psi.mu_interval[1]
    assert psi.tau_interval[0] < PSI_SPREAD < psi.tau_interval[1]
    assert mu0.mu_interval[0] < MU0_MEAN < mu0.mu_interval[1]
    assert mu0.tau_interval[0] < MU0_SPREAD < mu0.tau_interval[1]
    # and the intervals are sane: a mean to within 0.1 (about 2 tau / sqrt(100)), a spread
    # to within a factor of 1.5
    assert 0.02 < psi.mu_interval[1] - psi.mu_interval[0] < 0.1
    assert psi.tau_interval[1] / psi.tau_interval[0] < 1.5
    assert 0.005 < mu0.mu_interval[1] - mu0.mu_interval[0] < 0.04
    # shrunken estimates are closer to the truth than the participants' own fits
    labels = [p.label for p in result.fitted]
    normal = [i for i, label in enumerate(labels) if label != f"p{ODD:03d}"]
    raw = np.array([result.fitted[i].fit.params["psi_star"] for i in normal])  # type: ignore
    shrunk = np.array(psi.shrunken)[normal]
    raw_error = float(np.mean((raw - truth[0][normal]) ** 2))
    shrunk_error = float(np.mean((shrunk - truth[0][normal]) ** 2))
    assert shrunk_error < raw_error


def test_the_study_flags_the_participant_with_another_effect_and_reports_never_seen_error(
        study100: tuple[np.ndarray, PopulationResult]) -> None:
    _, result = study100
    assert result.effects == ()
    (trial,) = result.trials
    assert trial.effect == "load-index" and not trial.added
    assert trial.own_count == 1
    flagged = {p.label: p.flags for p in result.fitted if p.flags}
    assert flagged == {f"p{ODD:03d}": {"load-index": "needs"}}
    # a participant never seen is predicted worse than with its own fit, but within 2x
    own, never = result.mean_error("held_out_rmse"), result.mean_error("never_seen_rmse")
    assert 0.01 < own < never < 2 * own
    assert all(math.isfinite(p.never_seen_rmse) for p in result.fitted)


def test_the_cli_writes_the_table_the_json_and_the_forest_plot(tmp_path: Path) -> None:
    truth = make_study(tmp_path / "rec", 20, seed=2)
    result = CliRunner().invoke(cli, ["calibrate", "population", str(tmp_path / "rec"),
                                      "-o", str(tmp_path / "out"), "--model",
                                      "dimensionless-group", "--effect", "load-index"])
    assert result.exit_code == 0, result.output
    assert "participant 20/20 p019" in result.stderr
    document = json.loads((tmp_path / "out" / "population.json").read_text())
    assert document["format"] == "hcard-population-report/1"
    psi = document["population"]["psi_star"]
    assert psi["k"] == 20
    assert psi["mu_interval"][0] < psi["mu"] < psi["mu_interval"][1]
    assert abs(psi["mu"] - float(np.mean(truth[0]))) < 0.15
    rows = {p["label"]: p for p in document["participants"]}
    assert rows[f"p{ODD:03d}"]["flags"] == {"load-index": "needs"}
    assert (tmp_path / "out" / "forest.png").stat().st_size > 10_000
    assert "| p019 |" in (tmp_path / "out" / "population.md").read_text()


# -- bad inputs ------------------------------------------------------------------------------
def test_recordings_without_participant_labels_are_named(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    write_recording(tmp_path / "a.csv", "p1", 1.3, 0.5, 0.01, rng)
    write_recording(tmp_path / "b.csv", None, 1.3, 0.5, 0.01, rng)
    result = CliRunner().invoke(cli, ["calibrate", "population", str(tmp_path / "a.csv"),
                                      str(tmp_path / "b.csv"), "-o", str(tmp_path / "out"),
                                      "--model", "dimensionless-group"])
    assert result.exit_code == 1
    assert "1 recording(s) have no participant label" in result.output
    assert "b.csv" in result.output


def test_a_single_participant_is_refused(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for name in ("a", "b"):
        write_recording(tmp_path / f"{name}.csv", "p1", 1.3, 0.5, 0.01, rng)
    with pytest.raises(PopulationError, match="at least 2 participants; the recordings name "
                                              "only 'p1'"):
        group_recordings([read_measurement(tmp_path / f"{n}.csv") for n in ("a", "b")])


def test_a_participant_whose_fit_fails_is_named_and_the_rest_go_on(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for i, psi in enumerate((1.1, 1.3, 1.5)):
        write_recording(tmp_path / f"p{i}.csv", f"p{i}", psi, 0.5, 0.01, rng)
    write_recording(tmp_path / "bad.csv", "lonely", 1.3, 0.5, 0.01, rng, strokes=1)
    result = CliRunner().invoke(cli, ["calibrate", "population", str(tmp_path),
                                      "-o", str(tmp_path / "out"), "--model",
                                      "dimensionless-group", "--effect", "load-index"])
    assert result.exit_code == 0, result.output
    assert "warning: participant lonely left out:" in result.stderr
    document = json.loads((tmp_path / "out" / "population.json").read_text())
    assert [f["label"] for f in document["failed"]] == ["lonely"]
    assert document["population"]["psi_star"]["k"] == 3
