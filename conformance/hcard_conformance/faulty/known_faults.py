"""The known-fault table (spec/conformance.md section 6, QN2): each fault of the faulty device
(:mod:`.faults`) with the check that must catch it, a strength above the check's threshold at
which that check must FAIL and one below at which the same run of it must PASS every case, and
why those strengths follow from the threshold.

The margin is a factor of about 3 on either side of the threshold's strength (the strength at
which the check's metric reaches its threshold, from a model of what the fault does to the
metric stated in ``why``), unless the fault's range or the metric's resolution says otherwise.
``tests/conformance/test_known_faults.py`` runs every row at both strengths (in CI) and renders
:func:`markdown_table` into conformance/README.md (a test holds them equal).

>>> row = KNOWN_FAULTS_BY_NAME["output-latency"]
>>> row.level, row.uri(row.fails_at)
('device', 'faulty://output-latency?strength=30')
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hcard_conformance import check_names
from hcard_conformance.faulty.faults import FAULTS_BY_NAME, Fault, fault_uri


@dataclass(frozen=True)
class KnownFault:
    """One row of the table.

    Attributes:
        fault: the fault's name (:data:`~.faults.FAULTS`).
        check: the check that must catch it (a ``--check`` prefix naming that check alone).
        renders: for a renderer-level check, the render entries of spec/vectors run (the
            cases; ``Context.options["renders"]``); empty for a device check, whose cases all
            run.
        fails_at: a strength above the threshold: the check has a FAIL case (fault unit).
        passes_at: a strength below it: every case of the same run PASSes (fault unit).
        why: how both strengths follow from the threshold.
    """

    fault: str
    check: str
    renders: tuple[str, ...]
    fails_at: float
    passes_at: float
    why: str

    @property
    def level(self) -> str:
        """The check's level (``renderer`` or ``device``)."""
        return self.check.split(".", 1)[0]

    @property
    def info(self) -> Fault:
        """The fault."""
        return FAULTS_BY_NAME[self.fault]

    def uri(self, strength: float) -> str:
        """The faulty device with this row's fault at ``strength``."""
        return fault_uri(self.fault, strength)


KNOWN_FAULTS: tuple[KnownFault, ...] = (
    KnownFault(
        "output-latency", check_names.DEVICE_LATENCY, (), 30.0, 3.0,
        "D3: L <= 10 ms. The device's own latency is 0.8 ms and the delay adds to it, so the "
        "threshold strength is 9.2 ms: 30 ms (L 30.8 ms) fails, 3 ms (L 3.8 ms) passes."),
    KnownFault(
        "slow-plate", check_names.DEVICE_DYNAMICS, (), 2.4, 0.25,
        "D2: t_r <= 2 ms. A first-order rise takes tau ln 9 with tau = 0.1 ms + strength, so "
        "the threshold strength is 2 ms / ln 9 - 0.1 ms = 0.81 ms: 2.4 ms (t_r 5.5 ms) fails, "
        "0.25 ms (t_r 0.77 ms) passes. D1 does not bind: the braked fall keeps the swept gain "
        "above -3 dB to 470 Hz."),
    KnownFault(
        "weak-plate", check_names.DEVICE_FRICTION, (), 30.0, 3.0,
        "A1 (device): RMS relative error <= 0.08. UV friction 1 - exp(-Psi/Psi*), Psi ~ 1/w "
        "(Eq. 2.33), moves by 0.65-0.8 per unit of ln w at the cases' targets 0.35-0.85, so a "
        "deficit g gives A1 ~ 0.7 ln(1/(1 - g)) and the threshold strength is 10-12 %: 30 % "
        "fails, 3 % passes."),
    KnownFault(
        "plate-overdrive", check_names.DEVICE_SAFETY, (), 1.0, 0.02,
        "S1: n_over = 0, one report count (1 nm) over a limit tolerated and amplitudes "
        "reported in whole nm. The plate driven at its 2500 nm limit shows over it once "
        "(1 + g) 2500 nm >= 2501.5 nm, g = 0.06 %: 1 % (25 nm over) fails, 0.02 % (0.5 nm) "
        "passes."),
    KnownFault(
        "weak-ev", check_names.DEVICE_FRICTION, (), 100.0, 12.0,
        "A1 (device), case bipolar: half its taxtels ask EV 1.2; at 0.5 N the device's "
        "2000 V give 1 + 0.157 (1 - g)^2 (force ~ V^2, Eq. 3.12), so A1 ~ (1.2 - that) / 1.2 "
        "/ sqrt(2) reaches 0.08 at g = 36 %: the dead channel (100 %, the largest strength) "
        "fails, 12 % passes."),
    KnownFault(
        "late-watchdog", check_names.DEVICE_WATCHDOG, (), 150.0, 16.0,
        "S2: t_fault <= watchdog_ms + 50 ms. The device is off 69 ms after the host's last "
        "report with watchdog_ms 70 (50 ms of host silence and its 20 ms watchdog) and the "
        "delay adds to it, so the threshold strength is 51 ms: 150 ms fails, 16 ms passes."),
    KnownFault(
        "residual-vibration", check_names.DEVICE_WATCHDOG, (), 150.0, 16.0,
        "S2's safe state is a plate at most 50 nm: a residual r leaves the plate at r after "
        "the watchdog, so the threshold strength is 50 nm: 150 nm never gets there and fails, "
        "16 nm passes."),
    KnownFault(
        "touch-lag", check_names.DEVICE_LATENCY, (), 15.0, 1.5,
        "D3: L <= 10 ms. The move is applied lag late (L = 0.8 ms + lag), and the check's "
        "jump of 60 mm in one 10 ms sample reads as a 6 m/s stroke that dead reckoning (R6) "
        "carries off the 120 mm surface within 5 ms of the sample's time: from a lag of about "
        "4.5 ms the plate waits for the next sample, 10 ms later. Threshold strength 4.5 ms: "
        "15 ms (L 25.8 ms) fails, 1.5 ms (L 2.6 ms) passes."),
    KnownFault(
        "touch-offset", check_names.RENDERER_BOUNDARY, ("edge@moderate-stroke",), 7.5, 0.75,
        "A5: db <= 2.5 mm. The edge at x = 60 mm is crossed offset early, db = offset, so the "
        "threshold strength is 2.5 mm: 7.5 mm (beyond the 5 mm search window at 100 mm/s: no "
        "transition, db = inf) fails, 0.75 mm passes."),
    KnownFault(
        "phase-offset", check_names.RENDERER_SPATIAL_PHASE,
        ("coarse-grating@moderate-stroke",), 67.5, 7.5,
        "A4: dx <= 2.5 mm. A phase phi moves the 40 mm position-locked grating by phi / 360 "
        "x 40 mm, so the threshold strength is 22.5 deg: 67.5 deg (7.5 mm; A4 reports its 5 mm "
        "search bound) fails, 7.5 deg (0.83 mm) passes."),
    KnownFault(
        "frequency-scale", check_names.RENDERER_COMPONENT_FREQUENCY,
        ("single-grating@moderate-stroke",), 15.0, 1.5,
        "A3: e_f <= 0.05, and e_f is the scale: threshold strength 5 %: 15 % fails, 1.5 % "
        "passes."),
    KnownFault(
        "amplitude-deficit", check_names.RENDERER_COMPONENT_AMPLITUDE,
        ("single-grating@moderate-stroke",), 84.0, 9.0,
        "A2: e_A <= 0.08 of the mean friction. The 1 mm grating of amplitude 0.2 on a mean of "
        "0.7 loses g x 0.2 / 0.7, so the threshold strength is 28 %: 84 % fails, 9 % passes."),
    KnownFault(
        "depth-deficit", check_names.RENDERER_FRICTION_ERROR, ("edge@fast-stroke",), 34.0, 3.8,
        "A1: RMS relative error <= 0.08. The edge card's 0.5 half is rendered 0.5 + 0.5 d "
        "(relative error d), its 1.0 half exactly, so A1 ~ d / sqrt(2) and the threshold "
        "strength is 11.3 %: 34 % fails, 3.8 % passes."),
    KnownFault(
        "velocity-locked", check_names.RENDERER_SPATIAL_PHASE, ("coarse-grating@scrub",),
        1000.0, 1.0,
        "R8, A4: rendered from the odometer, a position-locked grating stroked with reversals "
        "moves by the change of the velocity estimate times the touch period at each reversal "
        "(10 mm at 250 mm/s and 20 ms on the scrub). 1000 mm velocity-locks every "
        "position-locked texture and fails; 1 mm reaches no texture of the vectors and passes."),
    KnownFault(
        "band-limit", check_names.RENDERER_FRICTION_ERROR, ("single-grating@flick",),
        2000.0, 10.0,
        "R10, A1: a component at or above the band limit B = 1000 Hz is silenced in the golden "
        "render. Raised by 2000 Hz, the band renders it in full (A1 ~ its amplitude over the "
        "mean, aliased by the 1 kHz reports) and fails; raised by 10 Hz (1 % of B) the fade "
        "moves by 1 % and passes."),
)
"""The faulty device's rows, device faults first."""

KNOWN_FAULTS_BY_NAME = {row.fault: row for row in KNOWN_FAULTS}

TABLE_HEADER = (
    "| Fault | Where | Strength | Check (`--check`) | Cases run | FAIL at | PASS at | Why |\n"
    "|---|---|---|---|---|---|---|---|\n")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table(control_catches: Mapping[str, tuple[str, str]]) -> str:
    """The known-fault table in Markdown: a row per fault of the faulty device, then a row per
    negative control of the reference device (``control:NAME``, spec QN1: one fault at one
    strength, the case it must fail), from ``control_catches`` (the reference device's
    ``controls.CATCHES``, given by the caller: this package does not import the reference
    device)."""
    lines = [TABLE_HEADER]
    for row in KNOWN_FAULTS:
        fault = row.info
        cases = ", ".join(f"`{r}`" for r in row.renders) or "every case"
        lines.append(
            f"| `faulty://{fault.name}` | {fault.where} | {_cell(fault.quantity)}, {fault.unit} "
            f"| `{row.check}` | {_cell(cases)} | {row.fails_at:g} {fault.unit} "
            f"| {row.passes_at:g} {fault.unit} | {_cell(row.why)} |\n")
    for name, (check, case) in sorted(control_catches.items()):
        lines.append(f"| `control:{name}` | reference device | its one defect | `{check}` "
                     f"| `{case}` | its defect | - | QN1: the defect and its measured value in "
                     "spec/conformance.md section 6 |\n")
    return "".join(lines)
