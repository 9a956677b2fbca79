"""Firmware step cost: wall time per ``Firmware.advance`` of 1, 2 and 5 ms, as the served device
runs it, and its ratio to real time.

Run: ``python bench/bench_firmware_step.py [--seconds 2] [--repeat 3] [--step-ms 1 2 5]``

``hcard device serve`` runs the simulation from :meth:`Firmware.run_realtime`, which wakes every
1 ms and advances the device by the time elapsed: about 10 frames (10 kHz) and one STATE report
per call. Each call costs a fixed amount besides its frames (renderer, model-based rendering,
plate loop, amplifier, finger physics, sensors and the STATE report, each run on a few frames),
so the device keeps up with the wall clock only when that cost is well under 1 ms. Here a host
finger strokes back and forth (FINGER reports through the protocol codec at ``--finger-hz``, its
speed swelling from 30 to 180 mm/s on every 0.7 s stroke) while a card plays (a UV grating on
the E-ViTa, a bipolar grating on the coupled stimulator), and the STATE reports are drained
after every step as the USB pump does. Prints, per device and step, the wall time per step and
the ratio of device time to wall time (aim: at least 3x at 1 ms, so the served device keeps up
with room to spare), and the same ratio by CPU time (the one-core figure when other processes
share the machine). The best of ``--repeat`` runs is kept.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from bench_device_sim import back_and_forth, cards

from hcard.card_io import to_bytes
from hcard.device import open_device

DEVICES = {"e-vita, UV grating": "sim://", "coupled, bipolar grating": "sim://coupled"}
"""Bench case -> device URI (the card of the same case in :func:`bench_device_sim.cards`)."""


def run(uri: str, card: object, seconds: float, step_s: float,
        finger_hz: float) -> tuple[float, float]:
    """Wall-clock and CPU seconds per ``Firmware.advance(step_s)`` over ``seconds`` of device
    time, with a host finger reporting at ``finger_hz`` and the card playing."""
    with open_device(uri) as driver:
        firmware = driver.firmware
        width, height = firmware.config.surface_mm
        track = back_and_forth(seconds + 0.1, width, height / 2)
        driver.upload_card(to_bytes(card))
        driver.start()
        steps = round(seconds / step_s)
        period = 1.0 / finger_hz
        next_report, sample = 0.0, 0
        wall = cpu = 0.0
        for k in range(steps):
            now = k * step_s
            while next_report <= now:  # host reports due by now, as they arrive
                sample = min(int(next_report * 1e3), len(track) - 1)
                driver.send_finger(next_report, float(track.x[sample]), float(track.y[sample]),
                                   0.5, True)
                next_report += period
            start, start_cpu = time.perf_counter(), time.process_time()
            firmware.advance(step_s)
            firmware.take_input_reports()
            wall += time.perf_counter() - start
            cpu += time.process_time() - start_cpu
    return wall / steps, cpu / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="device seconds per run")
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (best is kept)")
    parser.add_argument("--step-ms", type=float, nargs="+", default=[1.0, 2.0, 5.0],
                        help="device time per Firmware.advance() call, ms")
    parser.add_argument("--finger-hz", type=float, default=100.0,
                        help="rate of the host's FINGER reports, Hz")
    args = parser.parse_args()
    print(f"Firmware.advance() with a host finger at {args.finger_hz:g} Hz and a card playing, "
          f"{args.seconds:g} s of device time per run, best of {args.repeat}")
    all_cards = cards()
    for name, uri in DEVICES.items():
        _, card = all_cards[name]
        for step_ms in args.step_ms:
            step_s = step_ms * 1e-3
            results = [run(uri, card, args.seconds, step_s, args.finger_hz)
                       for _ in range(args.repeat)]
            wall = min(r[0] for r in results)
            cpu = min(r[1] for r in results)
            print(f"{name:26s} step {step_ms:g} ms: {wall * 1e3:.3f} ms wall per step -> "
                  f"{step_s / wall:5.2f}x real time ({step_s / cpu:.2f}x by CPU time)")


if __name__ == "__main__":
    main()
