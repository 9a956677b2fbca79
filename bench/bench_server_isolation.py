"""Benchmark: how isolated each client of a served device is (spec/device-protocol.md rules
PN15, PU12; the bounds and the guaranteed share are in its section 13).

Run from the repository root::

    python bench/bench_server_isolation.py [--seconds 5] [--no-commit]

Serves an E-ViTa in another process (``python -m hcard_device.usb.server`` on 127.0.0.1) and
measures, with the clients of ``conformance/hcard_conformance/usbip_clients.py``:

* **delivery**: the share of the 1000 STATE reports a second the device produces that a
  well-behaved client (the hcard driver's link, 4 IN URBs outstanding) receives, alone and then
  beside each kind of misbehaving client (each in a process of its own, started once the
  well-behaved one holds its connection, given 2 s to take effect): a client that parks URBs
  and stops reading its socket, a parked-URB flood, a 2 GiB OUT URB fed as fast as the socket
  takes it, an OUT-report flood, 300 idle importers. Each row measures "alone" again just
  before, and prints the share, the goal (0.9 of alone) and the ratio to alone;
* **commit**: the largest gap between STATE reports at an observing client while another
  connection COMMITs a 2 MiB JSON card of ~699 000 empty components (invalid) and the largest
  valid binary card (1.3 MB), against the same measurement without a commit: wall-clock
  arrival gap (ms, ratio to the one without) and device-time step (us; the goal is 2 report
  periods, 2000 us: no report lost);
* **memory**: the server's resident memory before and at its peak during each flood (the goal:
  under 16 MiB of growth).
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the repository's root: the clients and cards of the tests

from hcard.card_io import to_bytes  # noqa: E402
from hcard.device.protocol.constants import DEFAULT_MAX_CARD_BYTES  # noqa: E402
from hcard_conformance import usbip_clients as clients  # noqa: E402
from tests.helpers.cards import large_valid_card  # noqa: E402
from tests.helpers.hostile_cards import json_empty_components  # noqa: E402
from tests.helpers.served_device import served_device  # noqa: E402

SHARE_GOAL = 0.9
"""A well-behaved client keeps at least this share of what it receives alone (section 13)."""
STEP_GOAL_US = 2000
"""Largest device-time step between two STATE reports received during a commit, us."""
RSS_GOAL_MIB = 16.0
"""Most the server's resident memory may grow during a flood, MiB."""


def rss_mib(pid: int) -> float:
    """Resident memory of process ``pid``, MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class PeakRss:
    """The peak resident memory of a process, sampled every 50 ms on a thread."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.peak = rss_mib(pid)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> PeakRss:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            self.peak = max(self.peak, rss_mib(self.pid))


def delivery_rows(host: str, port: int, pid: int, seconds: float) -> None:
    """The delivery and memory table."""
    print(f"{'well-behaved client beside':28s} {'alone':>7s} {'beside':>7s} {'goal':>7s} "
          f"{'ratio':>6s} {'lost':>6s} {'gap ms':>7s} {'RSS MiB':>8s} {'peak':>7s} "
          f"{'goal':>7s}")
    alone = clients.measure_delivery(host, port, seconds)
    print(f"{'(nothing)':28s} {alone.fraction:7.3f} {alone.fraction:7.3f} "
          f"{'':>7s} {1.0:6.3f} {alone.lost:6d} {alone.max_arrival_gap_ms:7.1f}")
    for kind in sorted(clients.HOSTILE_KINDS):
        alone = clients.measure_delivery(host, port, seconds)
        before = rss_mib(pid)

        def beside(kind: str = kind) -> object:
            return clients.hostile_process(kind, host, port)

        with PeakRss(pid) as rss:
            near = clients.measure_delivery(host, port, seconds, beside_settle_s=2.0,
                                            beside=beside)  # type: ignore[arg-type]
        goal = SHARE_GOAL * alone.fraction
        print(f"{kind:28s} {alone.fraction:7.3f} {near.fraction:7.3f} {goal:7.3f} "
              f"{near.fraction / alone.fraction:6.3f} {near.lost:6d} "
              f"{near.max_arrival_gap_ms:7.1f} {before:8.1f} {rss.peak:7.1f} "
              f"{before + RSS_GOAL_MIB:7.1f}")


def commit_rows(host: str, port: int, pid: int) -> None:
    """The commit table."""
    print()
    print(f"{'2 MiB-class commit':28s} {'result':>8s} {'took s':>7s} {'gap ms':>7s} "
          f"{'without':>8s} {'ratio':>6s} {'step us':>8s} {'goal':>6s} {'lost':>5s} "
          f"{'RSS peak':>9s}")
    cards: list[tuple[str, Callable[[], bytes]]] = [
        ("JSON, 699k empty components",
         lambda: json_empty_components(size=DEFAULT_MAX_CARD_BYTES)),
        ("binary, largest valid", lambda: to_bytes(large_valid_card())),
    ]
    for name, make in cards:
        data = make()
        with PeakRss(pid) as rss:
            outcome = clients.measure_commit(host, port, data, real_time=True)
        during, without = outcome.during, outcome.baseline
        result = "COMMITTED" if outcome.status.state == 2 else f"FAILED/{outcome.status.result}"
        print(f"{name:28s} {result:>8s} {outcome.commit_s:7.2f} "
              f"{during.max_arrival_gap_ms:7.1f} {without.max_arrival_gap_ms:8.1f} "
              f"{during.max_arrival_gap_ms / without.max_arrival_gap_ms:6.2f} "
              f"{during.max_stamp_gap_us:8d} {STEP_GOAL_US:6d} {during.lost:5d} "
              f"{rss.peak:9.1f}")
    print("observer read at the device's SCHED_RR priority: "
          f"{'yes' if outcome.during.real_time else 'no (not permitted)'}")


def main(argv: list[str] | None = None) -> int:
    """Print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0,
                        help="length of each delivery measurement, s")
    parser.add_argument("--no-commit", action="store_true", help="skip the commit table")
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    with served_device() as served:
        pid = served.process.pid
        print(f"server: {served.banner.split(' (')[0]}, pid {pid}, RSS {rss_mib(pid):.1f} MiB")
        delivery_rows(served.host, served.port, pid, args.seconds)
        if not args.no_commit:
            commit_rows(served.host, served.port, pid)
    print(f"\n(bench took {time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
