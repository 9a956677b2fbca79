"""Population fits on Dask (spec/calibration.md K26): the same result in this process and on a
local cluster, a participant whose task fails named and the others pooled, retries, and the
command line on a cluster given by its scheduler's address. Studies from
hcard.calibration.population.synthetic (independent of the fitting code)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from hcard.calibration.population.population_fit import PopulationResult, fit_population
from hcard.calibration.population.synthetic import make_study
from hcard.cli.main import cli
from hcard.executor import Executor, ExecutorOptions
from hcard.plugins.registry import get_registry


def _study(folder: Path, n: int) -> dict[str, list[str]]:
    make_study(folder, n, seed=7)
    return {p.stem: [str(p)] for p in sorted(folder.glob("*.csv"))}


def _fit(groups: dict[str, list[str]], executor: Executor) -> PopulationResult:
    registry = get_registry()
    return fit_population(groups, registry.get("predictor", "dimensionless-group"),
                          [registry.calibration_effects["load-index"]], executor=executor)


def _numbers(result: PopulationResult) -> dict[str, object]:
    """Every number of a result, for an exact comparison."""
    return {
        "effects": result.effects,
        "population": {name: (pop.mu, pop.tau, pop.mu_interval, pop.tau_interval,
                              tuple(pop.shrunken))
                       for name, pop in result.population.items()},
        "participants": [(p.label, p.error, p.held_out_rmse, p.never_seen_rmse,
                          dict(p.fit.params) if p.fit else None,
                          dict(p.fit.uncertainties) if p.fit else None, dict(p.flags))
                         for p in result.participants],
        "trials": [(t.effect, t.round, t.criterion_change, t.own, t.added)
                   for t in result.trials],
    }


def test_a_two_worker_local_cluster_gives_the_in_process_result_to_the_last_bit(
        tmp_path: Path) -> None:
    groups = _study(tmp_path / "study", 6)
    with Executor(ExecutorOptions(workers=0)) as here:
        alone = _fit(groups, here)
    with Executor(ExecutorOptions(workers=2)) as cluster:  # 2 worker processes
        spread = _fit(groups, cluster)
    assert len(alone.fitted) == 6
    # load-index was tried on every participant (a round of tasks), and earns its place for
    # p003 alone (n = 0.5): not added, p003 flagged
    assert [(t.effect, len(t.own), t.added) for t in alone.trials] == [("load-index", 6, False)]
    assert {p.label: p.flags for p in alone.fitted}["p003"] == {"load-index": "needs"}
    assert _numbers(spread) == _numbers(alone)  # floats compared with ==, not a tolerance


def test_a_corrupt_recording_is_named_and_the_others_are_pooled(tmp_path: Path) -> None:
    groups = _study(tmp_path / "study", 5)
    Path(groups["p002"][0]).write_text("t_s,fn_n,fl_n\n0.0,not a number,1\n")
    lines: list[str] = []
    with Executor(ExecutorOptions(workers=2, processes=False)) as cluster:
        result = fit_population(
            groups, get_registry().get("predictor", "dimensionless-group"), executor=cluster,
            progress=lines.append)
    assert [p.label for p in result.failed] == ["p002"]
    assert "p002.csv" in result.failed[0].error
    assert [p.label for p in result.fitted] == ["p000", "p001", "p003", "p004"]
    assert result.population["psi_star"].k == 4
    assert any(line.startswith("participant 3/5 p002: fit failed") for line in lines)
    assert sum(line.startswith("task ") for line in lines) == 5 + 4  # first fits, never seen


def fail_once(marker: str) -> str:
    """Fails the first time it is called with ``marker`` (a file it then creates)."""
    path = Path(marker)
    if not path.exists():
        path.write_text("")
        raise OSError("the first attempt fails")
    return path.name


def always_fails(count_file: str) -> str:
    """Fails every time, counting its attempts in ``count_file``."""
    with open(count_file, "a") as file:
        file.write("x")
    raise ValueError(f"no good: {Path(count_file).name}")


@pytest.mark.parametrize("options", [ExecutorOptions(workers=0),
                                     ExecutorOptions(workers=1, processes=False)],
                         ids=["in-process", "cluster"])
def test_a_task_that_fails_once_is_retried_and_one_that_always_fails_is_named(
        tmp_path: Path, options: ExecutorOptions) -> None:
    lines: list[str] = []
    with Executor(options) as executor:
        good = list(executor.map(fail_once, [("a", str(tmp_path / "a")),
                                             ("b", str(tmp_path / "b"))], lines.append))
        bad = list(executor.map(always_fails, [("c", str(tmp_path / "c.count"))]))
    assert sorted((o.key, o.value, o.error) for o in good) == [("a", "a", ""), ("b", "b", "")]
    assert sorted(line.split(" ", 2)[2] for line in lines) == ["a: done", "b: done"]
    if options.in_process:
        assert [o.attempts for o in good] == [2, 2]
    assert [(o.key, o.error) for o in bad] == [("c", "ValueError: no good: c.count")]
    assert (tmp_path / "c.count").read_text() == "xxx"  # 1 run + 2 retries


def test_items_are_sent_in_batches_and_a_failure_stays_its_items_own(tmp_path: Path) -> None:
    """A cluster gets about 4 batches per worker thread (a task costs the scheduler a few ms,
    a participant's fit ~20 ms): 9 items on one thread go as 3 batches of 3, and the one item
    that always fails is named, after 1 + 2 attempts, while the 8 others, its batch's two
    included, are done."""
    from hcard.executor import batch_size

    assert [batch_size(n, threads) for n, threads in ((9, 1), (100, 2), (3, 4), (1, 1))] == [
        3, 13, 1, 1]
    items = [(f"i{n}", str(tmp_path / f"i{n}")) for n in range(9)]
    items[4] = ("bad", str(tmp_path / "bad.count"))
    lines: list[str] = []
    with Executor(ExecutorOptions(workers=1, processes=False)) as cluster:
        outcomes = list(cluster.map(_fail_once_or_always, items, lines.append))
    assert sorted(o.key for o in outcomes if o.ok) == sorted(
        key for key, _ in items if key != "bad")
    assert [(o.key, o.error, o.attempts) for o in outcomes if not o.ok] == [
        ("bad", "ValueError: no good: bad.count", 3)]
    assert (tmp_path / "bad.count").read_text() == "xxx"
    assert len(lines) == 9


def _fail_once_or_always(path: str) -> str:
    return always_fails(path) if path.endswith(".count") else fail_once(path)


def test_the_command_runs_on_the_cluster_at_the_address_given(tmp_path: Path) -> None:
    from dask.distributed import LocalCluster

    make_study(tmp_path / "study", 4, seed=3)
    runner = CliRunner()
    arguments = ["calibrate", "population", str(tmp_path / "study"), "-m",
                 "dimensionless-group", "--effect", "load-index", "--no-figures", "--json"]
    here = runner.invoke(cli, [*arguments, "-o", str(tmp_path / "here"), "--workers", "0"])
    assert here.exit_code == 0, here.output
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        there = runner.invoke(cli, [*arguments, "-o", str(tmp_path / "there"), "--scheduler",
                                    cluster.scheduler_address])
    assert there.exit_code == 0, there.output
    assert f"on the Dask scheduler at {cluster.scheduler_address}" in there.stderr
    # tasks finish in any order: each participant's first fit is one "task N/4 KEY: done"
    done = re.findall(r"task [1-4]/4 (p00[0-3]): done", there.stderr)
    assert set(done) == {"p000", "p001", "p002", "p003"}
    document, expected = json.loads(there.stdout), json.loads(here.stdout)
    document.pop("elapsed_s", None), expected.pop("elapsed_s", None)
    assert document["population"] == expected["population"]
    assert document["participants"] == expected["participants"]
