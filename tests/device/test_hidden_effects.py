"""Physical effects hidden in the simulated hardware (hcard_device.sim.hidden): the physics of
their own model, switched on from the command line and the URI, and never named by the device."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from hcard import build
from hcard.card_io import save as hcard_save
from hcard.cli.main import cli
from hcard.device import open_device
from hcard.device.errors import UriError
from hcard.device.play import play
from hcard.device.recording import recording
from hcard.device.uri import parse_uri
from hcard.track import make_track
from hcard_builtins.physics.electrovibration import AirLayer
from hcard_device.sim.hidden import HIDDEN_EFFECTS, HiddenEffectError, parse_assignments, resolve

EV_CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="ev", name="plain"), build.texture(1.1, channel="ev", name="ev")],
    texture_index=[0, 1])


def slow_stroke(force: float) -> object:
    x = np.linspace(2.0, 18.0, 81)
    return make_track(np.arange(x.size) * 0.01, x, np.full(x.size, 5.0), force, True)


def ev_patch(uri: str, force: float) -> tuple[float, float, float]:
    """(median voltage, mean measured lateral/normal on the EV patch, on the plain patch)."""
    with open_device(uri) as driver:
        m = recording(play(driver, EV_CARD, slow_stroke(force)))
    settled = m.contact & (m.t > 0.05)
    on = settled & (m.device["target_ev"] > 1.0)
    off = settled & (m.device["target_ev"] == 1.0) & (m.x < 0.009)
    mu = m.lateral_force / m.normal_force
    return float(np.median(m.voltage[on])), float(mu[on].mean()), float(mu[off].mean())


@pytest.mark.parametrize("force", [0.3, 0.6])
def test_the_hidden_air_layer_is_eq_3_17_on_the_recorded_voltage(force):
    voltage, ev_mu, plain_mu = ev_patch("sim://coupled?seed=3&effect=air-layer", force)
    own_voltage, own_ev, own_plain = ev_patch("sim://coupled?seed=3", force)
    assert voltage == pytest.approx(own_voltage, rel=0.01)  # the firmware does not know
    # the rendered EV friction, independently from Eq. 3.17 with the section 3.6.1 contact
    # (A = 1 cm^2, 200 um stratum corneum at 1560, 90 um film at 3.35) and d_a = 10 um / Fn,
    # against Eq. 3.12 (no air) on the same device, seed and stroke: the finger's own drift
    # (occlusion over the stroke) is the same in both and cancels in the ratio
    # leakage at the 440 Hz carrier: |H| of Eq. 3.22's high pass with tau_d(440 Hz), the
    # section 3.6.3 tau_d of 7.7 ms at 10 Hz scaled by the Fig. 3.13 power law (slope -0.7)
    tau_d = 7.7e-3 * (440.0 / 10.0) ** -0.7
    omega_tau = 2.0 * math.pi * 440.0 * tau_d
    gain = omega_tau / math.sqrt(1.0 + omega_tau**2)
    layers = {"area": 1e-4, "sc_thickness": 200e-6, "sc_permittivity": 1560.0,
              "insulator_thickness": 90e-6, "insulator_permittivity": 3.35}
    effective = gain * voltage / math.sqrt(2.0)
    with_air = 1.0 + float(AirLayer(**layers).forward(voltage=effective,
                                                        air_gap=10e-6 / force)) / force
    without = 1.0 + float(AirLayer(**layers).forward(voltage=effective, air_gap=0.0)) / force
    measured = (ev_mu / plain_mu) / (own_ev / own_plain)
    assert measured == pytest.approx(with_air / without, abs=0.005)
    assert with_air / without < 0.97  # the effect is large enough to matter
    # no effect: about the target (the finger's occlusion over the stroke adds ~2 %)
    assert own_ev / own_plain == pytest.approx(1.1, abs=0.03)


def test_effects_from_the_uri():
    uri = parse_uri("sim://coupled?effect=air-layer&air-layer.air_gap=8um")
    assert uri.effects == {"air-layer": {"air_gap": pytest.approx(8e-6)}}
    assert parse_uri("sim://coupled?air-layer.air_gap=4um").effects == {
        "air-layer": {"air_gap": pytest.approx(4e-6)}}
    assert parse_uri("sim://coupled").effects == {}
    loop = parse_uri("usbip://loopback?device=coupled&effect=air-layer")
    assert loop.effects == {"air-layer": {"air_gap": pytest.approx(10e-6)}}


@pytest.mark.parametrize(
    ("uri", "message"),
    [
        ("sim://evita?effect=air-layer", "needs the coupled device, not evita"),
        ("sim://coupled?effect=magic", "unknown hidden effect 'magic'"),
        ("sim://coupled?air-layer.gap=1um", "no parameter 'gap'"),
        ("sim://coupled?air-layer.air_gap=1kHz", "not a unit of m"),
        ("sim://coupled?air-layer.air_gap=-1um", "outside its bounds"),
        ("usbip://127.0.0.1:3240/1-1?effect=air-layer", "options apply to loopback only"),
    ],
)
def test_bad_effects_in_a_uri_are_named(uri, message):
    with pytest.raises(UriError, match=message):
        parse_uri(uri)


def test_assignments_and_resolution():
    assert parse_assignments(["air-layer"], []) == {"air-layer": {}}
    assert resolve("coupled", {"air-layer": {}}) == {"air-layer": {"air_gap": 10e-6}}
    with pytest.raises(HiddenEffectError, match=r"expected EFFECT\.PARAM=VALUE"):
        parse_assignments([], ["air_gap=1um"])


def test_nothing_the_device_says_names_the_effect():
    card = EV_CARD
    with open_device("sim://coupled?effect=air-layer&air-layer.air_gap=12um") as hidden, \
            open_device("sim://coupled") as plain:
        assert hidden.info() == plain.info()
        assert hidden.limits() == plain.limits()
        result = play(hidden, card, slow_stroke(0.5))
    conditions = recording(result).conditions
    text = json.dumps(conditions).lower()
    assert "air-layer" not in text and "air_gap" not in text and "12um" not in text
    assert conditions["session"]["uri"] == "sim://coupled"
    assert conditions["profile"]["content"]["effects"] == []  # the device's own profile


def test_serve_lists_and_checks_effects():
    listing = CliRunner().invoke(cli, ["device", "serve", "--list-effects"])
    assert listing.exit_code == 0
    lines = listing.output.splitlines()
    assert [line.split(" ", 1)[0] for line in lines] == list(HIDDEN_EFFECTS)
    assert "air-layer (coupled; air_gap=1e-05 m): air between" in listing.output
    assert "force-sensor-resonance (evita/coupled; natural_frequency=150 Hz, " in listing.output
    refused = CliRunner().invoke(cli, ["device", "serve", "--device", "evita", "--effect",
                                       "air-layer", "--port", "0"])
    assert refused.exit_code == 2  # a bad option value (README: exit status)
    assert "effect air-layer needs the coupled device, not evita" in refused.output
    malformed = CliRunner().invoke(cli, ["device", "serve", "--effect-param", "air-layer=1"])
    assert malformed.exit_code == 2 and "expected EFFECT.PARAM=VALUE" in malformed.output


def assignment(name: str) -> str:
    """``NAME.PARAM=VALUE`` of the effect's first parameter, at a value off its default."""
    parameter = HIDDEN_EFFECTS[name].parameters[0]
    low, high = parameter.bounds
    value = parameter.default * 0.9 if parameter.default else 0.5 * (low + high)
    return f"{name}.{parameter.name}={value!r}"


@pytest.mark.parametrize("name", sorted(HIDDEN_EFFECTS))
def test_every_effect_is_served_from_the_uri_and_the_command_line(name):
    from hcard_device.device_cmd import hidden_effects

    text = assignment(name)
    key, value = text.split("=")
    parameter = key.split(".", 1)[1]
    uri = parse_uri(f"sim://coupled?seed=1&effect={name}&{text}")
    assert uri.effects[name][parameter] == pytest.approx(float(value))
    assert set(uri.effects[name]) == {p.name for p in HIDDEN_EFFECTS[name].parameters}
    assert hidden_effects((name,), (text,), "coupled") == {name: {parameter: float(value)}}
    if "evita" in HIDDEN_EFFECTS[name].devices:
        assert parse_uri(f"sim://evita?effect={name}").effects[name]
    else:
        with pytest.raises(UriError, match=f"effect {name} needs the coupled device, not evita"):
            parse_uri(f"sim://evita?effect={name}")


def test_several_effects_at_once_through_a_served_device_and_the_pressure_in_the_sidecar():
    effects = "squeeze-film-share,force-sensor-resonance,plate-load-damping,charge-leakage"
    query = f"device=coupled&seed=3&effect={effects}&ambient_pressure=50kPa"
    uv_card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(0.6, channel="uv", name="uv"), build.texture(1.3, channel="ev", name="ev")],
        texture_index=[0, 1])
    with open_device(f"usbip://loopback?{query}") as hidden:
        m = recording(play(hidden, uv_card, slow_stroke(0.5)))
    with open_device("usbip://loopback?device=coupled&seed=3") as plain:
        own = recording(play(plain, uv_card, slow_stroke(0.5)))
    # the device's own profile names its own models (its leakage at the carrier is
    # "ev-charge-leakage"), never a hidden effect; nothing else names one
    assert m.conditions["profile"]["content"]["effects"] == []
    text = json.dumps({k: v for k, v in m.conditions.items() if k != "profile"}).lower()
    for name in effects.split(","):
        assert name not in text
    assert "?" not in m.conditions["session"]["uri"]
    assert m.conditions["ambient_pressure_pa"] == pytest.approx(50e3)
    assert "ambient_pressure_pa" not in own.conditions
    def uv_patch(rec):  # the mean lateral force on the UV patch (x < 9 mm), N
        return float(np.mean(rec.lateral_force[rec.contact & (rec.t > 0.05) & (rec.x < 0.009)]))

    # less of the reduction at half an atmosphere and under the finger's load
    assert uv_patch(m) > uv_patch(own) + 0.01


def test_the_ambient_pressure_is_checked():
    with pytest.raises(UriError, match="not a unit of Pa"):
        parse_uri("sim://coupled?ambient_pressure=3mm")
    with pytest.raises(UriError, match="must be a pressure > 0"):
        parse_uri("sim://coupled?ambient_pressure=0")
    assert parse_uri("sim://coupled?ambient_pressure=0.5atm").ambient_pressure_pa == (
        pytest.approx(50662.5))
    refused = CliRunner().invoke(cli, ["device", "serve", "--ambient-pressure", "1kHz",
                                       "--port", "0"])
    assert refused.exit_code == 2 and "--ambient-pressure" in refused.output


def test_hcard_play_keeps_the_pressure_the_lab_measured(tmp_path):
    """A served or real device cannot know the air around its plate; the lab states what it
    measured (`hcard play --ambient-pressure`) and the recording keeps it, where the device's
    own URI states none."""
    card = tmp_path / "c.hcard"
    hcard_save(build.card(20.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.6, channel="uv")]),
               card)
    track = tmp_path / "t.csv"
    track.write_text("t_s,x_mm,y_mm,fn_n,contact\n0,2,5,0.5,1\n0.1,6,5,0.5,1\n0.2,10,5,0.5,1\n")
    out = tmp_path / "rec.csv"
    played = CliRunner().invoke(cli, ["play", str(card), "--track", str(track), "--device",
                                      "usbip://loopback?device=evita", "-o", str(out), "-q",
                                      "--ambient-pressure", "85kPa"])
    assert played.exit_code == 0, played.output
    assert json.loads((tmp_path / "rec.csv.json").read_text())["ambient_pressure_pa"] == (
        pytest.approx(85e3))
    refused = CliRunner().invoke(cli, ["play", str(card), "--track", str(track), "--device",
                                       "sim://evita", "-o", str(out), "--ambient-pressure",
                                       "3 s"])
    assert refused.exit_code == 2 and "--ambient-pressure" in refused.output
