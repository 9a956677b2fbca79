"""Format and renderer levels: the reference conforms, deliberately wrong renderers do not."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from hcard.render import Frames, RenderOptions, render
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb
from hcard_conformance.context import Context
from hcard_conformance.result import CheckResult
from hcard_conformance.runner import SuiteReport, run_suite
from hcard_conformance.vectors import load_manifest

MANIFEST = load_manifest()


def by_check(report: SuiteReport, name: str) -> dict[str, CheckResult]:
    """Results of check ``name`` by case."""
    return {r.case: r for r in report.results if r.check == name}


@pytest.fixture(scope="module")
def reference_report() -> SuiteReport:
    return run_suite(Context.for_driver("reference"), ("format", "renderer"))


def test_reference_passes_format_and_renderer_levels(reference_report: SuiteReport) -> None:
    assert reference_report.failures == []
    assert reference_report.exit_code == 0
    parse = by_check(reference_report, "format.parse")
    assert len(parse) == 2 * len(MANIFEST.cards)
    assert len(by_check(reference_report, "format.round_trip")) == len(MANIFEST.cards)
    assert len(by_check(reference_report, "format.reject")) == len(MANIFEST.invalid)
    exact = by_check(reference_report, "renderer.exact")
    assert sorted(exact) == sorted(e.name for e in MANIFEST.renders)
    assert all(r.metric == "A0" and r.value <= 1e-5 and r.threshold == 1e-5
               for r in exact.values())
    a1 = by_check(reference_report, "renderer.friction_error")
    assert len(a1) == len(MANIFEST.renders)
    assert max(r.value for r in a1.values()) < 1e-6
    # tag selection (spec Q6): A2/A3 on dense/oriented/temporal/bipolar, A4 on coarse/sparse
    a2 = by_check(reference_report, "renderer.component_amplitude")
    assert "temporal@slow-stroke" in a2 and "edge@slow-stroke" not in a2
    assert max(r.value for r in a2.values()) < 1e-9
    a4 = by_check(reference_report, "renderer.spatial_phase")
    assert set(a4) <= {e.name for e in MANIFEST.renders
                       if e.card in ("coarse-grating", "edge", "button")}
    assert "coarse-grating@slow-stroke" in a4
    a5 = by_check(reference_report, "renderer.boundary")
    assert "checkerboard@moderate-stroke" in a5 and "single-grating@slow-stroke" not in a5


def _scaled(card: pb.Card, track: FingerTrack, options: RenderOptions) -> Frames:
    """The golden render with 10% too much UV friction."""
    frames = render(card, track, options)
    return Frames(frames.t, frames.uv * 1.1, frames.ev, frames.contact, frames.texture)


def test_ten_percent_friction_error_fails_a0_and_a1() -> None:
    ctx = Context("scaled", renderer=_scaled)
    report = run_suite(ctx, ("renderer",), select=("renderer.exact", "renderer.friction_error"))
    exact = by_check(report, "renderer.exact")
    a1 = by_check(report, "renderer.friction_error")
    assert len(exact) == len(a1) == len(MANIFEST.renders)
    assert not any(r.passed for r in exact.values())
    assert not any(r.passed for r in a1.values())
    grating = exact["single-grating@moderate-stroke"]
    # the grating peaks at friction 0.9: 10% of it
    assert grating.value == pytest.approx(0.09, abs=2e-3)
    for r in a1.values():
        assert r.metric == "A1" and r.threshold == 0.08
        assert 0.08 < r.value <= 0.1 + 1e-9, r


def _position_only(card: pb.Card, track: FingerTrack, options: RenderOptions) -> Frames:
    return render(card, track, RenderOptions(frame_rate_hz=options.frame_rate_hz,
                                             band_limit_hz=options.band_limit_hz,
                                             mode="position-only"))


def test_position_only_renderer_fails_dense_and_keeps_coarse_in_place() -> None:
    ctx = Context("position-only", renderer=_position_only)
    report = run_suite(ctx, ("renderer",))
    a1 = by_check(report, "renderer.friction_error")
    a2 = by_check(report, "renderer.component_amplitude")
    a4 = by_check(report, "renderer.spatial_phase")
    for name in ("single-grating@moderate-stroke", "single-grating@fast-stroke",
                 "bipolar-grating@moderate-stroke"):
        assert not a1[name].passed and a1[name].value > 0.3, a1[name]
        assert not a2[name].passed and a2[name].value > 0.2, a2[name]
    # a 100 Hz grating held at one phase per 20 ms touch sample loses its spectral peak
    assert "amplitude 0.0000" in a2["single-grating@moderate-stroke"].detail
    for name in ("coarse-grating@slow-stroke", "coarse-grating@moderate-stroke"):
        assert a4[name].passed and a4[name].value <= 2.5, a4[name]
    assert report.exit_code == 1


def test_sim_device_passes_renderer_level() -> None:
    report = run_suite(Context.for_driver("sim://"), ("renderer",))
    assert report.failures == []
    assert "renderer.exact" in report.not_applicable  # a driver is not frame exact (A0)
    a1 = by_check(report, "renderer.friction_error")
    assert len(a1) == len(MANIFEST.renders)
    # reports at 1 kHz, quantised to 1e-4, interpolated: well inside the 8% JND
    assert max(r.value for r in a1.values()) < 0.06
    assert by_check(report, "renderer.component_amplitude")["single-grating@slow-stroke"].value \
        < 0.01


def test_position_only_driver_fails_dense_but_not_coarse_slow_and_moderate() -> None:
    ctx = Context.for_driver("control:position-only", options={"renders": [
        "single-grating@moderate-stroke", "coarse-grating@slow-stroke",
        "coarse-grating@moderate-stroke"]})
    report = run_suite(ctx, ("renderer",))
    a1 = by_check(report, "renderer.friction_error")
    assert not a1["single-grating@moderate-stroke"].passed
    assert a1["single-grating@moderate-stroke"].value > 0.3
    a4 = by_check(report, "renderer.spatial_phase")
    assert set(a4) == {"coarse-grating@slow-stroke", "coarse-grating@moderate-stroke"}
    assert all(r.passed and r.value < 2.5 for r in a4.values())


@pytest.fixture
def vectors_copy(tmp_path: Path) -> Path:
    """A writable copy of spec/vectors."""
    target = tmp_path / "vectors"
    shutil.copytree(MANIFEST.root, target)
    return target


def test_accepted_invalid_vector_fails_rejection(vectors_copy: Path) -> None:
    manifest = load_manifest(vectors_copy)
    victim = manifest.invalid[0]
    victim.file.write_bytes(manifest.cards[0].binary.read_bytes())
    report = run_suite(Context.for_driver("reference", vectors_root=vectors_copy), ("format",))
    reject = by_check(report, "format.reject")
    assert not reject[victim.name].passed
    assert reject[victim.name].value == 1.0
    assert "accepted" in reject[victim.name].detail
    assert sum(not r.passed for r in report.results) == 1


def test_round_trip_mismatch_and_invalid_card_are_caught(vectors_copy: Path) -> None:
    manifest = load_manifest(vectors_copy)
    first, second = manifest.cards[0], manifest.cards[1]
    # a JSON file describing another card: both files still parse, the round trip breaks
    first.json.write_bytes(second.json.read_bytes())
    report = run_suite(Context.for_driver("reference", vectors_root=vectors_copy), ("format",),
                       select=("format.round_trip",))
    trip = by_check(report, "format.round_trip")
    assert not trip[first.name].passed
    assert trip[first.name].value == 2.0  # json->binary and binary->json differ
    assert trip[second.name].passed and trip[second.name].value == 0.0


def test_frame_count_mismatch_is_infinite_a0() -> None:
    def short(card: pb.Card, track: FingerTrack, options: RenderOptions) -> Frames:
        f = render(card, track, options)
        return Frames(f.t[:-1], f.uv[:-1], f.ev[:-1], f.contact[:-1], f.texture[:-1])

    ctx = Context("short", renderer=short, options={"renders": ["edge@slow-stroke"]})
    report = run_suite(ctx, ("renderer",), select=("renderer.exact",))
    (result,) = report.results
    assert not result.passed and result.value == np.inf


def test_renders_given_as_text_are_whole_case_names() -> None:
    """``--option renders=A,B`` arrives as text: the renders named, comma-separated, each a
    whole case name (a name inside another, or a misspelt one, selects nothing)."""
    from hcard_conformance.check_names import RENDERER_EXACT
    from hcard_conformance.renderer_level import applicable_entries

    def chosen(text: str) -> list[str]:
        ctx = Context.for_driver("reference", options={"renders": text})
        return [e.name for e in applicable_entries(ctx, RENDERER_EXACT)]

    assert chosen("edge@fast-stroke,coarse-grating@slow-stroke") == [
        "edge@fast-stroke", "coarse-grating@slow-stroke"]
    assert chosen("xedge@slow-stroke") == []
