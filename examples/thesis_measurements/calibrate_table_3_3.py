"""Run the calibration loop on the only measured data set the thesis prints in full: Table 3.3.

Table 3.3 (thesis lines 1435-1446) gives, for 11 participants, the electrostatic attraction on a
finger hovering over the plate under the three conditions of Table 3.4 (lines 1450-1455): HDHV
(0.50 mm gap, 2000 V), LDHV (0.25 mm, 2000 V) and LDLV (0.25 mm, 1414 V). The recordings in this
directory hold those 33 values (``fn_mn`` is the measured force; see README.md).

The base model is the air-layer law, Eq. 3.17 (``ev-air-layer``: voltage and air gap in, force
out), with its area fitted; the loop holds out three participants (all their conditions) and runs
with the full effect library. It runs twice: with the columns as printed, and with the two 0.25 mm
voltages swapped (the printed LDLV column, at 1414 V, is larger than LDHV, at 2000 V, in all 11
rows, which Eq. 3.17's ``F ~ V^2`` cannot produce).

    python examples/thesis_measurements/calibrate_table_3_3.py [-o OUTDIR]

prints the verdict of each run and writes both reports (Markdown, JSON, figures) to OUTDIR
(default ``table_3_3_calibration/``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.loop import CalibrationResult, calibrate
from hcard.calibration.measurement import read_measurement
from hcard.plugins.registry import get_registry

HERE = Path(__file__).resolve().parent
RECORDINGS = (
    ("ev_hover_table3_3_gap0p25mm.csv", 0.25e-3),  # LDHV then LDLV, participants i-xi
    ("ev_hover_table3_3_gap0p50mm.csv", 0.50e-3),  # HDHV, participants i-xi
)
"""The two recordings and their finger-plate air gap (Table 3.4), m."""

PARTICIPANTS = 11
HELD_OUT = (1, 4, 8)
"""Participants ii, v and ix (0-based 1, 4, 8): all their conditions form the held-out set."""

FINGER_WIDTH_MM = (19.18, 14.04, 17.65, 17.89, 16.45, 16.25, 16.89, 16.78, 18.20, 14.69, 15.46)
"""Finger pad width a of participants i-xi, mm (Table 3.3, lines 1436-1446)."""

FINGER_HEIGHT_MM = (13.09, 11.16, 12.41, 14.94, 11.66, 11.40, 12.53, 13.20, 15.00, 12.80, 12.49)
"""Finger pad height b of participants i-xi, mm (Table 3.3, lines 1436-1446)."""


def table_3_3(*, swap_voltages: bool = False) -> CalibrationData:
    """The 33 Table 3.3 forces as calibration data for the ``ev-air-layer`` model.

    Inputs ``voltage`` (V) and ``air_gap`` (m); observed: the electrostatic force, N.
    Regressors: voltage, air gap, participant, finger width and height (m). The samples are
    steady-state points, not a time series. ``swap_voltages`` exchanges 2000 V and 1414 V in the
    0.25 mm recording (the printed LDHV and LDLV labels).
    """
    voltage, gap, force, who = [], [], [], []
    for name, air_gap in RECORDINGS:
        m = read_measurement(HERE / name)
        v = m.voltage.copy()
        if swap_voltages and air_gap == 0.25e-3:
            v = np.where(v == 2000.0, 1414.0, 2000.0)
        voltage.append(v)
        gap.append(np.full(len(m), air_gap))
        force.append(m.normal_force)
        who.append(np.asarray(m.stroke) % PARTICIPANTS)
    participant = np.concatenate(who)
    test = np.isin(participant, HELD_OUT)
    inputs = {"voltage": np.concatenate(voltage), "air_gap": np.concatenate(gap)}
    return CalibrationData(
        inputs=inputs,
        observed=np.concatenate(force),
        regressors={
            **inputs,
            "participant": participant.astype(np.float64),
            "finger_width": np.asarray(FINGER_WIDTH_MM)[participant] * 1e-3,
            "finger_height": np.asarray(FINGER_HEIGHT_MM)[participant] * 1e-3,
        },
        train=~test,
        test=test,
        recording=np.repeat(np.arange(len(RECORDINGS)), [len(f) for f in force]),
        sources=tuple(f"thesis Table 3.3 ({name})" for name, _ in RECORDINGS),
        sample_rate_hz=1.0,
        split="by participant: ii, v and ix held out (all three conditions each)",
        time_ordered=False,
    )


def run(*, swap_voltages: bool = False) -> CalibrationResult:
    """The loop on :func:`table_3_3` with ``ev-air-layer`` and every installed effect."""
    registry = get_registry()
    return calibrate(
        table_3_3(swap_voltages=swap_voltages),
        registry.get("predictor", "ev-air-layer"),
        list(registry.calibration_effects.values()),
        observation="output",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("table_3_3_calibration"))
    args = parser.parse_args()
    from hcard.calibration.report import write_report

    for label, swap in (("as printed", False), ("voltages swapped", True)):
        result = run(swap_voltages=swap)
        directory = args.output / ("swapped" if swap else "printed")
        write_report(result, directory)
        area = result.after.fit.params["area"]
        sigma = result.after.fit.uncertainties["area"]
        print(f"{label}: {result.summary}")
        print(f"  fitted area {area * 1e6:.1f} +- {sigma * 1e6:.1f} mm^2; report {directory}")


if __name__ == "__main__":
    main()
