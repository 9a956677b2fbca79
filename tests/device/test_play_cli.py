"""``hcard play``, ``hcard device list`` and ``hcard device serve`` on the command line."""

from __future__ import annotations

import os
import socket
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from hcard import build
from hcard.calibration.measurement import Measurement, read_measurement
from hcard.card_io import save
from hcard.cli.main import cli
from hcard.device.play import MAX_PLAY_S, TAIL_S
from hcard.device.protocol import FaultBits
from hcard.track import straight_stroke, track_to_csv
from tests.helpers.realtime import in_real_time, kept_run
from tests.helpers.served_device import served_device

pytestmark = pytest.mark.wall_clock


@pytest.fixture
def files(tmp_path):
    """The step card (plain glass left, UV friction 0.4 right) and a 0.4 s stroke at 40 mm/s
    from x = 2 mm to 18 mm, sampled at 50 Hz like a capacitive touch screen."""
    card = build.card(
        20.0, 10.0, taxtel_mm=10.0,
        textures=[build.texture(1.0, channel="uv", name="plain"),
                  build.texture(0.4, channel="uv", name="slippery")],
        texture_index=[0, 1], title="step",
    )
    save(card, tmp_path / "step.hcard")
    track = straight_stroke((2.0, 5.0), (40.0, 0.0), 0.4)
    (tmp_path / "stroke.csv").write_text(track_to_csv(track))
    return tmp_path


def play(files, uri: str, *extra: str):
    return CliRunner().invoke(cli, [
        "play", str(files / "step.hcard"), "--device", uri, "--track", str(files / "stroke.csv"),
        "-o", str(files / "rec.csv"), *extra,
    ])


def recording(files) -> Measurement:
    """The recording, read by the measurement reader (spec/measurement-format.md)."""
    return read_measurement(files / "rec.csv")


def column(m: Measurement, name: str) -> np.ndarray:
    """A column by quantity name, with positions in mm as the card's coordinates."""
    if name in ("x_mm", "y_mm"):
        return m.column(name[0]) * 1e3
    return m.column(name.removesuffix("_s").removesuffix("_n").removesuffix("_m"))


def test_play_on_sim_records_every_report(files):
    result = play(files, "sim://")
    assert result.exit_code == 0, result.output
    table = recording(files)
    # 0.4 s of track plus the tail, one report per millisecond of device time
    expected = round((0.4 + TAIL_S) * 1000)
    assert len(table) == pytest.approx(expected, abs=2)
    assert f"{len(table)} reports received, 0 lost in transit" in result.output
    assert np.all(np.diff(column(table, "t_s")) == pytest.approx(0.001))
    assert np.all(np.diff(column(table, "sequence")) % 65536 == 1)
    x, target = column(table, "x_mm"), column(table, "target_uv")
    assert x.min() == pytest.approx(2.0, abs=0.1) and x.max() == pytest.approx(18.0, abs=0.5)
    during = column(table, "t_s") < 0.4  # after it, the finger is dead-reckoned off the card
    assert np.all(target[during & (x > 3) & (x < 9)] == 1.0)
    assert np.all(target[during & (x > 11)] == pytest.approx(0.4))
    assert column(table, "fn_n")[10:].mean() == pytest.approx(0.5, abs=0.05)
    assert column(table, "amplitude_m")[x > 12].min() > 1e-7
    assert np.all(column(table, "faults") == 0) and "faults: none" in result.output
    assert "nothing clipped" in result.output
    # a moderate stroke through the device renders the target within the 8 % JND on average
    line = next(line for line in result.output.splitlines() if "friction error" in line)
    patch_error = float(line.split("rms ")[1].split(" ")[0])
    assert 0.0 < patch_error < 0.08


def test_play_on_sim_is_reproducible_for_a_seed(files):
    first = play(files, "sim://evita?seed=3")
    table = recording(files)
    second = play(files, "sim://evita?seed=3")
    assert first.exit_code == second.exit_code == 0
    again = recording(files)
    for name in ("t", "fn", "fl", "amplitude", "target_uv", "faults", "sequence"):
        assert np.array_equal(column(table, name), column(again, name)), name


def test_play_reports_a_card_the_device_clips(files):
    result = play(files, "sim://")
    assert result.exit_code == 0
    ev_card = build.card(10.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(2.0, channel="ev", name="sticky")], texture_index=[0])
    save(ev_card, files / "step.hcard")
    result = play(files, "sim://evita")  # E-ViTa has no EV
    assert result.exit_code == 0, result.output
    assert "clipped: 1 item(s) in 1 texture(s), e.g. texture 0 'sticky' EV asks 2.000" in \
        result.output
    assert "CARD_CLIPPED" in result.output
    assert np.all(column(recording(files), "faults").astype(int) & FaultBits.CARD_CLIPPED)


def test_play_over_usbip_in_real_time(files):
    def one_play() -> None:  # played again while the machine did not keep real time
        with served_device() as served, kept_run():
            result = play(files, served.uri)
            assert result.exit_code == 0, result.output
            table = recording(files)
            device_s = column(table, "t_s")[-1]
            assert device_s == pytest.approx(0.4 + TAIL_S, abs=0.05)  # real time
            assert len(table) == pytest.approx(device_s * 1000, rel=0.05)
            # during the stroke (after it, the renderer dead-reckons the finger off the card)
            during = column(table, "t_s") < 0.4
            x, target = column(table, "x_mm")[during], column(table, "target_uv")[during]
            assert np.all(target[x > 11] == pytest.approx(0.4))
            assert np.all(target[(x > 3) & (x < 9)] == 1.0)
            lost = int(result.output.split(" lost in transit")[0].rsplit(" ", 1)[1])
            assert lost <= 2

    in_real_time(one_play, "hcard play over usbip")


@pytest.mark.parametrize(("uri", "message", "status"), [
    ("usbip://127.0.0.1:port/1-1", "bad device URI 'usbip://127.0.0.1:port/1-1': port 'port'",
     2),
    ("bluetooth://device", "unknown scheme 'bluetooth'", 2),
    ("sim://nano", "unknown device 'nano' (known: evita, coupled)", 2),
    ("hid://1209:fffe", "no HID device 1209:fffe found", 1),
    ("hid:///dev/hidraw-none", "no such device node /dev/hidraw-none", 1),
    ("pyusb://127.0.0.1:{closed}/1-1", "cannot connect", 1),
    ("usbip://127.0.0.1:{closed}/1-1", "cannot connect (Connection refused)", 1),
])
def test_play_errors_are_one_line(files, uri, message, status):
    """A device URI that cannot mean anything is a bad option value (exit 2); one that names
    a device that cannot be reached is a failure (exit 1)."""
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        closed = probe.getsockname()[1]
    result = play(files, uri.format(closed=closed))
    assert result.exit_code == status
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and message in lines[0]
    assert "Traceback" not in result.output
    assert not (files / "rec.csv").exists()


def test_play_checks_its_arguments_before_the_device(files):
    result = play(files, "usbip://127.0.0.1:1/1-1", "-o", str(files / "rec.npz"))
    assert result.exit_code == 2 and "must end in .csv" in result.output
    (files / "step.hcard").write_bytes(b"not a card")
    result = play(files, "usbip://127.0.0.1:1/1-1")
    assert result.exit_code == 1 and "step.hcard" in result.output
    assert "cannot connect" not in result.output


def test_play_refuses_a_missing_profile_before_the_device(files):
    """The profile is read with the profile reader's own errors (one line naming the file)
    before a device is opened: the unreachable URI is never tried."""
    result = play(files, "usbip://127.0.0.1:1/1-1", "--profile", str(files / "missing.json"))
    assert result.exit_code == 1 and "missing.json: no such file" in result.output
    assert len(result.output.strip().splitlines()) == 1 and "cannot connect" not in result.output


def test_device_list_without_servers_lists_the_simulations():
    result = CliRunner().invoke(cli, ["device", "list", "--host", "127.0.0.1:1"])
    assert result.exit_code == 0, result.output
    uris = [line.split()[0] for line in result.output.splitlines()]
    assert uris[-2:] == ["sim://evita", "sim://coupled"]
    assert not any(uri.startswith(("usbip://", "pyusb://")) for uri in uris)


def test_device_list_finds_a_served_device():
    with served_device("coupled", cli=True) as served:
        assert "serving coupled at" in served.banner
        result = CliRunner().invoke(cli, ["device", "list", "--host",
                                          f"127.0.0.1:{served.port}", "--host", "127.0.0.1:1"])
        status, out = served.terminate()
    assert result.exit_code == 0, result.output
    rows = [line.split(None, 2) for line in result.output.splitlines()]
    assert [f"usbip://127.0.0.1:{served.port}/1-1", "usbip"] in [row[:2] for row in rows]
    assert [f"pyusb://127.0.0.1:{served.port}/1-1", "pyusb"] in [row[:2] for row in rows]
    assert status == 0 and "stopped after" in out


def test_device_list_rejects_a_bad_host():
    result = CliRunner().invoke(cli, ["device", "list", "--host", "127.0.0.1:http"])
    assert result.exit_code == 2 and "the port must be a number" in result.output


def test_device_serve_reports_a_busy_port_and_gives_back_what_it_took():
    """`hcard device serve` runs in the calling process: a serve that returned used to leave
    its main thread at SCHED_RR (root), so every process it started later inherited real-time
    scheduling (the CI failure of two `hcard play` taking turns in 100 ms slices); it gives
    back the scheduling and the switch interval it took."""
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
              os.getpriority(os.PRIO_PROCESS, 0), sys.getswitchinterval())
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        result = CliRunner().invoke(cli, ["device", "serve", "--port", str(port)])
    assert result.exit_code == 1
    assert f"cannot serve on 127.0.0.1:{port}" in result.output
    after = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
             os.getpriority(os.PRIO_PROCESS, 0), sys.getswitchinterval())
    assert after == before


def test_play_checks_the_output_directory_before_the_device(files):
    result = play(files, "usbip://127.0.0.1:1/1-1", "-o", str(files / "no" / "rec.csv"))
    assert result.exit_code == 1
    assert "cannot write (no directory" in result.output and "cannot connect" not in result.output


def test_play_refuses_a_track_longer_than_a_session_before_the_device(files):
    # a 100,000 s gap between two samples: 28 hours of reports, refused before any connection
    (files / "stroke.csv").write_text("t_s,x_mm,y_mm\n0,2,5\n0.02,3,5\n100000,4,5\n")
    result = play(files, "usbip://127.0.0.1:1/1-1")
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "stroke.csv: the track lasts 100000 s" in lines[0]
    assert f"at most {MAX_PLAY_S:.0f} s" in lines[0] and "cannot connect" not in lines[0]
    assert not (files / "rec.csv").exists()


def test_the_play_function_refuses_a_long_track_before_sending_anything():
    from hcard.device import PlayTooLong, open_device
    from hcard.device.play import play as play_track
    from hcard.track import make_track

    track = make_track(np.array([0.0, MAX_PLAY_S + 1.0]), np.array([2.0, 3.0]),
                       np.array([5.0, 5.0]), 0.5, True)
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")],
                      texture_index=[0, 0])
    with open_device("sim://evita") as driver:
        with pytest.raises(PlayTooLong, match="play it in parts"):
            play_track(driver, card, track)
        assert driver.upload_status().card_generation == 0  # no card was uploaded
