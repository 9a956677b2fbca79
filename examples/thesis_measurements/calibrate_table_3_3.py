"""Run the calibration loop on the only measured data set the thesis prints in full: Table 3.3.

Table 3.3 (thesis lines 1435-1446) gives, for 11 participants, the electrostatic attraction on a
finger hovering over the plate under the three conditions of Table 3.4 (lines 1450-1455): HDHV
(0.50 mm gap, 2000 V), LDHV (0.25 mm, 2000 V) and LDLV (0.25 mm, 1414 V). The recordings in this
directory hold those 33 values under the printed column labels (``fn_mn`` is the measured force;
see README.md).

The printed columns contradict Eq. 3.17 (the 1414 V column is the largest), so the labels may be
permuted. An *assignment* maps each printed column to the condition it is taken to have been
measured under; there are 3! = 6 of them (:data:`ASSIGNMENTS`). For each, the base model is the
air-layer law, Eq. 3.17 (``ev-air-layer``: voltage and air gap in, force out), with its area
fitted; the loop holds out three participants (all their conditions) and runs with the full
effect library.

    python examples/thesis_measurements/calibrate_table_3_3.py [-o OUTDIR]
    python examples/thesis_measurements/calibrate_table_3_3.py --all-assignments

The first form runs the printed labels and the swap of the two 0.25 mm voltages and writes both
reports (Markdown, JSON, figures) to OUTDIR (default ``table_3_3_calibration/``). The second
prints one row per assignment, best held-out error first: held-out RMSE (mN), fitted area with
its uncertainty (mm^2), the residual's eta^2 (and F-test p) against the air gap and the voltage,
and the loop's verdict.
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.loop import calibrate
from hcard.calibration.measurement import read_measurement
from hcard.calibration.results import CalibrationResult
from hcard.plugins.registry import get_registry

HERE = Path(__file__).resolve().parent

CONDITIONS: dict[str, tuple[float, float]] = {
    "HDHV": (0.50e-3, 2000.0),
    "LDHV": (0.25e-3, 2000.0),
    "LDLV": (0.25e-3, 1414.0),
}
"""Table 3.4 (lines 1450-1455): condition label -> (finger-plate air gap, m; voltage, V)."""

COLUMNS = tuple(CONDITIONS)
"""The printed column labels of Table 3.3, in the printed order."""

PRINTED: dict[str, str] = {column: column for column in COLUMNS}
"""The assignment as printed: every column measured under its own label."""

VOLTAGES_SWAPPED: dict[str, str] = {"HDHV": "HDHV", "LDHV": "LDLV", "LDLV": "LDHV"}
"""The two 0.25 mm columns exchanged (the relabelling the README first proposed)."""

CYCLIC: dict[str, str] = {"HDHV": "LDLV", "LDHV": "HDHV", "LDLV": "LDHV"}
"""The cyclic relabelling, the best fit of the six (README.md in this folder)."""

ASSIGNMENTS: tuple[dict[str, str], ...] = tuple(
    dict(zip(COLUMNS, order, strict=True)) for order in itertools.permutations(COLUMNS)
)
"""All six ways the printed column labels can map to the three conditions."""

PARTICIPANTS = 11
HELD_OUT = (1, 4, 8)
"""Participants ii, v and ix (0-based 1, 4, 8): all their conditions form the held-out set."""

FINGER_WIDTH_MM = (19.18, 14.04, 17.65, 17.89, 16.45, 16.25, 16.89, 16.78, 18.20, 14.69, 15.46)
"""Finger pad width a of participants i-xi, mm (Table 3.3, lines 1436-1446)."""

FINGER_HEIGHT_MM = (13.09, 11.16, 12.41, 14.94, 11.66, 11.40, 12.53, 13.20, 15.00, 12.80, 12.49)
"""Finger pad height b of participants i-xi, mm (Table 3.3, lines 1436-1446)."""


def printed_columns() -> dict[str, np.ndarray]:
    """The three printed columns of Table 3.3 as read from the recordings: label -> the 11
    forces of participants i-xi, N.

    Raises:
        ValueError: a recording whose (gap, voltage) rows do not make 11 participants per
            printed column.
    """
    near = read_measurement(HERE / "ev_hover_table3_3_gap0p25mm.csv")
    far = read_measurement(HERE / "ev_hover_table3_3_gap0p50mm.csv")
    columns = {
        "HDHV": np.asarray(far.normal_force)[far.voltage == 2000.0],
        "LDHV": np.asarray(near.normal_force)[near.voltage == 2000.0],
        "LDLV": np.asarray(near.normal_force)[near.voltage == 1414.0],
    }
    for label, values in columns.items():
        if len(values) != PARTICIPANTS:
            raise ValueError(
                f"printed column {label}: {len(values)} values in the recordings, expected "
                f"{PARTICIPANTS} (one per participant)"
            )
    return columns


def describe(assignment: Mapping[str, str]) -> str:
    """An assignment in words, e.g. ``"HDHV->LDLV, LDHV->HDHV, LDLV->LDHV"``."""
    if dict(assignment) == PRINTED:
        return "as printed"
    return ", ".join(f"{column}->{assignment[column]}" for column in COLUMNS)


def _checked(assignment: Mapping[str, str]) -> dict[str, str]:
    if sorted(assignment) != sorted(COLUMNS) or sorted(assignment.values()) != sorted(COLUMNS):
        raise ValueError(
            f"assignment must map each printed column {', '.join(COLUMNS)} to a distinct "
            f"condition of Table 3.4, got {dict(assignment)!r}"
        )
    return dict(assignment)


def table_3_3(
    assignment: Mapping[str, str] = PRINTED,
    *,
    swap_voltages: bool = False,
    held_out: tuple[int, ...] = HELD_OUT,
) -> CalibrationData:
    """The 33 Table 3.3 forces as calibration data for the ``ev-air-layer`` model.

    Inputs ``voltage`` (V) and ``air_gap`` (m); observed: the electrostatic force, N.
    Regressors: voltage, air gap, participant, finger width and height (m). The samples are
    steady-state points, not a time series. ``assignment`` maps each printed column label to the
    Table 3.4 condition its values are taken to have been measured under; ``swap_voltages`` is
    short for :data:`VOLTAGES_SWAPPED`. ``held_out``: 0-based participants whose three
    conditions form the held-out set (default :data:`HELD_OUT`).

    Raises:
        ValueError: ``assignment`` is not a permutation of the three labels, or ``held_out``
            names no participant or all of them.
    """
    if not held_out or not set(held_out) <= set(range(PARTICIPANTS)) or len(set(held_out)) >= (
        PARTICIPANTS
    ):
        raise ValueError(
            f"held_out must name some but not all participants 0-{PARTICIPANTS - 1}, "
            f"got {held_out!r}"
        )
    chosen = _checked(VOLTAGES_SWAPPED if swap_voltages else assignment)
    columns = printed_columns()
    voltage, gap, force, who, source = [], [], [], [], []
    for index, column in enumerate(COLUMNS):
        air_gap, volts = CONDITIONS[chosen[column]]
        force.append(columns[column])
        voltage.append(np.full(PARTICIPANTS, volts))
        gap.append(np.full(PARTICIPANTS, air_gap))
        who.append(np.arange(PARTICIPANTS))
        source.append(np.full(PARTICIPANTS, index))
    participant = np.concatenate(who)
    test = np.isin(participant, held_out)
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
        recording=np.concatenate(source),
        sources=tuple(
            f"thesis Table 3.3, printed column {c} taken as {chosen[c]}" for c in COLUMNS
        ),
        sample_rate_hz=1.0,
        split=f"by participant: {held_out} (0-based) held out (all three conditions each)",
        time_ordered=False,
    )


def run(
    assignment: Mapping[str, str] = PRINTED,
    *,
    swap_voltages: bool = False,
    held_out: tuple[int, ...] = HELD_OUT,
) -> CalibrationResult:
    """The loop on :func:`table_3_3` with ``ev-air-layer`` and every installed effect."""
    registry = get_registry()
    return calibrate(
        table_3_3(assignment, swap_voltages=swap_voltages, held_out=held_out),
        registry.get("predictor", "ev-air-layer"),
        list(registry.calibration_effects.values()),
        observation="output",
    )


@dataclass(frozen=True)
class AssignmentRow:
    """One assignment through the loop.

    Attributes:
        assignment: printed column -> condition.
        test_rmse: held-out RMSE of the final model, N.
        area: fitted area, m^2; area_sigma: its uncertainty as the loop reports it, m^2.
        gap_eta2, gap_p: residual variance share explained by the air gap, and its F-test p.
        voltage_eta2, voltage_p: the same against the voltage.
        verdict: the loop's verdict; structure: where structure is left, in words.
    """

    assignment: dict[str, str]
    test_rmse: float
    area: float
    area_sigma: float
    gap_eta2: float
    gap_p: float
    voltage_eta2: float
    voltage_p: float
    verdict: str
    structure: str


def assignment_row(assignment: Mapping[str, str]) -> AssignmentRow:
    """Run the loop on one assignment and collect the figures of the comparison table."""
    result = run(assignment)
    regressors = result.after.analysis.regressors
    return AssignmentRow(
        assignment=dict(assignment),
        test_rmse=result.after.test_rmse,
        area=result.after.fit.params["area"],
        area_sigma=result.after.fit.uncertainties["area"],
        gap_eta2=regressors["air_gap"].eta2,
        gap_p=regressors["air_gap"].p_value,
        voltage_eta2=regressors["voltage"].eta2,
        voltage_p=regressors["voltage"].p_value,
        verdict=result.verdict,
        structure=result.structure.describe(),
    )


def all_assignments() -> list[AssignmentRow]:
    """Every assignment of :data:`ASSIGNMENTS` through the loop, lowest held-out error first."""
    return sorted((assignment_row(a) for a in ASSIGNMENTS), key=lambda row: row.test_rmse)


def participant_errors(assignment: Mapping[str, str]) -> np.ndarray:
    """Leave-one-participant-out: the loop run 11 times, each time holding out one
    participant's three conditions; returns each participant's held-out RMSE, N (index = the
    participant, 0-based). The spread of these shows how much the choice of held-out
    participants moves the comparison of assignments."""
    return np.array(
        [run(assignment, held_out=(who,)).after.test_rmse for who in range(PARTICIPANTS)]
    )


def cross_validated_rmse(errors: np.ndarray) -> float:
    """Pooled leave-one-participant-out RMSE from :func:`participant_errors`, N."""
    return float(np.sqrt(np.mean(np.square(errors))))


RATIOS = {"LDHV/LDLV": ("LDHV", "LDLV"), "HDHV/LDHV": ("HDHV", "LDHV")}
"""The two within-participant ratios: the voltage step (2000 V / 1414 V at 0.25 mm) and the gap
step (0.50 mm / 0.25 mm at 2000 V)."""


def condition_ratios(assignment: Mapping[str, str]) -> dict[str, tuple[float, float, float]]:
    """Each participant's force ratio between two conditions under ``assignment``, where the
    participant's own contact area cancels: ratio name -> (geometric mean over participants,
    standard error of the mean log ratio, the ratio Eq. 3.17 predicts with the ``ev-air-layer``
    defaults). Eq. 3.17 gives (2000/1414)^2 = 2.00 for the voltage step whatever the layers."""
    chosen = _checked(assignment)
    columns = printed_columns()
    measured = {chosen[column]: values for column, values in columns.items()}
    model = get_registry().get("predictor", "ev-air-layer")

    def predicted(condition: str) -> float:
        air_gap, volts = CONDITIONS[condition]
        force = model.forward(voltage=np.array([volts]), air_gap=np.array([air_gap]))
        return float(np.asarray(force)[0])

    out = {}
    for name, (upper, lower) in RATIOS.items():
        logs = np.log(measured[upper] / measured[lower])
        out[name] = (
            float(np.exp(logs.mean())),
            float(logs.std(ddof=1) / np.sqrt(len(logs))),
            predicted(upper) / predicted(lower),
        )
    return out


def format_table(rows: list[AssignmentRow]) -> str:
    """The comparison table as Markdown."""
    lines = [
        "| assignment (printed -> condition) | held-out RMSE | area | gap eta2 (p) "
        "| voltage eta2 (p) | structure left |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {describe(row.assignment)} | {row.test_rmse * 1e3:.3f} mN "
            f"| {row.area * 1e6:.1f} +- {row.area_sigma * 1e6:.1f} mm2 "
            f"| {row.gap_eta2:.2f} ({row.gap_p:.2g}) "
            f"| {row.voltage_eta2:.2f} ({row.voltage_p:.2g}) "
            f"| {row.structure} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("table_3_3_calibration"))
    parser.add_argument(
        "--all-assignments",
        action="store_true",
        help="run all six label assignments and print the comparison table (no reports)",
    )
    args = parser.parse_args()
    if args.all_assignments:
        rows = all_assignments()
        print(format_table(rows))
        print()
        print("Leave-one-participant-out (each of the 11 participants held out in turn):")
        errors = {describe(row.assignment): participant_errors(row.assignment) for row in rows}
        best = next(iter(errors))
        for name, err in errors.items():
            line = f"  {name}: pooled held-out RMSE {cross_validated_rmse(err) * 1e3:.3f} mN"
            if name != best:
                wins = int(np.sum(errors[best] < err))
                line += f"; {best} lower for {wins} of {PARTICIPANTS} participants"
            print(line)
        print()
        print("Within-participant ratios (geometric mean over 11, +- standard error) against")
        print("Eq. 3.17 at the model's defaults (area cancels):")
        for row in rows:
            ratios = condition_ratios(row.assignment)
            print(
                f"  {describe(row.assignment)}: "
                + "; ".join(
                    f"{key} {value:.2f} x/ {np.exp(se):.2f} (Eq. 3.17: {model:.2f})"
                    for key, (value, se, model) in ratios.items()
                )
            )
        return
    from hcard.calibration.report.writer import write_report

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
