"""``hcard calibrate`` of a 1e5-sample coupled-stimulator recording with the air layer hidden,
in CPU seconds against the goal of 60 s, and whether its answers are the baseline's.

Run: ``python bench/bench_calibrate_coupled.py [--duration 100s] [--no-evita] [--cache DIR]``

The recording is ``hcard device synthesize --device coupled --effect air-layer --duration 100s
--seed 0`` (100,840 samples), synthesized once into ``--cache`` (default: a folder in the
temporary directory) and reused. The calibration runs in this process as the command line runs
it (``hcard calibrate RECORDING -o OUT``, its 50 bootstrap refits and figures included). CPU
time is ``time.process_time`` (every thread of the process); the machine is shared and its wall
time noisy. The answers (effects chosen, verdict, the final model's fitted values and
uncertainties, held-out RMSE, runner-up) are compared with :data:`BASELINE`, those of commit
:data:`BASELINE_COMMIT`: equal when every value is within :data:`RELATIVE` of the baseline's.

The E-ViTa figure: the same for ``--device uv`` (no effect hidden; the E-ViTa hides none).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

from hcard.cli.main import main as hcard_main

GOAL_CPU_S = 60.0
BASELINE_COMMIT = "cad03d9"
"""The commit the baseline answers came from (24-26 s CPU). Before it:

- commit 3ce097b (52.6 s CPU; 39.2-41.6 s after the forward cache, same answers): "structured
  residual not explained" against speed and direction, the finger fit biased (friction_occluded
  0.53, occlusion time 6.5 s, speed sensitivity 0.37 for the device's 0.79, 20 s and 0.3) by the
  ~300 touch-down samples at speed 0 that rule MS5 now leaves out;
- commit 7767ba3 (13.8 s CPU): "no effect needed", the finger recovered, the air layer the
  runner-up at -4.3 % held-out RMSE and ``H`` -1605, refused by K9 (b)'s 5 %, its effect
  absorbed by an EV area of 6.1e-5 m^2 for the device's 1e-4.

Now (K38: 92 % of the base's held-out MSE is sensor noise) the air layer is added, at 9.97 +-
0.33 um for the hidden 10 um, and every base parameter is the device's own: EV area 9.90e-5
m^2, load index 0.911 (0.91), psi* 2.384 (2.38), the finger's 0.360, 40 mm/s, 0.30. The verdict
is ambiguous against the pad's flattening, which ``--settle`` on a device would play out
(spec/calibration.md K34)."""
RELATIVE = 1e-6
BASELINE = {
    "effects_added": ["air-layer"],
    "verdict": "ambiguous: the data cannot separate the final model from its runner-up",
    "held_out_rmse_n": 0.007895801345101133,
    "runner_up": ["finger-geometry"],
    "parameters": {  # name: (value, uncertainty), the final model's fitted parameters
        "air-layer.air_gap": (9.967547970597544e-06, 3.4924302403138223e-07),
        "ev_area": (9.900463655608336e-05, 1.2289859322023083e-06),
        "finger.friction_initial": (0.35970638552484807, 0.00018564824486839578),
        "finger.friction_occluded": (0.8896632587940927, 0.04136438902399369),
        "finger.load_index": (0.9109065228388445, 0.0005412428206899066),
        "finger.occlusion_time": (25.10489676366, 2.1156905060437188),
        "finger.peak_speed": (0.03986254835983371, 6.429560842169071e-05),
        "finger.speed_sensitivity": (0.29657623804694233, 0.0011353722490669892),
        "force_offset": (0.0003485508032919202, 0.00011714522926619716),
        "uv_psi_star": (2.3835461219699607, 0.0017527906161817197),
    },
}


def _run(args: list[str]) -> None:
    try:
        hcard_main(args)
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise


def synthesized(cache: Path, device: str, effect: str | None, duration: str) -> Path:
    """The recording of ``hcard device synthesize`` with these options (made once)."""
    folder = cache / f"{device}-{effect or 'none'}-{duration}-seed0"
    recording = folder / "recording.csv"
    if not recording.exists():
        args = ["device", "synthesize", "-q", "--device", device, "--duration", duration,
                "--seed", "0", "-o", str(folder)]
        if effect:
            args += ["--effect", effect]
        print("synthesizing: hcard " + " ".join(args), flush=True)
        _run(args)
    return recording


def calibrated(recording: Path, out: Path) -> tuple[float, float, dict]:
    """CPU and wall seconds of ``hcard calibrate RECORDING -o OUT`` in this process, and its
    report."""
    cpu, wall = time.process_time(), time.perf_counter()
    _run(["calibrate", "-q", str(recording), "-o", str(out)])
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    return cpu, wall, json.loads((out / "report.json").read_text())


def answers(report: dict) -> dict:
    after = report["after"]["parameters"]
    return {
        "effects_added": [effect["name"] for effect in report["effects_added"]],
        "verdict": report["verdict"],
        "held_out_rmse_n": report["held_out_rmse_n"]["after"],
        "runner_up": (report.get("runner_up") or {}).get("runner_up"),
        "parameters": {k: (v["value"], v["uncertainty"]) for k, v in after.items()
                       if v["fitted"]},
    }


def differences(got: dict, expected: dict) -> list[str]:
    def close(a: float, b: float) -> bool:
        return math.isclose(a, b, rel_tol=RELATIVE, abs_tol=0.0)

    out = [f"{key}: {got[key]!r} != {expected[key]!r}"
           for key in ("effects_added", "verdict", "runner_up") if got[key] != expected[key]]
    if not close(got["held_out_rmse_n"], expected["held_out_rmse_n"]):
        out.append(f"held-out RMSE {got['held_out_rmse_n']!r} != {expected['held_out_rmse_n']!r}")
    if got["parameters"].keys() != expected["parameters"].keys():
        out.append(f"fitted parameters {sorted(got['parameters'])} != "
                   f"{sorted(expected['parameters'])}")
    else:
        for name, (value, sigma) in expected["parameters"].items():
            v, s = got["parameters"][name]
            if not (close(v, value) and close(s, sigma)):
                out.append(f"{name}: {v!r} +- {s!r} != {value!r} +- {sigma!r}")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", default="100s")
    parser.add_argument("--cache", type=Path,
                        default=Path(tempfile.gettempdir()) / "hcard-bench-calibrate-coupled")
    parser.add_argument("--no-evita", action="store_true", help="skip the E-ViTa figure")
    options = parser.parse_args()
    recording = synthesized(options.cache, "coupled", "air-layer", options.duration)
    with tempfile.TemporaryDirectory() as tmp:
        cpu, wall, report = calibrated(recording, Path(tmp) / "coupled")
        samples = report["data"].get("samples", "?") if isinstance(report.get("data"), dict) \
            else "?"
        print(f"coupled, air layer hidden, {options.duration} ({samples} samples): "
              f"{cpu:.1f} s CPU, {wall:.1f} s wall; {cpu / GOAL_CPU_S:.2f} of the "
              f"{GOAL_CPU_S:.0f} s goal ({'met' if cpu < GOAL_CPU_S else 'NOT met'})")
        found = differences(answers(report), BASELINE) if options.duration == "100s" else None
        if found is None:
            print("answers: not compared (the baseline is of --duration 100s)")
        elif found:
            print(f"answers: DIFFER from commit {BASELINE_COMMIT}'s:")
            for line in found:
                print("  " + line)
        else:
            print(f"answers: equal to commit {BASELINE_COMMIT}'s (within {RELATIVE:g} relative; "
                  "effects, verdict, runner-up, fitted values and uncertainties)")
        if not options.no_evita:
            evita = synthesized(options.cache, "uv", None, options.duration)
            cpu_uv, wall_uv, _ = calibrated(evita, Path(tmp) / "evita")
            print(f"E-ViTa, {options.duration}: {cpu_uv:.1f} s CPU, {wall_uv:.1f} s wall")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
