"""Benchmark: end-to-end latency of the reference device, per tier, and the cost of Nagle.

Run from the repository root::

    python bench/bench_device_latency.py [--trials 50]

Latency is measured from a host finger update to the friction change visible in the STATE input
reports. The card is 20 x 10 mm: plain glass (relative friction 1) on the left 10 mm, a UV
friction reduction to 0.4 on the right. Each trial holds the host finger still on one side,
then moves it to the other (sent twice, so the renderer sees no velocity) and times:

* ``applied``: until the first report echoing the new finger report's host time;
* ``target``: until the first report whose target friction is the new side's (1.0 or 0.4);
* ``plate``: (moves onto the 0.4 side) until the measured plate amplitude reaches half of its
  settled value for that target.

Tiers: ``sim://`` (in-process, on the simulation's clock: device time, 0.1 ms resolution; the
wall time the CPU needed is shown too), ``usbip://loopback`` (the device in this process on a
socket pair), and USB/IP over TCP on 127.0.0.1 to a device in a separate process
(``python -m hcard_device.usb.server``) with the usbip and the pyusb drivers (wall clock).
``wall/trial`` is the wall time from the move to the change (for ``sim://``: the CPU time to
simulate it in 0.1 ms steps).

The second table is the cost of one interrupt OUT transfer and one GET_REPORT with the stock
``usbip.host`` client (which writes a URB header and its payload separately) with and without
``TCP_NODELAY`` on the client and on the server.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import select
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from usbip import host as usbip_host

from hcard import build
from hcard.device import Driver, open_device
from hcard.device.protocol import Finger, ReportId, State
from hcard.device.protocol.usb_ids import OUT_ENDPOINT
from hcard_device.usb.server import SWITCH_INTERVAL_S, DeviceServer
from hcard_device.usb.transport import NoDelayUSBIP

LEFT_MM, RIGHT_MM = 5.0, 15.0
TARGETS = {LEFT_MM: 1.0, RIGHT_MM: 0.4}
HOLD_S = 0.03
"""Time the finger stays on one side before the next move, s."""
TRIAL_TIMEOUT_S = 0.5
"""A change not seen within this long counts as a failure, s."""


def step_card():
    """Plain glass on the left 10 mm, UV friction reduction to 0.4 on the right."""
    return build.card(
        20.0, 10.0, taxtel_mm=10.0,
        textures=[build.texture(1.0, channel="uv", name="plain"),
                  build.texture(0.4, channel="uv", name="slippery")],
        texture_index=[0, 1], title="latency step",
    )


@dataclass
class Latencies:
    """Latencies of one tier, s."""

    applied: list[float] = field(default_factory=list)
    target: list[float] = field(default_factory=list)
    plate: list[float] = field(default_factory=list)
    wall: list[float] = field(default_factory=list)
    failures: int = 0


def _send_still(driver: Driver, x_mm: float) -> int:
    """Send the finger at ``x_mm`` twice (zero velocity); returns the host time, us."""
    t = driver.clock()
    driver.send_finger(t, x_mm, 5.0, 0.5, True)
    driver.send_finger(t, x_mm, 5.0, 0.5, True)
    return round(t * 1e6) % (1 << 32)


def _hold(driver: Driver, x_mm: float, seconds: float) -> list[State]:
    states: list[State] = []
    end = driver.clock() + seconds
    while driver.clock() < end:
        _send_still(driver, x_mm)
        states += driver.collect_until(min(driver.clock() + 0.01, end))
    return states


def run_trials(driver: Driver, trials: int, step_s: float | None) -> Latencies:
    """Move the finger ``trials`` times; ``step_s``: advance the driver's clock by this much
    between polls (sim://), else poll the device on the wall clock."""
    out = Latencies()
    driver.upload_card(step_card())
    driver.set_touch_source(host=True)
    driver.start()
    x = LEFT_MM
    _hold(driver, x, 0.05)
    for _ in range(trials):
        x = RIGHT_MM if x == LEFT_MM else LEFT_MM
        wall0 = time.perf_counter()
        t0 = driver.clock()
        echo = _send_still(driver, x)
        seen: list[tuple[float, State]] = []
        applied = target = None
        while target is None and driver.clock() - t0 < TRIAL_TIMEOUT_S:
            if step_s is not None:
                states = driver.collect_until(driver.clock() + step_s)
            else:
                states = driver.read_inputs(0.01)
            now = driver.clock()
            for state in states:
                seen.append((now - t0, state))
                if applied is None and state.host_time_echo_us == echo:
                    applied = now - t0
                if target is None and abs(state.target_uv - TARGETS[x]) < 1e-3:
                    target = now - t0
        out.wall.append(time.perf_counter() - wall0)
        if applied is None or target is None:
            out.failures += 1
            continue
        out.applied.append(applied)
        out.target.append(target)
        held = _hold(driver, x, HOLD_S)
        if x == RIGHT_MM and held:
            settled = float(np.mean([s.amplitude_nm for s in held[-10:]]))
            # the plate rises over the reports that follow the move
            rise = seen + [(driver.clock() - t0, s) for s in held]
            half = next((t for t, s in rise if s.amplitude_nm >= settled / 2), None)
            if half is not None and settled > 10:
                out.plate.append(half)
    driver.stop()
    return out


@contextlib.contextmanager
def device_process() -> Iterator[str]:
    """``python -m hcard_device.usb.server --port 0`` in a separate process; yields its URI."""
    process = subprocess.Popen(
        [sys.executable, "-m", "hcard_device.usb.server", "--port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        data, deadline = b"", time.monotonic() + 30
        while b"\n" not in data and time.monotonic() < deadline:
            ready, _, _ = select.select([process.stdout], [], [], 0.5)
            if ready:
                chunk = os.read(process.stdout.fileno(), 4096)
                if not chunk:
                    break
                data += chunk
        match = re.search(rb"at (usbip://\S+)", data)
        if not match:
            raise RuntimeError(f"the device server did not start: {data!r}")
        yield match[1].decode()
    finally:
        process.kill()
        process.wait(5)


def _stats(values: list[float]) -> str:
    if not values:
        return f"{'-':>8s} {'-':>8s}"
    ms = np.array(values) * 1e3
    return f"{np.median(ms):8.2f} {np.percentile(ms, 95):8.2f}"


def latency_table(trials: int) -> None:
    """Print median and p95 latency per tier."""
    print(f"latency from a host finger update, ms ({trials} trials per tier)")
    print(f"{'tier':38s} {'applied':>17s} {'target':>17s} {'plate (UV on)':>17s} "
          f"{'wall/trial':>10s}")
    print(f"{'':38s} " + " ".join(f"{'median':>8s} {'p95':>8s}" for _ in range(3)))
    tiers: list[tuple[str, Callable[[], contextlib.AbstractContextManager[str]], float | None]]
    tiers = [
        ("in-process sim:// (device time)", lambda: contextlib.nullcontext("sim://"), 1e-4),
        ("usbip://loopback (socket pair)", lambda: contextlib.nullcontext("usbip://loopback"),
         None),
    ]
    with device_process() as uri:
        tiers += [
            ("USB/IP TCP 127.0.0.1, usbip driver", lambda: contextlib.nullcontext(uri), None),
            ("USB/IP TCP 127.0.0.1, pyusb driver",
             lambda: contextlib.nullcontext(uri.replace("usbip://", "pyusb://")), None),
        ]
        for name, source, step in tiers:
            with source() as device_uri, open_device(device_uri) as driver:
                result = run_trials(driver, trials, step)
            failed = f"  ({result.failures} failed)" if result.failures else ""
            print(f"{name:38s} {_stats(result.applied)} {_stats(result.target)} "
                  f"{_stats(result.plate)} {statistics.median(result.wall) * 1e3:10.2f}{failed}")


def transfer_costs(server: DeviceServer, client_nodelay: bool, count: int) -> tuple[float, float]:
    """Median interrupt OUT and GET_REPORT(Feature) cost with the stock client, ms."""
    handle = usbip_host.open(busid="1-1", transport=NoDelayUSBIP(
        "127.0.0.1", server.port, nodelay=client_nodelay))
    try:
        report = Finger.from_si(0.0, 5.0, 5.0, 0.5, True).encode()
        outs, gets = [], []
        for _ in range(count):
            t0 = time.perf_counter()
            handle.interrupt_out(OUT_ENDPOINT, report)
            t1 = time.perf_counter()
            handle.control(0xA1, 0x01, 0x0300 | ReportId.DEVICE_INFO, 0, 64)
            t2 = time.perf_counter()
            outs.append(t1 - t0)
            gets.append(t2 - t1)
        return statistics.median(outs) * 1e3, statistics.median(gets) * 1e3
    finally:
        handle.close()


def nodelay_table(count: int) -> None:
    """Print the OUT / GET_REPORT cost for each TCP_NODELAY combination."""
    print(f"\nUSB/IP transfer cost on 127.0.0.1, stock usbip.host client, median of {count}, ms")
    print(f"{'server NODELAY':>14s} {'client NODELAY':>14s} {'OUT transfer':>13s} "
          f"{'GET_REPORT':>11s}")
    for server_nodelay in (True, False):
        with DeviceServer(port=0, nodelay=server_nodelay) as server:
            for client_nodelay in (True, False):
                out_ms, get_ms = transfer_costs(server, client_nodelay, count)
                print(f"{server_nodelay!s:>14s} {client_nodelay!s:>14s} {out_ms:13.2f} "
                      f"{get_ms:11.2f}")


def main(argv: list[str] | None = None) -> int:
    """Run both tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=50, help="finger moves per tier")
    parser.add_argument("--transfers", type=int, default=20,
                        help="transfers per NODELAY combination")
    args = parser.parse_args(argv)
    # As the server process does: the usbip://loopback tier serves the device in this process,
    # and Python's default 5 ms GIL switch interval would hold its USB threads off.
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    latency_table(args.trials)
    nodelay_table(args.transfers)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
