"""The whole calibration loop through the reference device: protocol, calibrate, verify.

Run: ``python bench/bench_loop.py [--device sim|usbip] [--duration 60s] [--effect air-layer]``

Plays the EV protocol of ``hcard calibrate plan`` (default 60 s) on the coupled stimulator with an
effect hidden in its hardware (default the air layer, d_a1 = 10 um), calibrates the recording
with every installed calibration effect as a candidate, and plays the held-out verification
card without and with the fitted profile. ``--device sim`` runs the device in this process on
its own clock (as fast as the CPU allows); ``--device usbip`` serves it from another process in
real time (``hcard device serve``) and talks USB/IP to it. ``--effect none`` hides nothing.

Prints the time of each stage, the ratio of the played device time to the wall time, what the
loop found, the held-out model error and the rendered friction error before and after.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from click.testing import CliRunner

from hcard.calibration.measurement import read_measurement
from hcard.cli.main import cli

READY = re.compile(r"at (usbip://\S+)")


def invoke(*args: object) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    if result.exit_code != 0:
        raise SystemExit(f"hcard {' '.join(map(str, args))} failed:\n{result.output}")
    return result.output


def serve(effect: str) -> tuple[subprocess.Popen[bytes], str]:
    """``hcard device serve`` in another process; its URI."""
    extra = [] if effect == "none" else ["--effect", effect]
    process = subprocess.Popen(
        [sys.executable, "-c", "from hcard.cli.main import cli; cli()", "device", "serve",
         "--device", "coupled", "--port", "0", *extra], stdout=subprocess.PIPE)
    assert process.stdout is not None
    line = process.stdout.readline().decode()
    match = READY.search(line)
    if not match:
        process.kill()
        raise SystemExit(f"the server did not start: {line!r}")
    return process, match[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", choices=("sim", "usbip"), default="sim")
    parser.add_argument("--duration", default="60s", help="length of the protocol")
    parser.add_argument("--effect", default="air-layer", help="hidden effect, or none")
    args = parser.parse_args()
    server = None
    if args.device == "usbip":
        server, uri = serve(args.effect)
    else:
        uri = "sim://coupled?seed=1" + ("" if args.effect == "none" else
                                        f"&effect={args.effect}")
    try:
        with tempfile.TemporaryDirectory() as folder:
            work = Path(folder)
            timings: dict[str, float] = {}
            tic = time.perf_counter()
            invoke("calibrate", "plan", "--device", "ev", "--duration", args.duration, "-o",
                   work / "plan")
            timings["plan"] = time.perf_counter() - tic
            tic = time.perf_counter()
            invoke("play", work / "plan" / "protocol.hcard", "--track",
                   work / "plan" / "protocol.csv", "--device", uri, "-o", work / "rec.csv")
            timings["play protocol"] = time.perf_counter() - tic
            played_s = float(read_measurement(work / "rec.csv").t[-1])
            tic = time.perf_counter()
            invoke("calibrate", work / "rec.csv", "-o", work / "calib", "-q", "--no-figures")
            timings["calibrate"] = time.perf_counter() - tic
            tic = time.perf_counter()
            invoke("calibrate", work / "rec.csv", "-o", work / "verified", "-q", "--no-figures",
                   "--verify", uri)
            timings["calibrate + verify"] = time.perf_counter() - tic
            report = json.loads((work / "verified" / "report.json").read_text())
    finally:
        if server is not None:
            server.terminate()
            server.wait(10)
    print(f"device {uri.split('?')[0]} ({args.device}), hidden effect: {args.effect}; "
          f"protocol {args.duration}")
    for stage, seconds in timings.items():
        print(f"  {stage:20s} {seconds:7.1f} s")
    verify_s = timings["calibrate + verify"] - timings["calibrate"]
    total = timings["plan"] + timings["play protocol"] + timings["calibrate + verify"]
    print(f"  {'loop (plan, play, calibrate, verify)':20s} {total:7.1f} s")
    print(f"  protocol played: {played_s:.1f} s of device time in {timings['play protocol']:.1f}"
          f" s ({played_s / timings['play protocol']:.2f}x real time); verification "
          f"{verify_s:.1f} s")
    effects = [(e["name"], e["parameters"]) for e in report["profile"]["effects"]]
    print(f"  verdict: {report['verdict']}; effects: "
          + (", ".join(f"{name} " + ", ".join(f"{k}={v['value']:.4g} +- {v['uncertainty']:.2g}"
                                             for k, v in params.items())
                       for name, params in effects) or "none"))
    rmse = report["held_out_rmse_n"]
    print(f"  held-out model error: {rmse['before'] * 1e3:.3f} mN -> {rmse['after'] * 1e3:.3f} mN")
    print(f"  rendered friction error: {report['rendering']['text']}")


if __name__ == "__main__":
    main()
