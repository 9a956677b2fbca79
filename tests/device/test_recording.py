"""A play session is a measurement recording (spec/measurement-format.md MF3, MF9, MF12): columns
by name in SI units, the finger's speed from the echoed track samples, and the sidecar of what
the device and the host know."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest

from hcard import build
from hcard.calibration.measurement import read_measurement, write_measurement
from hcard.calibration.splits import split_by_stroke, stroke_ids
from hcard.card_io import to_bytes
from hcard.device import open_device
from hcard.device.play import play, session_host_times
from hcard.device.protocol import PROTOCOL_MAJOR, PROTOCOL_MINOR
from hcard.device.recording import echoed_samples, recording, track_speeds
from hcard.physics.profile import DeviceProfile
from hcard.track import make_track, straight_stroke

CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="uv", name="plain"), build.texture(0.5, channel="uv", name="slip")],
    texture_index=[0, 1], title="step")


def back_and_forth() -> object:
    """2 mm -> 18 mm at 40 mm/s, then back at 80 mm/s, 100 Hz samples, 0.5 N."""
    there = np.linspace(2.0, 18.0, 41)
    back = np.linspace(18.0, 2.0, 21)[1:]
    x = np.concatenate([there, back])
    t = np.arange(x.size) * 0.01
    return make_track(t, x, np.full(x.size, 5.0), 0.5, True)


def test_the_recording_is_the_measurement_format_and_reads_back(tmp_path):
    track = back_and_forth()
    with open_device("sim://evita?seed=2") as driver:
        result = play(driver, CARD, track)
    m = recording(result, track_path="t.csv", card_path="c.hcard")
    write_measurement(m, tmp_path / "rec.csv")
    back = read_measurement(tmp_path / "rec.csv")
    header = (tmp_path / "rec.csv").read_text().splitlines()[0].split(",")
    assert header[:9] == ["t_s", "amplitude_m", "x_m", "y_m", "speed_m_s", "fn_n", "fl_n",
                          "stroke", "contact"]
    np.testing.assert_array_equal(back.stroke, m.stroke)
    assert "voltage_v" not in header  # the E-ViTa has no EV channel (rule MF5)
    for name in ("sequence", "faults", "target_uv", "texture", "echo", "f_tl", "current"):
        np.testing.assert_array_equal(back.column(name), m.column(name), err_msg=name)
    np.testing.assert_array_equal(back.contact, m.contact)
    # one report per millisecond of device time, sequences consecutive
    assert np.allclose(np.diff(back.t), 1e-3)
    assert np.all(np.diff(back.column("sequence")) % 65536 == 1)
    # the normal force is the sum of the four corner sensors
    corners = sum(back.column(c) for c in ("f_tl", "f_tr", "f_bl", "f_br"))
    np.testing.assert_allclose(back.normal_force, corners, atol=1e-12)


def test_speed_is_the_tracks_signed_speed_at_the_echoed_sample():
    track = back_and_forth()
    with open_device("sim://evita") as driver:
        m = recording(play(driver, CARD, track))
    moving = m.contact & (m.speed != 0)
    there = moving & (m.speed > 0)
    away = moving & (m.speed < 0)
    # independent: 16 mm in 0.4 s, then 16 mm back in 0.2 s
    assert np.allclose(m.speed[there], 0.040, rtol=1e-6)
    assert np.allclose(m.speed[away], -0.080, rtol=1e-6)
    assert there.sum() > 300 and away.sum() > 150


def test_a_stale_echo_of_the_previous_session_is_not_taken_for_this_ones():
    # A device that stays powered echoes the previous session's last sample until the first
    # FINGER of the next; the same track played again starts later on the host's clock, so
    # its host times differ and the stale echo names no sample of the new session.
    track = straight_stroke((2.0, 5.0), (40.0, 0.0), 0.3)
    first = session_host_times(10.0, track)
    second = session_host_times(10.0 + track.t[-1] + 0.5, track)
    assert not set(first.tolist()) & set(second.tolist())
    stale = [first[-1]] * 7
    fresh = np.repeat(second, 20)
    samples = echoed_samples(second, np.concatenate([stale, fresh]))
    assert np.all(samples[:7] == -1)
    np.testing.assert_array_equal(samples[7:], np.repeat(np.arange(len(track)), 20))
    assert echoed_samples(second, np.array([second[0], 12_345]))[1] == -1
    # a session starting at 0 on its clock never sends 0, the echo of "no sample yet"
    assert session_host_times(0.0, track)[0] == 1


def test_two_sessions_on_one_device_each_echo_their_own_samples():
    track = straight_stroke((2.0, 5.0), (40.0, 0.0), 0.2)
    with open_device("sim://evita") as driver:
        one, two = play(driver, CARD, track), play(driver, CARD, track)
    for result in (one, two):
        sample = echoed_samples(result.host_us, [s.host_time_echo_us for s in result.states])
        named = sample[sample >= 0]
        assert named.size > 150 and np.all(np.diff(named) >= 0)  # in order, this session's
    assert two.host_us[0] > one.host_us[-1]  # later on the host's clock


def test_strokes_follow_the_track_whatever_reports_are_lost():
    """Reports lost in transit leave gaps in the device's time stamps, which rule MS2 reads as
    new strokes; the recording takes each report's stroke from the track sample it echoes, so
    the strokes, and the split that holds whole strokes out, are those of the finger."""
    track = back_and_forth()
    with open_device("sim://evita") as driver:
        result = play(driver, CARD, track)
    whole = recording(result)
    lost = np.zeros(len(result.states), dtype=bool)
    lost[[*range(100, 140), *range(300, 320), *range(480, 530)]] = True  # 10-50 ms gaps
    lossy = recording(dataclasses.replace(
        result, states=[s for s, gone in zip(result.states, lost, strict=True) if not gone]))
    # independent: the track goes 2 -> 18 mm (stroke 0), then back (stroke 1)
    touching = whole.stroke >= 0
    assert set(whole.stroke[touching].tolist()) == {0, 1}
    assert np.all(whole.speed[whole.stroke == 0] >= 0)
    assert np.all(whole.speed[whole.stroke == 1] <= 0)
    np.testing.assert_array_equal(lossy.stroke, whole.stroke[~lost])
    assert stroke_ids(dataclasses.replace(lossy, stroke=None)).max() + 1 >= 4  # MS2 on the gaps
    # the split holds out the same stroke, whatever was lost
    _, test_whole = split_by_stroke(whole, seed=3)
    _, test_lossy = split_by_stroke(lossy, seed=3)
    assert set(whole.stroke[test_whole].tolist()) == set(lossy.stroke[test_lossy].tolist())


def test_track_speeds_of_a_lift_are_zero():
    track = make_track([0.0, 0.1, 0.2, 0.3], [0.0, 4.0, 8.0, 8.0], [0.0, 0.0, 3.0, 3.0],
                       0.5, [True, True, True, False])
    np.testing.assert_allclose(track_speeds(track), [0.0, 0.04, 0.05, 0.0])


def test_the_sidecar_holds_what_the_device_and_host_know():
    track = back_and_forth()
    with open_device("sim://coupled?seed=1") as driver:
        result = play(driver, CARD, track)
    conditions = recording(result, track_path="t.csv", card_path="c.hcard").conditions
    version = f"{PROTOCOL_MAJOR}.{PROTOCOL_MINOR}"  # the protocol the device reports (PV1)
    assert version == "1.4"  # spec/device-protocol.md, the version this firmware implements
    assert conditions["device"] == f"coupled UV+EV stimulator (hcard protocol {version})"
    assert conditions["firmware"]["protocol"] == version
    assert conditions["plate_frequency_hz"] == 38_220.0
    assert conditions["voltage_form"] == "envelope"
    assert conditions["carrier_frequency_hz"] == 440.0
    assert conditions["limits"] == pytest.approx(
        {"max_amplitude_m": 2.5e-6, "max_voltage_v": 2000.0, "max_current_a": 250e-6})
    assert conditions["card"]["sha256"] == hashlib.sha256(to_bytes(CARD)).hexdigest()
    assert conditions["card"]["title"] == "step" and conditions["card"]["path"] == "c.hcard"
    assert conditions["session"]["reports"] == len(result.states)
    assert conditions["session"]["track"] == "t.csv"
    profile = conditions["profile"]
    assert profile["source"] == "device" and profile["name"] == "coupled-stimulator"
    own = DeviceProfile.from_dict(profile["content"])
    assert own.predictor.params == DeviceProfile.coupled_stimulator().predictor.params
    json.dumps(conditions, allow_nan=False)  # a valid sidecar


def test_the_sidecar_records_the_limits_in_force_during_the_recording_not_before():
    """A second host lowers the amplitude limit halfway through the recording (sim:// names
    no origin, so the device carries it out, PN12): the sidecar records the limits in force
    at the recording's end, read back from the device, and those from its start beside them
    (spec/measurement-format.md MF9). Before, it recorded those read before START."""
    track = back_and_forth()
    with open_device("sim://evita?seed=3") as driver, driver.another_host() as other:
        send_finger = driver.send_finger
        sent = []

        def finger_then_lower(*args: object) -> None:
            send_finger(*args)  # type: ignore[arg-type]
            sent.append(args)
            if len(sent) == 30:
                other.set_limits(max_amplitude_m=1.0e-6)

        driver.send_finger = finger_then_lower  # type: ignore[method-assign]
        result = play(driver, CARD, track)
    conditions = recording(result).conditions
    assert conditions["limits"]["max_amplitude_m"] == pytest.approx(1.0e-6)
    assert conditions["limits_at_start"]["max_amplitude_m"] == pytest.approx(2.5e-6)
    # the plate obeyed the new limit from the change on (PS5: within 5 ms)
    amplitude = recording(result).column("amplitude")
    assert amplitude[-50:].max() <= 1.0e-6 + 1e-9
    json.dumps(conditions, allow_nan=False)


def test_the_sidecar_has_no_limits_at_start_when_the_limits_did_not_change():
    with open_device("sim://evita") as driver:
        result = play(driver, CARD, back_and_forth())
    assert "limits_at_start" not in recording(result).conditions


def test_an_uploaded_profile_is_named_by_its_digest():
    profile = DeviceProfile.coupled_stimulator().replace(name="fitted")
    data = profile.to_json()
    with open_device("sim://coupled") as driver:
        result = play(driver, CARD, back_and_forth(), profile=data)
    record = recording(result).conditions["profile"]
    assert record["source"] == "host" and record["name"] == "fitted"
    assert record["sha256"] == hashlib.sha256(data).hexdigest()
    assert record["content"]["format"] == "hcard-device-profile/2"


@pytest.mark.parametrize("enabled_before", [True, False])
def test_the_collector_rests_while_the_session_streams_and_is_restored(enabled_before):
    """A full collection in a large process pauses the host for 0.5 s, longer than the 32 ms
    of reports the device keeps: play() keeps the cyclic collector off while it streams and
    leaves it as it found it."""
    import gc

    seen: list[bool] = []
    with open_device("sim://evita") as driver:
        send = driver.send_finger

        def watched_send(*args, **kwargs):
            seen.append(gc.isenabled())
            return send(*args, **kwargs)

        driver.send_finger = watched_send
        (gc.enable if enabled_before else gc.disable)()
        try:
            result = play(driver, CARD, back_and_forth())
            after = gc.isenabled()
        finally:
            gc.enable()
    assert len(seen) == 61 and not any(seen)
    assert after is enabled_before
    assert len(result.states) > 500
