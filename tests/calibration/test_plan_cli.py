"""The calibration protocol and its commands: `hcard calibrate plan`, `hcard device synthesize`,
the base `hcard calibrate` takes from a recording, and profiles on `hcard play` and `hcard
render` (spec/calibration.md section 6, K14)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import hcard
from hcard.calibration.measurement import read_measurement, write_measurement
from hcard.calibration.plan import (
    EV_STAIRCASE,
    FORCES_N,
    SPEEDS_MM_S,
    VERIFY_EV,
    VERIFY_FORCES_N,
    VERIFY_SPEEDS_MM_S,
    VERIFY_UV,
    PlanError,
    protocol,
    verification,
)
from hcard.physics.profile import DeviceProfile
from hcard.render import Renderer
from hcard_device.sim.tribometer import Protocol, synthesize
from tests.helpers.cli import run_hcard as run


@pytest.mark.parametrize(("device", "lanes"), [
    ("uv", ("uv-staircase", "uv-steps")),
    ("ev", ("ev-staircase", "ev-square")),
    ("coupled", ("uv-staircase", "uv-steps", "ev-staircase", "ev-square", "bipolar")),
])
def test_the_protocol_covers_its_lanes_forces_and_speeds(device, lanes):
    plan = protocol(device, duration_s=60.0, seed=2)
    assert plan.lanes == lanes
    assert [p for p in hcard.validate(plan.card) if p.severity == "error"] == []
    sessions = plan.sessions
    assert {lane for lane, _, _ in sessions} == set(lanes)
    assert {force for _, force, _ in sessions} == set(FORCES_N)
    assert {s for _, _, pair in sessions for s in pair} == set(SPEEDS_MM_S)
    track = plan.track
    assert track.t[-1] >= 60.0
    # strokes along x at the session's speeds, lifts with no force between sessions
    touching = track.contact
    speed = np.abs(np.diff(track.x)) / np.diff(track.t)
    moving = touching[1:] & touching[:-1] & (speed > 0)
    nearest = np.min(np.abs(speed[moving, None] / np.array(SPEEDS_MM_S) - 1.0), axis=1)
    assert np.all(nearest < 0.05)  # each stroke at one of the speeds (a whole sample count)
    assert np.all(track.normal_force[~touching] == 0.0)
    lifts = np.count_nonzero(np.diff(touching.astype(int)) == -1)
    assert lifts == len(sessions)


def test_the_protocol_card_renders_its_levels_along_a_lane():
    plan = protocol("ev", duration_s=10.0)
    frames = Renderer(plan.card).render(plan.track)
    levels = np.unique(np.round(frames.ev[frames.contact], 4))
    assert set(np.round(EV_STAIRCASE, 4)) <= set(levels) | {1.0}


def test_the_verification_holds_out_levels_forces_and_speeds():
    plan = protocol("coupled", duration_s=60.0)
    check = verification("coupled")
    protocol_levels = {t.baseline for t in plan.card.textures}
    held_out = {t.baseline for t in check.card.textures} - {1.0}
    assert held_out and not held_out & protocol_levels
    assert set(VERIFY_UV[1::2]) | set(VERIFY_EV[1::2]) <= held_out | {1.0}
    assert {f for _, f, _ in check.sessions} == set(VERIFY_FORCES_N)
    assert not set(VERIFY_FORCES_N) & set(FORCES_N)
    assert not set(VERIFY_SPEEDS_MM_S) & set(SPEEDS_MM_S)


def test_plan_errors():
    with pytest.raises(PlanError, match="unknown device class 'tv'"):
        protocol("tv")
    with pytest.raises(PlanError, match="duration must be"):
        protocol("uv", duration_s=0.0)


def test_calibrate_plan_writes_cards_tracks_and_the_plan(tmp_path):
    result = run("calibrate", "plan", "--device", "uv", "--duration", "20s", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["plan.json", "protocol.csv", "protocol.hcard", "verify.csv", "verify.hcard"]
    described = json.loads((tmp_path / "plan.json").read_text())
    assert described["device"] == "uv" and described["protocol"]["duration_s"] >= 20.0
    assert hcard.load(tmp_path / "protocol.hcard").metadata.title.startswith("hcard calibration")
    assert "next: hcard play" in result.output
    bad = run("calibrate", "plan", "--device", "uv", "--duration", "5 kHz", "-o", tmp_path)
    assert bad.exit_code == 2 and "--duration" in bad.output  # a bad option value


def test_synthesize_plays_the_protocol_on_the_device(tmp_path):
    result = run("device", "synthesize", "--device", "ev", "--effect", "air-layer",
                 "--duration", "3s", "--seed", "2", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    m = read_measurement(tmp_path / "recording.csv")
    assert m.voltage is not None and m.voltage.max() > 1000.0  # through the amplifier
    assert m.column("target_ev").max() > 1.5 and m.contact.any()
    assert m.conditions["session"]["uri"] == "sim://coupled"
    assert "air" not in json.dumps(m.conditions)
    assert (tmp_path / "verify.hcard").exists()
    listing = run("device", "synthesize", "--list-effects")
    assert listing.exit_code == 0 and "air-layer" in listing.output


@pytest.mark.parametrize(("args", "message"), [
    (["--uri", "sim://coupled", "--effect", "air-layer"], "start it with `hcard device serve"),
    (["--device", "uv", "--effect", "air-layer"], "needs the coupled device, not evita"),
    (["--effect-param", "air-layer.gap=1um"], "no parameter 'gap'"),
    (["--duration", "three"], "--duration"),
])
def test_synthesize_option_errors_are_one_line_usage_errors(tmp_path, args, message):
    result = run("device", "synthesize", *args, "-o", tmp_path / "out")
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.output
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def device_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("synth")
    result = run("device", "synthesize", "--device", "ev", "--duration", "8s", "-o", out)
    assert result.exit_code == 0, result.output
    return out


def test_calibrate_takes_the_profile_the_recording_names(device_recording, tmp_path):
    result = run("calibrate", device_recording / "recording.csv", "-o", tmp_path, "-q",
                 "--no-figures", "--effect", "air-layer")
    assert result.exit_code == 0, result.output
    profile = DeviceProfile.load(tmp_path / "profile.json")
    assert profile.calibration["base"] == {"kind": "profile", "name": "coupled-stimulator",
                                           "voltage_form": "envelope"}
    assert profile.limits == DeviceProfile.coupled_stimulator().limits
    assert profile.observation["finger"]["model"] == "finger-friction"
    assert "held-out model error:" in result.output
    # an EV recording has no plate vibration: the profile's UV parameter moves no sample, so
    # it is held (fitted, it left the optimiser crawling at its evaluation cap) and says so
    report = json.loads((tmp_path / "report.json").read_text(encoding="utf-8"))
    assert "uv_psi_star" in report["after"]["held"]
    assert report["after"]["success"]
    # refits converge from the optimum (kept free, it capped 47 of 50 on a 30 s recording);
    # the few that crawl along a shallow direction are counted and stated
    boot = report["bootstrap"]
    assert boot["capped"] <= 0.2 * boot["samples"]
    assert (f"{boot['capped']} of the refits stopped" in report["uncertainty_method"]) == (
        boot["capped"] > 0)
    # the bootstrap does not resample it (a spread of 0 would read as exactly known)
    assert report["bootstrap"]["held"] == report["after"]["held"]
    assert report["bootstrap"]["uncertainties"]["uv_psi_star"] is None  # inf: JSON null
    assert "uv_psi_star" not in report["bootstrap"]["intervals_95"]
    assert "Held at their start values" in (tmp_path / "report.md").read_text(encoding="utf-8")
    # the same with --profile, and a bare predictor with --model
    own = tmp_path / "own.json"
    DeviceProfile.from_dict(read_measurement(device_recording / "recording.csv")
                            .conditions["profile"]["content"]).save(own)
    again = run("calibrate", device_recording / "recording.csv", "--profile", own, "-o",
                tmp_path / "again", "-q", "--no-figures", "--effect", "air-layer",
                "--bootstrap", "0")
    assert again.exit_code == 0, again.output
    assert DeviceProfile.load(tmp_path / "again" / "profile.json").calibration["base"][
        "kind"] == "profile"


def test_calibrate_refuses_what_it_cannot_take(device_recording, tmp_path):
    m = read_measurement(device_recording / "recording.csv")
    m.conditions["profile"] = {"source": "device", "name": None, "content": None}
    write_measurement(m, tmp_path / "anonymous.csv")
    cases = [
        ([tmp_path / "anonymous.csv"], "name no device profile"),
        ([device_recording / "recording.csv", "--model", "ev-kaczmarek", "--verify", "sim://"],
         "--verify plays a device profile"),
        ([device_recording / "recording.csv", "--model", "coupled", "--profile",
          tmp_path / "x.json"], "give --model or --profile, not both"),
        ([device_recording / "recording.csv", "--finger", "no-such-finger"], "no-such-finger"),
    ]
    for args, message in cases:
        result = run("calibrate", *args, "-o", tmp_path / "out", "-q")
        assert result.exit_code == 2, result.output  # what the command line must add or drop
        assert message in result.output and "Traceback" not in result.output
        assert not (tmp_path / "out").exists()


def test_calibrate_verify_needs_the_held_out_files(tmp_path):
    (recording,) = synthesize("ev", protocol=Protocol(duration_s=3.0), seed=1)
    write_measurement(recording, tmp_path / "tribometer.csv")
    result = run("calibrate", tmp_path / "tribometer.csv", "--profile",
                 tmp_path / "missing.json", "--verify", "sim://coupled", "-o", tmp_path / "out")
    assert result.exit_code == 1 and "missing.json: no such file" in result.output


def test_play_and_render_with_a_profile(device_recording, tmp_path):
    profile = DeviceProfile.coupled_stimulator().replace(
        predictor=DeviceProfile.coupled_stimulator().predictor.with_params(ev_area=5e-5))
    path = tmp_path / "p.json"
    profile.save(path)
    card, track = device_recording / "verify.hcard", device_recording / "verify.csv"
    played = run("play", card, "--track", track, "--device", "sim://coupled", "--profile", path,
                 "-o", tmp_path / "rec.csv")
    assert played.exit_code == 0, played.output
    assert "profile: coupled-stimulator (uploaded, sha256" in played.output
    assert "rendered friction error vs target: rms" in played.output
    assert read_measurement(tmp_path / "rec.csv").conditions["profile"]["source"] == "host"
    rendered = run("render", card, "--track", track, "--profile", path, "-o",
                   tmp_path / "frames.npz")
    assert rendered.exit_code == 0, rendered.output
    frames = np.load(tmp_path / "frames.npz")
    ev = frames["ev"] > 1.0
    assert ev.any()
    np.testing.assert_allclose(frames["rendered_ev"][ev], frames["ev"][ev], rtol=1e-9)
    plain = run("render", card, "--track", track, "--profile", path.with_name("none.json"),
                "-o", tmp_path / "f.csv")
    assert plain.exit_code == 1 and "none.json: no such file" in plain.output
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"format": "hcard-calibrated-profile/1"}))
    refused = run("play", card, "--track", track, "--device", "sim://coupled", "--profile", old,
                  "-o", tmp_path / "rec2.csv")
    assert refused.exit_code == 1 and "run 'hcard calibrate' on the recordings again" in \
        refused.output
    assert not (tmp_path / "rec2.csv").exists()
