"""Spec rule QC1: every rule of the card format, the rendering equation and the device protocol
is reached by a vector and a check, or declared a gap (spec/conformance.md section 8).

The table is read from the spec as text and held against the rules the documents define
(:func:`tests.repository.test_spec_rule_ids.definitions`), the vectors of the manifest and the
checks of the registry. Two rules the suite once could not reach, R8 and R10, are also checked
for what their vectors do, computed here from the track files and the card alone.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from hcard import card_io
from hcard.v1 import card_pb2 as pb
from hcard_conformance.registry import all_checks
from hcard_conformance.vectors import load_manifest
from tests.helpers.repository import REPO
from tests.repository.test_spec_rule_ids import definitions

SPEC = REPO / "spec"
VECTORS = SPEC / "vectors"
COVERED_DOCUMENTS = ("README.md", "device-protocol.md")
"""The documents whose rules bind a reader, renderer or device (QC1)."""
NONE = "—"
EDITORIAL = "(editorial)"
_TICKED = re.compile(r"`([^`]+)`")
_RULE = re.compile(r"\b([A-Z]{1,2}[0-9]+[a-z]?)(?:-([A-Z]{1,2})?([0-9]+))?\b")


def coverage_rows(text: str) -> dict[str, tuple[str, str]]:
    """Rule -> (vectors cell, checks cell) of the table of section 8; a rule listed twice
    raises."""
    section = text[text.index("## 8. Coverage"):]
    rows: dict[str, tuple[str, str]] = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("| ") or len(cells) != 4 or cells[0] in ("Document", "---"):
            continue
        rule = cells[1]
        if rule in rows:
            raise ValueError(f"rule {rule} has two rows")
        rows[rule] = (cells[2], cells[3])
    return rows


def listed_rules(paragraph: str) -> set[str]:
    """The rule identifiers a paragraph names, ranges such as PN12-PN15 expanded."""
    found: set[str] = set()
    for first, prefix, last in _RULE.findall(paragraph):
        found.add(first)
        if last:
            head = re.match(r"[A-Z]+", first)
            assert head is not None
            start = int(first[head.end():])
            found |= {f"{prefix or head.group()}{n}" for n in range(start + 1, int(last) + 1)}
    return found


def declared(text: str, lead: str, stop: str) -> set[str]:
    """The rules named between ``lead`` and ``stop`` in section 8."""
    section = text[text.index("## 8. Coverage"):]
    start = section.index(lead)
    return listed_rules(section[start + len(lead):section.index(stop, start)])


def uncovered(rows: dict[str, tuple[str, str]]) -> tuple[set[str], set[str]]:
    """(gaps, editorial): the rows with neither vectors nor checks, apart and marked editorial."""
    gaps = {rule for rule, (v, c) in rows.items() if v == NONE and c == NONE}
    editorial = {rule for rule, (v, c) in rows.items() if v == NONE and c == EDITORIAL}
    return gaps, editorial


SPEC_TEXT = (SPEC / "conformance.md").read_text(encoding="utf-8")
ROWS = coverage_rows(SPEC_TEXT)
MANIFEST = load_manifest(VECTORS)


def _defined_rules() -> list[str]:
    return [rule for name in COVERED_DOCUMENTS
            for rule in definitions((SPEC / name).read_text(encoding="utf-8"))]


def test_every_rule_of_the_covered_documents_has_one_row() -> None:
    defined = _defined_rules()
    assert len(defined) > 100
    missing = [rule for rule in defined if rule not in ROWS]
    assert not missing, f"rules without a row in spec/conformance.md section 8: {missing}"
    extra = sorted(set(ROWS) - set(defined))
    assert not extra, f"rows for rules the documents do not define: {extra}"


def test_every_named_vector_and_check_exists() -> None:
    vectors = ({c.name for c in MANIFEST.cards} | {t.name for t in MANIFEST.tracks}
               | {i.name for i in MANIFEST.invalid}
               | {f"compat/{c.file.name}" for c in MANIFEST.compat}
               | {f"{r.card}@{r.track}" for r in MANIFEST.renders})
    checks = {c.name for c in all_checks(plugins=False)}
    for rule, (vector_cell, check_cell) in ROWS.items():
        for name in _TICKED.findall(vector_cell):
            assert name in vectors, f"{rule}: no vector {name!r}"
        for name in _TICKED.findall(check_cell):
            assert name in checks, f"{rule}: no check {name!r}"
        if check_cell not in (NONE, EDITORIAL):
            assert _TICKED.findall(check_cell) or check_cell.startswith("every device check"), \
                f"{rule}: the checks cell names no check: {check_cell!r}"


def test_a_rule_without_vectors_or_checks_is_a_declared_gap() -> None:
    """QC1: the rows that reach nothing are exactly the gaps the spec declares; covering one
    (or losing the coverage of another) without updating the declaration fails."""
    gaps, editorial = uncovered(ROWS)
    assert gaps == declared(SPEC_TEXT, "**Gaps (not reached yet).**", "| Document |") - editorial
    assert editorial == {"V6", "V7", "V8", "PV4", "PV5"}
    assert "R8" not in gaps and "R10" not in gaps and "PU3" not in gaps


def test_the_scanners_catch_planted_mistakes() -> None:
    twice = SPEC_TEXT + "| README | R8 | — | — |\n"
    with pytest.raises(ValueError, match="R8 has two rows"):
        coverage_rows(twice)
    r10_checks = "`renderer.exact`, `renderer.friction_error` |\n| README | R11"
    dropped = coverage_rows(SPEC_TEXT.replace("| R10 | `single-grating@flick`", "| R10 | —")
                            .replace(r10_checks, "— |\n| README | R11"))
    assert "R10" in uncovered(dropped)[0]
    assert listed_rules("PN12-PN15 and PD1, PD2") == {"PN12", "PN13", "PN14", "PN15", "PD1",
                                                     "PD2"}


# ------------------------------------------------------------------- what R8 and R10 reach


def _track(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(t, x) of a vector track, read from its CSV."""
    lines = (VECTORS / "tracks" / f"{name}.csv").read_text(encoding="utf-8").splitlines()
    header = next(line for line in lines if not line.startswith("#"))
    assert header.startswith("t_s,x_mm,")
    rows = np.loadtxt(lines[lines.index(header) + 1:], delimiter=",", usecols=(0, 1), ndmin=2)
    return rows[:, 0], rows[:, 1]


def _card(name: str) -> pb.Card:
    return card_io.load(VECTORS / "cards" / f"{name}.hcard")


def test_the_flick_plays_the_grating_at_or_above_the_band_limit() -> None:
    """R10: from the second sample on, every velocity estimate (R4, finite differences here)
    puts the 1 mm grating at or above B, where the golden render has no grating left."""
    entry = next(r for r in MANIFEST.renders if (r.card, r.track) == ("single-grating", "flick"))
    (component,) = _card("single-grating").textures[0].components
    t, x = _track("flick")
    temporal_hz = component.frequency * np.abs(np.diff(x) / np.diff(t))
    assert temporal_hz.min() >= entry.band_limit_hz
    golden = np.load(VECTORS / entry.npz)
    after = golden["t_s"] >= t[1]
    assert np.ptp(golden["friction"][after & golden["contact"]]) < 1e-12


def test_the_scrub_takes_a_velocity_locked_odometer_off_by_more_than_a4() -> None:
    """R8: the coarse grating is position-locked, and on the scrub an odometer (R4: each step
    the previous velocity times the interval) ends a leg more than A4's 2.5 mm away from the
    finger, a quarter period of the grating."""
    texture = _card("coarse-grating").textures[0]
    assert texture.locking == pb.LOCKING_POSITION
    period_mm = 1.0 / texture.components[0].frequency
    t, x = _track("scrub")
    dt, dx = np.diff(t), np.diff(x)
    v = dx / dt
    odometer = np.concatenate(([x[0], x[1]], x[1] + np.cumsum(v[:-1] * dt[1:])))
    offset = np.abs(odometer - x)
    assert np.count_nonzero(np.diff(np.sign(v)) != 0) >= 3  # three reversals
    assert offset.max() >= 4 * 2.5 and math.isclose(offset.max(), period_mm / 4, rel_tol=1e-6)
