"""Electrovibration charge-leakage model (Eqs. 3.19-3.23) in the time domain: speed.

Run: ``python bench/bench_ev_leakage.py [--seconds 10] [--rate 10000] [--repeat 5]``

Simulates an EV drive of ``--seconds`` s sampled at ``--rate`` Hz: a 440 Hz carrier of 1000 V
amplitude under a 3 Hz raised-cosine envelope, through :meth:`ChargeLeakage.simulate` (effective
voltage and force), for a constant ``tau_d`` (``tau_d_exponent = 0``), the default power law
``tau_d(f)`` (Figs. 3.13, 3.16) and the same law as an explicit curve (both add the
dominant-frequency search). Prints the best wall time of ``--repeat`` runs and
its ratio to real time. Single thread (OMP/OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from hcard_builtins.physics.electrovibration import FIG_3_13_TREND, ChargeLeakage

CARRIER_HZ = 440.0
ENVELOPE_HZ = 3.0
AMPLITUDE_V = 1000.0


def drive(seconds: float, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample times (s) and voltage (V): the enveloped carrier."""
    t = np.arange(round(seconds * rate)) / rate
    envelope = 0.5 * (1.0 - np.cos(2 * math.pi * ENVELOPE_HZ * t))
    return t, AMPLITUDE_V * envelope * np.sin(2 * math.pi * CARRIER_HZ * t)


def best_time(model: ChargeLeakage, t: np.ndarray, v: np.ndarray, repeat: int) -> float:
    """Best wall time in s of ``repeat`` calls of ``model.simulate(t, v)``."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        model.simulate(t, v)
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="signal length, s")
    parser.add_argument("--rate", type=float, default=10_000.0, help="sampling rate, Hz")
    parser.add_argument("--repeat", type=int, default=5, help="runs; the best is reported")
    args = parser.parse_args()

    t, v = drive(args.seconds, args.rate)
    print(
        f"signal: {args.seconds:g} s at {args.rate:g} Hz ({t.size} samples), "
        f"{CARRIER_HZ:g} Hz carrier, {ENVELOPE_HZ:g} Hz envelope, {AMPLITUDE_V:g} V"
    )
    for label, model in (
        ("constant tau_d = 7.7 ms", ChargeLeakage(tau_d_exponent=0.0)),
        ("default tau_d(f) law", ChargeLeakage()),
        ("Fig. 3.13 tau_d(f) curve", ChargeLeakage(tau_d_curve=FIG_3_13_TREND)),
    ):
        result = model.simulate(t, v)
        elapsed = best_time(model, t, v, args.repeat)
        print(
            f"{label:26s}: {elapsed * 1e3:8.2f} ms, {args.seconds / elapsed:10.0f} x real time; "
            f"tau_d used {result.tau_d * 1e3:.3f} ms, peak force {result.force.max() * 1e3:.2f} mN"
        )


if __name__ == "__main__":
    main()
