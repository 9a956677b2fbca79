"""Benchmark: does a served device keep its stream queue fed, and whose fault is it when not?

Run from the repository root::

    python bench/bench_stream_feed.py [--device evita|coupled] [--repeat 2]

Serves the device in another process (``hcard device serve``, SCHED_RR where permitted) and
streams, as the conformance suite's ``device.dynamics`` does (:func:`hcard_conformance.streaming.
stream`), a 0.7 s UV sine at 25, 110 and 350 Hz, ``--repeat`` times, while a
:class:`~hcard_conformance.realtime.HostWatch` times the host process. Prints per stream: the
reports with an empty queue (underruns) of all reports, the host's longest stall, and the
reports the device flagged REALTIME_LAG (rule PI4). Underruns with a host that never stalled for
the lead (100 ms) and with REALTIME_LAG reports mean the device fell behind its clock and
caught up, not that the host left the queue empty.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the root: tests.helpers

from hcard.device import open_device
from hcard.device.protocol import FaultBits
from hcard_conformance.realtime import HostWatch
from hcard_conformance.streaming import stream
from tests.helpers.served_device import served_device

FREQUENCIES_HZ = (25.0, 110.0, 350.0)
"""Sine frequencies streamed, Hz (points of the conformance suite's bandwidth sweep)."""
STREAM_S = 0.7
"""Length of each streamed sine, s."""


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", choices=("evita", "coupled"), default="evita")
    parser.add_argument("--repeat", type=int, default=2, help="rounds of the three sines")
    args = parser.parse_args(argv)
    print(f"{'sine':>9s} {'underruns':>15s} {'host stall ms':>14s} {'REALTIME_LAG':>13s} "
          f"{'took s':>7s}")
    with served_device(args.device) as served:
        for _ in range(args.repeat):
            for frequency in FREQUENCIES_HZ:
                with open_device(served.uri) as driver:
                    rate = float(driver.info().frame_rate_hz)
                    t = np.arange(int(STREAM_S * rate)) / rate
                    uv = 0.6 + 0.3 * np.sin(2 * np.pi * frequency * t)
                    with HostWatch() as watch:
                        start = time.monotonic()
                        session = stream(driver, uv)
                        took = time.monotonic() - start
                late = sum(1 for s in session.states if s.faults & FaultBits.REALTIME_LAG)
                print(f"{frequency:6.0f} Hz {session.underruns:6d} of {len(session.states):5d} "
                      f"{watch.longest_s * 1e3:14.1f} {late:13d} {took:7.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
