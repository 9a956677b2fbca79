"""Population fit on Dask: speed-up with 1, 2 and 4 local workers, a 100-participant study's
wall time, and each worker's peak memory (dask's per-worker memory after the fit).

    python bench/bench_dask_population.py [N_PARTICIPANTS]

Measured on the 2-core build machine, idle, 100 participants (items sent in batches, about 4
per worker thread): in process 3.1 s; 1 worker 0.74x (the scheduler's and the transfers' cost
with no second core to gain), 2 workers 1.33x, 4 workers 1.17x (two cores); each worker
~134 MiB. Without batches (a task per participant) 2 workers gave 0.82x.
Studies from hcard.calibration.population.synthetic (independent of the fitting code).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from hcard.calibration.population.population_fit import fit_population
from hcard.calibration.population.synthetic import make_study
from hcard.executor import Executor, ExecutorOptions
from hcard.plugins.registry import get_registry


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    registry = get_registry()
    base = registry.get("predictor", "dimensionless-group")
    library = [registry.calibration_effects["load-index"]]
    with tempfile.TemporaryDirectory() as folder:
        make_study(Path(folder), n, seed=1)
        groups = {p.stem: [str(p)] for p in sorted(Path(folder).glob("*.csv"))}
        times: dict[int, float] = {}
        for workers in (0, 1, 2, 4):
            with Executor(ExecutorOptions(workers=workers)) as executor:
                started = time.perf_counter()
                fit_population(groups, base, library, executor=executor)
                times[workers] = time.perf_counter() - started
                memory = ""
                if executor._client is not None:
                    info = executor._client.scheduler_info()["workers"]
                    memory = ", worker memory " + ", ".join(
                        f"{w['metrics']['memory'] / 2**20:.0f} MiB" for w in info.values())
            label = "in process" if workers == 0 else f"{workers} worker(s)"
            print(f"{n} participants, {label}: {times[workers]:.1f} s "
                  f"(speed-up {times[0] / times[workers]:.2f}x){memory}")


if __name__ == "__main__":
    main()
