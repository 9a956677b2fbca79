"""Reading a large measurement CSV against ``numpy.loadtxt`` on the same file, in one run.

Run: ``python bench/bench_csv_read.py [--rows 1000000] [--repeat 3]``

Writes a measurement of ``--rows`` rows (t_s, amplitude_um, fn_n, fl_n, as a tribometer writes
them) and times, each in a fresh process (median of ``--repeat``): ``numpy.loadtxt`` of the
body (the baseline), ``read_measurement`` (hcard's fast path), and ``read_measurement`` of the
same file with one comment line in the body, which sends it down the row-by-row reader (the
fallback). Prints wall time, peak memory (max RSS) and each one's ratio to the baseline.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

MEASURE = (
    "import json, resource, sys, time\n"
    "t = time.perf_counter()\n"
    "{body}\n"
    "print(json.dumps({{'s': time.perf_counter() - t,\n"
    "                  'kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}}))\n"
)
LOADTXT = ("import numpy as np\n"
           "np.loadtxt(sys.argv[1], delimiter=',', skiprows=1, dtype=np.float64, ndmin=2)")
READ = ("from hcard.calibration.measurement import read_measurement\n"
        "read_measurement(sys.argv[1])")


def write_measurement_csv(path: Path, rows: int, comment: bool) -> None:
    """A measurement CSV and its sidecar; ``comment`` puts a comment line mid-body."""
    rng = np.random.default_rng(0)
    t = np.arange(rows) * 1e-3
    table = np.column_stack([t, 1 + 0.5 * np.sin(t), 0.5 + 0.01 * rng.standard_normal(rows),
                             0.2 + 0.01 * rng.standard_normal(rows)])
    with path.open("w") as out:
        out.write("t_s,amplitude_um,fn_n,fl_n\n")
        half = rows // 2
        np.savetxt(out, table[:half], delimiter=",", fmt="%.9g")
        if comment:
            out.write("# the finger lifted here\n")
        np.savetxt(out, table[half:], delimiter=",", fmt="%.9g")
    path.with_name(path.name + ".json").write_text(json.dumps({"device": "bench"}))


def measured(body: str, path: Path, repeat: int) -> tuple[float, float]:
    """Median wall time (s) and peak memory (MB) of ``body`` on ``path``."""
    runs = []
    for _ in range(repeat):
        done = subprocess.run([sys.executable, "-c", MEASURE.format(body=body), str(path)],
                              capture_output=True, text=True, check=True)
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return (statistics.median(r["s"] for r in runs),
            statistics.median(r["kb"] for r in runs) / 1024)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        plain, commented = Path(tmp) / "rec.csv", Path(tmp) / "commented.csv"
        write_measurement_csv(plain, args.rows, comment=False)
        write_measurement_csv(commented, args.rows, comment=True)
        size_mb = plain.stat().st_size / 1e6
        print(f"{args.rows} rows, {size_mb:.1f} MB; median of {args.repeat} fresh processes")
        base_s, base_mb = measured(LOADTXT, plain, args.repeat)
        print(f"  numpy.loadtxt (baseline)     {base_s:6.2f} s  {base_mb:7.0f} MB")
        for label, path in (("read_measurement, fast path", plain),
                            ("read_measurement, fallback", commented)):
            seconds, mb = measured(READ, path, args.repeat)
            print(f"  {label:28s} {seconds:6.2f} s  {mb:7.0f} MB   x{seconds / base_s:.2f} "
                  f"time, x{mb / base_mb:.2f} memory of the baseline")


if __name__ == "__main__":
    main()
