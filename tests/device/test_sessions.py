"""Sessions and ownership (spec/device-protocol.md section 14, protocol 1.2): the firmware's
rules PN1-PN7 and PN11, the drivers' PN8-PN9, two clients of one device served in another
process (PN10), and ``hcard play`` losing its session."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hcard import build
from hcard.calibration.measurement import read_measurement
from hcard.card_io import save, to_bytes
from hcard.device import open_device
from hcard.device.errors import DeviceError, SessionBusy, SessionLost
from hcard.device.play import play
from hcard.device.protocol import (
    Command,
    Control,
    FaultBits,
    State,
    StateFlags,
    UploadResult,
    UploadState,
    UploadStatus,
    decode_input,
    upload_reports,
)
from hcard.device.protocol.constants import ReportId, UploadAction
from hcard.track import straight_stroke, track_to_csv
from hcard_device.usb.server import make_firmware
from tests.helpers.realtime import NotKept, in_real_time, kept_run
from tests.helpers.served_device import served_device

pytestmark = pytest.mark.wall_clock

CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="uv"), build.texture(0.4, channel="uv")], texture_index=[0, 1])
OTHER_CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="uv"), build.texture(0.2, channel="uv")], texture_index=[0, 1])
BUSY = int(FaultBits.SESSION_BUSY | FaultBits.INVALID_REQUEST)


# ---------------------------------------------------------------------- firmware (PN1-PN7)

def firmware():
    """A fresh E-ViTa firmware run for 10 ms (its first reports taken)."""
    fw = make_firmware("evita")
    fw.advance(0.01)
    fw.take_input_reports()
    return fw


def control(fw, command: Command, argument: int = 0, run_s: float = 0.002) -> list[State]:
    """Send CONTROL, run ``run_s`` of device time, return the reports of that time."""
    fw.handle_output(Control(int(command), argument).encode())
    return run(fw, run_s)


def run(fw, seconds: float) -> list[State]:
    fw.advance(seconds)
    return [decode_input(r) for r in fw.take_input_reports()]


def session(state: State) -> tuple[int, int, bool]:
    return state.session_number, state.session_token, bool(state.flags & StateFlags.SESSION)


def upload(fw, card) -> UploadStatus:
    """Upload ``card`` with COMMIT through the feature path; the final UPLOAD_STATUS."""
    for report in upload_reports(to_bytes(card), UploadAction.COMMIT):
        fw.set_feature(report)
    return UploadStatus.decode(fw.get_feature(ReportId.UPLOAD_STATUS))


def test_start_with_a_token_begins_a_numbered_session_and_stamps_every_report():
    fw = firmware()
    before = run(fw, 0.002)
    assert session(before[-1]) == (0, 0, False)  # no session since power-up (PN2)
    states = control(fw, Command.START, 5)
    assert session(states[-1]) == (1, 5, True)  # PN1
    assert states[-1].flags & StateFlags.RUNNING
    again = control(fw, Command.START, 5)  # the owner's START: same session
    assert {session(s) for s in again} == {(1, 5, True)}
    assert not any(s.faults & FaultBits.SESSION_BUSY for s in again)


def test_start_of_another_token_is_refused_flagged_and_does_not_feed_the_session():
    fw = firmware()
    control(fw, Command.START, 5)
    started_ms = fw.session.last_host_s * 1e3  # device time of the START of token 5
    rejected = fw.counters().rejected_requests
    states = control(fw, Command.START, 6)
    assert states[0].faults & BUSY == BUSY  # PN3, in the next report only
    assert not any(s.faults & FaultBits.SESSION_BUSY for s in states[1:])
    assert {session(s) for s in states} == {(1, 5, True)}
    assert fw.counters().rejected_requests == rejected + 1
    # refused STARTs every 20 ms do not keep the session alive: it ends 100 ms after the last
    # accepted report, the START of token 5 (PN7)
    states = []
    for _ in range(5):
        states += control(fw, Command.START, 6, run_s=0.02)
    states += run(fw, 0.01)
    live = [s.session_live for s in states]
    assert live[0] and not live[-1]
    ended = states[live.index(False)].timestamp_us * 1e-3 - started_ms
    assert 100 < ended <= 101  # ms: the first report more than watchdog_ms after it
    assert session(control(fw, Command.START, 6)[-1]) == (2, 6, True)  # now it may begin


def test_stop_ends_only_the_owners_session():
    fw = firmware()
    control(fw, Command.START, 5)
    refused = control(fw, Command.STOP, 6)  # PN4: another token cannot stop it
    assert refused[0].faults & BUSY == BUSY
    assert session(refused[-1]) == (1, 5, True) and refused[-1].flags & StateFlags.RUNNING
    stopped = control(fw, Command.STOP, 5)
    assert session(stopped[-1]) == (1, 0, False)  # number stays, flag clears
    assert not stopped[-1].flags & StateFlags.RUNNING
    idle = control(fw, Command.STOP, 0)  # no session live: STOP as in 1.1
    assert not idle[0].faults & FaultBits.INVALID_REQUEST
    assert session(control(fw, Command.START, 7)[-1]) == (2, 7, True)


def test_commit_and_device_profile_are_busy_during_a_session_with_a_token():
    fw = firmware()
    assert upload(fw, CARD).card_generation == 1
    control(fw, Command.START, 5)
    status = upload(fw, OTHER_CARD)  # PN5: the owner is not exempt either
    assert (status.state, status.result) == (UploadState.FAILED, UploadResult.BUSY)
    assert status.detail == "session 1 of token 5 is live"
    assert status.card_generation == 1
    states = run(fw, 0.002)
    assert states[0].faults & FaultBits.SESSION_BUSY and states[-1].card_generation == 1
    refused = control(fw, Command.DEVICE_PROFILE)
    assert refused[0].faults & BUSY == BUSY
    control(fw, Command.STOP, 5)
    assert upload(fw, OTHER_CARD).card_generation == 2  # after STOP the upload goes through


def test_take_over_ends_the_live_session_and_begins_the_next():
    fw = firmware()
    control(fw, Command.START, 5)
    states = control(fw, Command.TAKE_OVER, 9)  # PN6: never refused
    assert session(states[-1]) == (2, 9, True)
    assert not any(s.faults & FaultBits.INVALID_REQUEST for s in states)
    assert fw.session.ended == "take-over"
    fw.handle_output(b"\x12\x07\x00")  # PO5: TAKE_OVER without a token is malformed
    malformed = run(fw, 0.002)
    assert malformed[0].faults & FaultBits.INVALID_REQUEST
    assert session(malformed[-1]) == (2, 9, True)


def test_a_session_ends_after_watchdog_ms_without_host_reports_whatever_the_touch_source():
    fw = firmware()
    control(fw, Command.SET_TOUCH_SOURCE, 0)  # internal sensor: the watchdog never trips
    states = control(fw, Command.START, 5, run_s=0.095)
    assert all(s.session_live for s in states)  # 95 ms of silence: still live
    states = run(fw, 0.01)
    assert not states[-1].session_live and states[-1].session_number == 1  # PN7
    assert fw.session.ended == "timeout"
    assert not any(s.faults & FaultBits.WATCHDOG for s in states)


def test_an_older_host_alone_works_as_before():
    fw = firmware()
    states = control(fw, Command.START, 0)  # a 1.1 host: argument 0, an anonymous session
    assert session(states[-1]) == (1, 0, True)
    assert upload(fw, CARD).state == UploadState.COMMITTED  # PN11: uploads not restricted
    assert run(fw, 0.002)[-1].card_generation == 1
    refused = control(fw, Command.START, 7)  # a 1.2 host cannot enter it either (PN3)
    assert refused[0].faults & BUSY == BUSY
    stopped = control(fw, Command.STOP, 0)
    assert session(stopped[-1]) == (1, 0, False)
    legacy = decode_input(states[-1].encode()[:State.LEGACY_SIZE])  # what a 1.1 device sends
    assert (legacy.session_number, legacy.session_token, legacy.sequence) == (
        0, 0, states[-1].sequence)


# ---------------------------------------------------------------------- driver (PN8, PN9)

def test_sim_driver_begins_and_ends_its_session_and_refuses_to_send_after_a_loss():
    with open_device("sim://") as driver:
        driver.upload_card(CARD)
        driver.start()
        token, number = driver.session_token, driver.session_number
        assert 1 <= token <= 255 and number == 1
        assert {s.session_number for s in driver.collect_until(driver.clock() + 0.01)} == {1}
        driver.stop()
        driver.start()
        assert driver.session_number == 2 and driver.session_token != token  # PN1
        driver.firmware.handle_output(Control(Command.TAKE_OVER, 200).encode())
        with pytest.raises(SessionLost, match=r"session 2 was lost: taken over by session 3 "
                                              r"\(token 200\)"):
            driver.collect_until(driver.clock() + 0.01)
        with pytest.raises(SessionLost, match="session 2 was lost"):
            driver.keepalive()  # PN9: nothing more that changes the device
        rejected = driver.counters().rejected_requests
        driver.stop()  # no STOP goes out: it would be refused and flag the new owner
    assert driver.firmware.counters().rejected_requests == rejected


# ---------------------------------------------------------------------- served (PN10)

FEED_PERIOD_S = 0.02
"""How often :func:`feeding` sends a KEEPALIVE, s (a playing host's reports come as often)."""


@contextlib.contextmanager
def feeding(driver) -> Iterator[list[State]]:
    """Keep ``driver``'s session fed on a thread (KEEPALIVE every :data:`FEED_PERIOD_S`, as a
    playing host's reports would) and collect its reports into the list yielded; the thread
    owns the driver until the block ends.

    The feeding is the host keeping real time: when the thread fell silent for longer than the
    device's watchdog (so that the device ended the session for host silence, PN7, and the
    block saw another host's session), the run was not kept (:class:`NotKept`, QT3), whatever
    the block found. Any other error of the thread fails the block."""
    states: list[State] = []
    stop = threading.Event()
    watchdog_s = driver.info().watchdog_ms / 1000
    longest_gap_s = [0.0]
    failure: list[BaseException] = []

    def feed() -> None:
        last = time.monotonic()
        try:
            while not stop.is_set():
                states.extend(driver.collect_until(driver.clock() + FEED_PERIOD_S))
                driver.keepalive()
                now = time.monotonic()
                longest_gap_s[0] = max(longest_gap_s[0], now - last)
                last = now
        except DeviceError as exc:
            failure.append(exc)

    thread = threading.Thread(target=feed, daemon=True)
    thread.start()
    try:
        yield states
    finally:
        stop.set()
        thread.join(5)
        silent = longest_gap_s[0] > watchdog_s or any(
            isinstance(e, SessionLost) and "host silence" in str(e) for e in failure)
        if silent:
            raise NotKept(f"the feeding thread fell silent for {longest_gap_s[0] * 1e3:.0f} ms "
                          f"(watchdog {watchdog_s * 1e3:.0f} ms)"
                          + (f": {failure[0]}" if failure else ""))
        if failure:
            raise failure[0]


def test_two_clients_of_one_device_served_in_another_process_repeatedly():
    def three_rounds() -> None:  # run again while the machine did not keep real time
        states: list[State] = []
        with served_device() as served, kept_run(states):
            for round_ in range(3):
                first, second = open_device(served.uri), open_device(served.uri)
                try:
                    first.start()
                    number = first.session_number
                    assert number == 2 * round_ + 1
                    with feeding(first) as states_a:
                        t0 = time.monotonic()
                        with pytest.raises(SessionBusy, match=rf"session {number} of another host "
                                                              rf"\(token {first.session_token}\)"):
                            second.start()  # PN8: looks, waits 150 ms of silence, sends nothing
                        waited = time.monotonic() - t0
                        states_b = second.collect_until(second.clock() + 0.05)
                        second.send(Control(Command.START, first.session_token % 255 + 1))
                        seen = second.collect_until(second.clock() + 0.02)
                    states += states_a + states_b + seen
                    assert 0.15 <= waited < 0.6
                    assert any(s.faults & FaultBits.SESSION_BUSY for s in seen)  # PN3
                    assert {s.session_number for s in states_a + states_b + seen} == {number}
                    # PN10: both clients get the same reports (every report, per connection)
                    common = {s.sequence for s in states_a} & {s.sequence for s in states_b}
                    assert len(common) >= 40
                    first.keepalive()
                    second.take_over()
                    assert second.session_number == number + 1
                    with pytest.raises(SessionLost, match=rf"session {number} was lost: taken over "
                                                          rf"by session {number + 1}"):
                        first.collect_until(first.clock() + 0.1)
                    second.stop()
                finally:
                    first.close()
                    second.close()

    in_real_time(three_rounds, "two clients of one served device, three rounds")


def _write_inputs(folder: Path, seconds: float) -> tuple[Path, Path]:
    card, track = folder / "step.hcard", folder / "stroke.csv"
    save(CARD, card)
    track.write_text(track_to_csv(straight_stroke((2.0, 5.0), (16.0 / seconds, 0.0), seconds)))
    return card, track


def _hcard_play(card: Path, uri: str, track: Path, output: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", "from hcard.cli.main import cli; cli()", "play", str(card),
         "--device", uri, "--track", str(track), "-o", str(output)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_session(uri: str, timeout_s: float = 20.0) -> State:
    """The first STATE report with a live session, read by a client that sends nothing."""
    with open_device(uri) as watcher:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            live = [s for s in watcher.read_inputs(0.05) if s.session_live]
            if live:
                return live[-1]
    raise AssertionError(f"no session began within {timeout_s} s")


def test_hcard_play_that_loses_its_session_exits_1_with_the_reason_and_writes_nothing(
        tmp_path):
    card, track = _write_inputs(tmp_path, 3.0)
    output = tmp_path / "rec.csv"
    output.write_text("previous\n")
    with served_device() as served:
        player = _hcard_play(card, served.uri, track, output)
        owner = _wait_for_session(served.uri)
        time.sleep(0.5)
        with open_device(served.uri) as intruder:
            intruder.take_over()
            assert intruder.session_number == owner.session_number + 1
            out, err = player.communicate(timeout=30)
            intruder.stop()
    assert player.returncode == 1, (out, err)
    assert f"session {owner.session_number} was lost: taken over by session " \
           f"{owner.session_number + 1}" in err
    assert "nothing is recorded" in err and err.startswith("Error: ")
    assert "reports from" not in out  # no recording reported
    assert output.read_text() == "previous\n"  # the earlier file is kept
    assert not (tmp_path / "rec.csv.json").exists()


TWO_PLAYS_TRACK_S = 12.0
"""Track of the first of two ``hcard play`` runs, s: the second must start while it plays."""


def test_a_second_hcard_play_is_refused_and_the_first_records_its_whole_track(tmp_path):
    """The audit's scenario: two `hcard play` on one served device."""
    # longer than a CLI process takes to start, also on a loaded machine (the second one took
    # over 6 s there, and found the first one's session over)
    card, track = _write_inputs(tmp_path, TWO_PLAYS_TRACK_S)

    attempt = [0]

    def two_plays() -> tuple[subprocess.Popen[str], str, subprocess.Popen[str], str, str]:
        attempt[0] += 1
        folder = tmp_path / f"attempt{attempt[0]}"  # each attempt writes its own recordings
        folder.mkdir()
        with served_device() as served:
            first = _hcard_play(card, served.uri, track, folder / "first.csv")
            _wait_for_session(served.uri)
            second = _hcard_play(card, served.uri, track, folder / "second.csv")
            _out2, err2 = second.communicate(timeout=40)
            out1, err1 = first.communicate(timeout=40)
            with open_device(served.uri) as watcher:
                trips = watcher.counters().watchdog_trips
        if first.returncode and (trips or "after host silence (PN7)" in err1):
            # the device's watchdog saw a host silent for watchdog_ms (PS3), or the first CLI
            # learnt that its session ended so (the second CLI's clear of the counters can hide
            # the trip): it did not keep real time, and PN7 ended its session (spec QT3)
            raise NotKept(f"the device's watchdog tripped {trips} times; the first hcard play "
                          f"said: {err1.strip()}")
        return first, out1, second, err2, err1

    first, out1, second, err2, err1 = in_real_time(two_plays, "two hcard play processes")
    tmp_path = tmp_path / f"attempt{attempt[0]}"  # the kept attempt's recordings
    assert "reports from" in out1, err1
    assert second.returncode == 1 and "device busy: session 1 of another host" in err2
    assert not (tmp_path / "second.csv").exists()
    assert first.returncode == 0, err1
    table = read_measurement(tmp_path / "first.csv")
    session = table.conditions["session"]
    # the whole track and its tail (wall clock)
    assert TWO_PLAYS_TRACK_S + 0.05 <= session["duration_s"] < TWO_PLAYS_TRACK_S + 0.5
    x_mm = table.column("x")[table.column("contact").astype(bool)] * 1e3  # touching rows
    assert x_mm.min() == pytest.approx(2.0, abs=0.2) and x_mm.max() == pytest.approx(18.0, abs=0.2)
    last_sample_s = straight_stroke((2.0, 5.0), (16.0 / TWO_PLAYS_TRACK_S, 0.0),
                                    TWO_PLAYS_TRACK_S).t[-1]
    assert table.column("echo")[-1] == pytest.approx(last_sample_s, abs=1e-6)  # applied
    # (the device's clock may run slower than the wall clock on a loaded machine, and the
    # second CLI starting up may starve the first for some ms: reports missed in transit are
    # counted as sequence gaps, PT5, and stay few)
    assert session["reports_lost"] <= 0.05 * session["reports"]


def test_a_driver_refuses_take_over_on_a_device_without_sessions():
    from hcard_device.served_controls import open_no_ownership

    with open_no_ownership() as driver:
        assert not driver.sessions_supported()
        with pytest.raises(DeviceError, match=r"protocol 1\.1: no sessions, no TAKE_OVER"):
            driver.take_over()


def test_a_host_slower_than_the_report_stream_still_begins_its_session():
    """A host that decodes a report in 2 ms (slower than the device's 1000 reports/s, as a
    Python host under software emulation is) always finds another report waiting; the driver's
    reads are bounded (READ_BATCH_MAX), so start() is granted instead of draining forever."""
    from hcard.device.base import READ_BATCH_MAX

    with served_device() as served:
        for _round in range(2):  # the same running server, twice
            driver = open_device(served.uri)
            parse = driver.parse_input

            def slow_parse(data: bytes, parse=parse) -> State | None:
                time.sleep(0.002)
                return parse(data)

            driver.parse_input = slow_parse  # type: ignore[method-assign]
            outcome: dict[str, object] = {}

            def begin(driver=driver, outcome=outcome) -> None:
                try:
                    driver.start()
                    outcome["batch"] = len(driver.read_inputs(0.05))
                    driver.stop()
                except Exception as exc:  # reported by the assertion below
                    outcome["error"] = exc

            thread = threading.Thread(target=begin, daemon=True)
            t0 = time.monotonic()
            thread.start()
            thread.join(15.0)
            try:
                assert not thread.is_alive(), "start() kept draining the report stream"
                assert "error" not in outcome, outcome.get("error")
                assert time.monotonic() - t0 < 5.0
                assert 1 <= int(outcome["batch"]) <= READ_BATCH_MAX  # type: ignore[call-overload]
            finally:
                driver.close()


def test_a_recording_is_refused_when_the_device_ended_its_session_after_host_silence():
    """PN7, PN9: a host that stalls past watchdog_ms has its session ended by the device, and
    from then on another host's reports are carried out: ``hcard play`` (``whole_session``)
    records nothing and says so; a measurement that judges the run itself gets the reports.
    Seen in CI under load: a recording held an intruding client's finger at x = 70 mm."""
    track = straight_stroke((2.0, 5.0), (16.0 / 3.0, 0.0), 1.0)

    def stalled(driver) -> None:  # 15 touch samples (300 ms) never sent
        send = driver.send_finger
        calls = {"n": 0}

        def finger(*args, **kwargs) -> None:
            calls["n"] += 1
            if not 15 <= calls["n"] < 30:
                send(*args, **kwargs)

        driver.send_finger = finger

    with open_device("sim://") as driver:
        stalled(driver)
        result = play(driver, CARD, track)  # the run itself, for a caller that judges it
        number = result.states[0].session_number
        assert any(s.session_number == number and not s.session_live for s in result.states)
    with open_device("sim://") as driver:
        stalled(driver)
        with pytest.raises(SessionLost, match=r"ended by the device after watchdog_ms of "
                                              r"silence .*nothing is recorded"):
            play(driver, CARD, track, whole_session=True)
    with open_device("sim://") as driver:  # a host that kept its session records as before
        assert len(play(driver, CARD, track, whole_session=True).states) > 900


def test_a_card_replaced_after_the_session_ended_for_silence_says_so():
    """PN9, PN7: a host whose session the device ended after its silence, and whose card
    another host then replaced, is told both (a loaded machine's host needs the first part to
    know its own stall began it)."""
    with open_device("sim://") as driver:
        driver.upload_card(CARD)
        driver.start()
        driver._idle(driver.info().watchdog_ms / 1000 + 0.02)  # silence: PN7 ends the session
        with driver.another_host() as other:
            other.upload_card(CARD)
        with pytest.raises(SessionLost, match=r"ended by the device after host silence \(PN7\), "
                                              r"then the active card was replaced"):
            driver.collect_until(driver.clock() + 0.01)
