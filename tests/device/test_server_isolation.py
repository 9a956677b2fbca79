"""Each client of a served device is isolated (spec/device-protocol.md rules PN10, PN12-PN15,
PU12; the bounds of section 13), tested against a server in another process over TCP on
127.0.0.1 with the hostile clients of ``hcard_conformance.usbip_clients``, each in a process
of its own.

The tests of the server fail against the server of before this isolation (usbip's
``serve_connection``, commit checked under the firmware's lock), which was run with them: its
pump stopped for every client when one stopped reading, it parked and read whatever a client
declared, 300 idle importers took 60-87 % of a client's reports, a 2 MiB card commit stopped
STATE for its whole parse, and a second client could halt, drive and re-limit the first one's
session. Two pass there too: the OUT-report flood (which never starved a client, kept as a
guard) and, on a lightly loaded machine, the 2 GiB OUT URB's share of reports (its memory test
fails there). The checker's bound and the log are the new code's own.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hcard import build
from hcard.calibration.measurement import read_measurement
from hcard.card_io import save, to_bytes
from hcard.device import open_device
from hcard.device.errors import DeviceStall, SessionBusy, SessionLost
from hcard.device.protocol import (
    INPUT_RATE_HZ,
    Command,
    Control,
    FaultBits,
    Finger,
    Limits,
    Stream,
    UploadBegin,
    UploadResult,
    UploadState,
)
from hcard.device.protocol.constants import DEFAULT_MAX_CARD_BYTES
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_effects import FittedEffect
from hcard.plugins.registry import get_registry
from hcard.render.options import RenderOptions
from hcard.track import straight_stroke, track_to_csv
from hcard_conformance import usbip_clients as clients
from hcard_device.card_check import (
    CHECK_TIMEOUT_S,
    WORKER_NICENESS,
    CheckedCard,
    CheckedProfile,
    CheckFailed,
    ProcessChecker,
)
from hcard_device.usb.connection import DEFAULT_LIMITS, ReportPacer
from hcard_device.usb.transport import MAX_CONNECTIONS
from tests.helpers.cards import large_valid_card
from tests.helpers.hostile_cards import json_empty_components
from tests.helpers.realtime import NotKept, in_real_time
from tests.helpers.served_device import ServedDevice, served_device

pytestmark = pytest.mark.wall_clock

DELIVERY_SHARE = 0.9
"""Share of the STATE reports a well-behaved client receives alone that it still receives
beside any misbehaving client (spec/device-protocol.md section 13, rule PN15)."""
MEASURE_S = 3.0
"""Length of each delivery measurement, s."""
RSS_GROWTH_MIB = 16.0
"""Most the server's resident memory may grow while a client floods it, MiB (its bounds
allow under 1 MiB for all connections together, section 13; the rest is allocator slack)."""


def rss_mib(pid: int) -> float:
    """Resident memory of process ``pid``, MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for process {pid}")


@pytest.fixture(scope="module")
def served():
    """One E-ViTa served in another process for the tests of this module."""
    with served_device() as device:
        yield device


def delivery_beside(served: ServedDevice, kind: str) -> tuple[clients.Delivery,
                                                              clients.Delivery]:
    """A well-behaved client's STATE delivery alone, then beside the misbehaving client
    ``kind`` (started once it holds its connection, given 2 s to take effect)."""
    alone = clients.measure_delivery(served.host, served.port, MEASURE_S)
    beside = clients.measure_delivery(
        served.host, served.port, MEASURE_S, beside_settle_s=2.0,
        beside=lambda: clients.hostile_process(kind, served.host, served.port))
    return alone, beside


# ---------------------------------------------------------------------- STATE delivery (PN15)

ATTEMPTS = 3
"""Pairs of measurements (alone, beside) a delivery test may take: other processes on the
machine move the share of a single measurement by more than the bound; a server that does not
isolate its clients fails every pair (the server before: 0 beside a client that stops
reading, 0.35-0.42 beside 300 idle importers)."""


@pytest.mark.parametrize("kind", sorted(clients.HOSTILE_KINDS))
def test_a_misbehaving_client_does_not_starve_another(served, kind):
    """Against the old server: a client that stops reading stopped every client's STATE
    (0 reports a second), 300 idle importers cut it to 24-42 %, URB floods to 70-90 %."""
    pairs = []
    for _attempt in range(ATTEMPTS):
        alone, beside = delivery_beside(served, kind)
        pairs.append(f"{beside.fraction:.3f} beside, {alone.fraction:.3f} alone "
                     f"(largest gap {beside.max_arrival_gap_ms:.0f} ms)")
        if (alone.fraction > 0.5 and beside.fraction >= DELIVERY_SHARE * alone.fraction
                and beside.max_arrival_gap_ms < 1000.0):
            return
    pytest.fail(f"{kind}: the share of STATE reports a client receives: " + "; ".join(pairs))


# ---------------------------------------------------------------------- bounds (PN15, sec. 13)

def test_a_transfer_declared_past_the_bound_closes_the_connection_unread(served):
    """One OUT URB declaring 2 GiB: the old server read 1.5 GB of it into memory."""
    before = rss_mib(served.process.pid)
    sock = clients.import_device(served.host, served.port)
    fed = 0
    with contextlib.suppress(OSError), sock:
        sock.sendall(clients.submit_header(1, 0, clients.OUT_EP, (1 << 31) - 1))
        sock.settimeout(5.0)
        chunk = bytes(1 << 20)
        while fed < 256 << 20:
            sock.sendall(chunk)
            fed += len(chunk)
    assert fed < 64 << 20, f"the server read {fed >> 20} MiB of a 2 GiB transfer"
    assert rss_mib(served.process.pid) - before < RSS_GROWTH_MIB


def test_parked_in_urbs_past_the_bound_close_the_connection(served):
    """The old server parked every IN URB it was sent (400 000: +267 MB)."""
    before = rss_mib(served.process.pid)
    sock = clients.import_device(served.host, served.port)
    with sock:
        sock.settimeout(10.0)
        with contextlib.suppress(OSError):
            sock.sendall(clients.in_urbs(1, 100_000))
        answered = 0
        with contextlib.suppress(OSError):
            while clients.read_answer(sock):
                answered += 1
    # a few reports may complete URBs before the 65th parks; the rest are never answered
    assert answered < DEFAULT_LIMITS.max_parked_in_urbs + 200
    assert rss_mib(served.process.pid) - before < RSS_GROWTH_MIB


def test_interrupt_out_reports_complete_at_the_buss_rate_after_a_burst(served):
    """A client that submits 664 FINGER reports at once gets 64 answered at once and the rest
    at one a millisecond (a full-speed bus frame each): 0.6 s at least, however idle the
    machine; twice against the same running server (a second connection gets its own bucket).
    The old server answered them as fast as it could carry them out (1557 a second while each
    one ran the simulation, 7900 after), and the flood took a core."""
    burst, rate = DEFAULT_LIMITS.out_report_burst, DEFAULT_LIMITS.out_reports_per_s
    count = burst + 600
    for _connection in range(2):
        sock = clients.import_device(served.host, served.port)
        with sock:
            sock.settimeout(10.0)
            start = time.monotonic()
            sock.sendall(clients.finger_outs(1, count))
            answered = [clients.read_answer(sock) for _ in range(count)]
            elapsed = time.monotonic() - start
        assert [seqnum for seqnum, _status, _data in answered] == list(range(1, count + 1))
        assert {status for _seqnum, status, _data in answered} == {0}
        assert elapsed >= (count - burst) / rate - 0.01, f"{count} reports in {elapsed:.3f} s"


def test_the_pacer_lets_a_burst_through_and_then_one_per_period():
    now = [0.0]
    pacer = ReportPacer(1000.0, 4, clock=lambda: now[0])
    assert [pacer.take() for _ in range(4)] == [0.0] * 4
    waits = [pacer.take() for _ in range(3)]  # at the same instant: 1, 2 and 3 ms to wait
    np.testing.assert_allclose(waits, [0.001, 0.002, 0.003])
    now[0] = 0.010  # 10 ms idle: the 3 owed are paid and the bucket is full again
    assert [pacer.take() for _ in range(4)] == [0.0] * 4
    assert pacer.take() == pytest.approx(0.001)
    now[0] = 0.0125  # 2.5 ms later: the one owed is paid, one and a half tokens left
    assert pacer.take() == 0.0 and pacer.take() == pytest.approx(0.0005)
    with pytest.raises(ValueError, match="rate > 0"):
        ReportPacer(0.0, 4)


def test_a_client_that_does_not_read_its_answers_is_closed(served):
    """Answers pile up for a client that never reads: past the bound it is closed, and the
    server never waits for it (the old server's threads blocked in sendall)."""
    sock = clients.import_device(served.host, served.port, receive_buffer=4096)
    with sock:
        sock.settimeout(0.5)
        sent = 0
        with contextlib.suppress(OSError):  # reset, or the server stopped reading
            while sent < 2_000_000:
                sock.sendall(clients.descriptor_gets(1, 256))
                sent += 256
        sock.settimeout(5.0)
        with contextlib.suppress(OSError):
            while sock.recv(1 << 16):
                pass  # what was sent before the close, then end of stream
        with pytest.raises(OSError):
            sock.sendall(clients.descriptor_gets(1, 256) * 64)  # closed: reset or broken pipe
            sock.sendall(clients.descriptor_gets(1, 256) * 64)
    # the server still serves others
    assert clients.measure_delivery(served.host, served.port, 0.5).received > 100


def test_connections_past_the_bound_are_refused(served):
    """The old server served every importer (300 of them: every report to each)."""
    with clients.IdleImporters(served.host, served.port, 3 * MAX_CONNECTIONS) as idle:
        assert len(idle.held) == MAX_CONNECTIONS
        assert idle.refused == 2 * MAX_CONNECTIONS
        for sock in idle.held:  # each held one is served: it gets an answer
            sock.sendall(clients.descriptor_gets(1, 1))
            assert clients.read_answer(sock)[1] == 0
    deadline = time.monotonic() + 5.0  # closed connections free their slots
    while True:
        try:
            clients.import_device(served.host, served.port).close()
            break
        except OSError:
            assert time.monotonic() < deadline, "no slot freed after the importers left"
            time.sleep(0.05)


# ---------------------------------------------------------------------- card check (PU12)

@pytest.mark.parametrize("card", ["json-empty-components", "large-binary"])
def test_a_2_mib_commit_does_not_stop_state(served, card):
    """The old server parsed under the firmware's lock: a 2 MiB JSON card of 698 966 empty
    components stopped STATE for the 46-82 s of its parse. The observer reads at the device's
    real-time priority (as root, as CI runs): then the commit may add at most 2 report periods
    to the longest gap it sees without one (measured: 3.0-3.5 ms during, 2.6-2.9 ms without),
    and no report may be lost; at an ordinary priority the gap is the machine's scheduling,
    and only a stop of a second would show. A gap over the bound with every report on time
    (no loss, no stamp gap) is the observer's machine, not the device: measured again, up to
    3 times (``tests/helpers/realtime.py``; one CI run saw 9.2 ms beside a 5.2 ms baseline), as is a
    report lost or late; a parse under the lock stops STATE every time."""
    data = (json_empty_components(size=DEFAULT_MAX_CARD_BYTES) if card == "json-empty-components"
            else to_bytes(large_valid_card()))
    period_ms = 1e3 / INPUT_RATE_HZ

    def commit_once() -> None:
        outcome = clients.measure_commit(served.host, served.port, data, real_time=True)
        if card == "json-empty-components":
            assert outcome.status.state == UploadState.FAILED
            assert outcome.status.result == UploadResult.INVALID_CARD, outcome.status
            assert outcome.commit_s < CHECK_TIMEOUT_S + 5.0
        else:
            assert outcome.status.state == UploadState.COMMITTED, outcome.status
        during, baseline = outcome.during, outcome.baseline
        assert during.max_arrival_gap_ms < 1000.0, during
        assert during.fraction >= 0.5 * baseline.fraction, (during, baseline)
        if during.real_time and not (
                during.lost == 0 and during.max_stamp_gap_us == round(period_ms * 1e3)
                and during.max_arrival_gap_ms <= baseline.max_arrival_gap_ms + 2 * period_ms):
            raise NotKept(f"STATE during the commit {during} vs without {baseline}")

    in_real_time(commit_once, f"a 2 MiB commit ({card})")


def test_a_check_longer_than_its_bound_fails_the_upload_and_the_next_one_works():
    """The check's time is bounded (PU12): a worker that has not answered is killed and
    replaced. Checking the largest valid card takes tens of milliseconds, more than 5 ms."""
    data = to_bytes(large_valid_card())
    options = RenderOptions(frame_rate_hz=10_000)
    checker = ProcessChecker(timeout_s=0.005).start()
    try:
        late = checker.check_card(data, options)
        assert isinstance(late, CheckFailed)
        assert late.detail == "card not checked within 0.005 s"
        assert checker.killed == 1
        checker.timeout_s = CHECK_TIMEOUT_S
        assert isinstance(checker.check_card(to_bytes(build.card(
            10.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])),
            options), CheckedCard)
    finally:
        checker.close()


def test_a_profile_with_fitted_effects_is_checked_in_the_worker_and_comes_back_whole():
    """``hcard calibrate --verify`` uploads a profile whose channels carry fitted effects
    (predictor classes made at run time); the worker once died pickling them, and the upload
    failed with 'the checker stopped'."""
    effects = get_registry().calibration_effects
    profile = DeviceProfile.coupled_stimulator().replace(effects=(
        FittedEffect(effects["air-layer"], {"air_gap": 6e-6}),
        FittedEffect(effects["load-index"], {"load_index": 0.8})))
    checker = ProcessChecker().start()
    try:
        pid = checker.worker_pid
        checked = checker.check_profile(profile.to_json())
        assert isinstance(checked, CheckedProfile), checked
        assert checked.profile.to_json() == profile.to_json()
        voltage, force = np.array([300.0, 900.0]), np.array([0.3, 1.2])
        assert np.array_equal(checked.profile.ev_channel.forward(voltage=voltage,
                                                                 normal_force=force),
                              profile.ev_channel.forward(voltage=voltage, normal_force=force))
        assert checker.worker_pid == pid and checker.killed == 0
    finally:
        checker.close()


def _children(pid: int) -> list[int]:
    """Process IDs whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                stat = (entry / "stat").read_text()
                if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
    return found


def test_the_check_worker_runs_below_the_device_and_below_ordinary_processes(served):
    """The server runs at SCHED_RR where permitted, and a child inherits its parent's
    scheduling: the worker once checked cards at the device's own real-time priority, beside
    its threads (and ahead of every ordinary process) however nice it made itself."""
    server = served.process.pid
    deadline = time.monotonic() + 30.0
    while not (workers := [c for c in _children(server)
                           if b"card_check" in Path(f"/proc/{c}/cmdline").read_bytes()]):
        assert time.monotonic() < deadline, "no card check worker under the server"
        time.sleep(0.1)
    (worker,) = workers
    assert os.sched_getscheduler(worker) == os.SCHED_OTHER
    assert os.getpriority(os.PRIO_PROCESS, worker) >= WORKER_NICENESS
    granted = os.sched_getscheduler(server) == os.SCHED_RR
    assert granted or os.geteuid() != 0  # as root the server's real-time request is granted


# ---------------------------------------------------------------------- sessions (PN12-PN14)

def test_another_connection_cannot_change_the_owners_session(served):
    """The old server carried out a second client's reports inside the first's session."""
    with open_device(served.uri) as owner, open_device(served.uri) as other:
        owner.start()
        owner.send_finger(0.5, 10.0, 5.0, 0.5, True)
        before = owner.counters()
        limits = owner.limits()
        other.send(Finger.from_si(0.000777, 70.0, 40.0, 0.5, True))
        other.send(Stream(1, (2000,), (10000,)))
        for command in (Command.KEEPALIVE, Command.CLEAR_COUNTERS, Command.STOP,
                        Command.PLAY_CARD):
            other.command(command, owner.session_token or 0)
        for report in (Limits.from_si(1e-7, 0.0, 1e-6), UploadBegin(16, 0)):
            with pytest.raises(DeviceStall):
                other.set_report(report)
        seen = other.collect_until(other.clock() + 0.02)
        owner.keepalive()
        states = owner.collect_until(owner.clock() + 0.02)
        after = owner.counters()
        assert any(s.faults & FaultBits.SESSION_BUSY for s in seen)
        assert after.rejected_requests - before.rejected_requests == 8  # 6 outputs, 2 SETs
        assert after.output_reports - before.output_reports == 1  # the owner's KEEPALIVE
        assert owner.limits() == limits
        assert all(s.host_time_echo_us == 500_000 for s in states[-5:])  # its own finger
        assert all(s.session_live and s.session_token == owner.session_token for s in states)
        owner.stop()


def test_another_connections_reports_do_not_keep_a_silent_owners_session_alive(served):
    """PN13 with PN7: the old server let a second host's KEEPALIVEs hold the session open."""
    with open_device(served.uri) as owner, open_device(served.uri) as other:
        owner.start()
        number = owner.session_number
        t0 = other.clock()
        states = []
        while other.clock() - t0 < 0.4:  # the owner is silent; the other one is not
            other.keepalive()
            states += other.collect_until(other.clock() + 0.02)
        last = states[-1]
        assert last.session_number == number and not last.session_live  # ended (PN7)
        other.start()  # and the device is free
        assert other.session_number == number + 1
        other.stop()


def test_take_over_stays_possible_and_moves_the_session_to_its_connection(served):
    def one_run() -> None:
        with open_device(served.uri) as first, open_device(served.uri) as second:
            first.start()
            second.take_over()
            try:
                first.collect_until(first.clock() + 0.05)
            except SessionLost as exc:
                if "after host silence (PN7)" in str(exc):  # the first host stalled past
                    raise NotKept(str(exc)) from exc     # the watchdog before the takeover
                assert "taken over" in str(exc)
            else:
                pytest.fail("the first host was not told its session was taken over (PN9)")
            before = second.counters().rejected_requests
            # the driver sends nothing after a loss (PN9); bypass it: now the other connection
            first._write_output(Control(Command.KEEPALIVE).encode())
            second.keepalive()
            # the two connections' requests reach the firmware on threads of their own: the
            # refusal is counted when the former owner's report arrives, which a GET on the
            # other connection may overtake; read until it shows, at most 1 s
            deadline = time.monotonic() + 1.0
            while (refused := second.counters().rejected_requests - before) < 1 \
                    and time.monotonic() < deadline:
                time.sleep(0.01)
            assert refused == 1
            second.stop()

    in_real_time(one_run, "a takeover between two connections")


def test_an_endpoint_halt_is_the_halting_connections_own(served):
    """The old server shared the OUT endpoint's halt: a second client's SET_FEATURE(ENDPOINT
    _HALT) made the first host's `hcard play` exit 1."""
    with open_device(served.uri) as first, open_device(served.uri) as second:
        second.link.control_out(0x02, 0x03, 0, 0x01, b"", timeout_s=1.0)  # halt OUT 0x01
        status = second.link.control_in(0x82, 0x00, 0, 0x01, 2, timeout_s=1.0)
        assert status == b"\x01\x00"  # GET_STATUS: its own OUT pipe is halted
        with pytest.raises(DeviceStall):
            second.keepalive()
        first.keepalive()  # the first connection's pipes run on
        assert first.link.control_in(0x82, 0x00, 0, 0x01, 2, timeout_s=1.0) == b"\x00\x00"
        second.link.control_out(0x02, 0x01, 0, 0x01, b"", timeout_s=1.0)  # CLEAR_FEATURE
        second.keepalive()
        # halting its IN pipe STALLs the second connection's IN URBs (those parked at once,
        # the next ones when its link submits them), no one else's
        with pytest.raises(DeviceStall, match="interrupt IN endpoint STALLed"):
            second.link.control_out(0x02, 0x03, 0, 0x81, b"", timeout_s=1.0)
            for _ in range(100):
                second.link.read_in(0.01)
        assert first.link.control_in(0x82, 0x00, 0, 0x81, 2, timeout_s=1.0) == b"\x00\x00"
        assert first.read_inputs(1.0)  # its IN pipe runs on


def _play(card: Path, uri: str, track: Path, output: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", "from hcard.cli.main import cli; cli()", "play", str(card),
         "--device", uri, "--track", str(track), "-o", str(output)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_hcard_play_records_only_its_own_session_whatever_another_client_sends(tmp_path):
    """The review's scenario: beside a playing host, a second client halts the OUT endpoint,
    sends FINGER reports at x = 70 mm, STREAM and a LIMITS change. The old server made play
    exit 1 (the halt), or exit 0 with 1200 of 4568 rows at the injected finger and a sidecar
    with the limits from before the change."""
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(1.0, channel="uv"), build.texture(0.4, channel="uv")], texture_index=[0, 1])
    save(card, tmp_path / "step.hcard")
    stroke = straight_stroke((2.0, 5.0), (16.0 / 3.0, 0.0), 3.0)
    (tmp_path / "stroke.csv").write_text(track_to_csv(stroke))
    output = tmp_path / "rec.csv"

    def one_run() -> str:
        with served_device() as served:
            player = _play(tmp_path / "step.hcard", served.uri, tmp_path / "stroke.csv", output)
            with open_device(served.uri) as intruder:
                deadline = time.monotonic() + 20.0
                while not any(s.session_live for s in intruder.read_inputs(0.05)):
                    assert time.monotonic() < deadline, "the player began no session"
                intruder.link.control_out(0x02, 0x03, 0, 0x01, b"", timeout_s=1.0)
                intruder.link.control_out(0x02, 0x01, 0, 0x01, b"", timeout_s=1.0)
                t_end = time.monotonic() + 1.5
                while time.monotonic() < t_end:
                    intruder._write_output(
                        Finger.from_si(0.000777, 70.0, 5.0, 0.5, True).encode())
                    intruder._write_output(Stream(1, (1000,), (10000,)).encode())
                    with contextlib.suppress(DeviceStall):
                        intruder.set_report(Limits.from_si(1e-7, 0.0, 1e-6))
                    intruder.read_inputs(0.01)
                _out, err = player.communicate(timeout=60)
        # a player that did not run for watchdog_ms on a loaded machine lost its session to
        # the device (PN7) and said so, recording nothing: the run measured the machine
        if player.returncode == 1 and "after watchdog_ms of silence" in err:
            raise NotKept(err.strip().splitlines()[-1])
        assert player.returncode == 0, err
        return err

    in_real_time(one_run, "hcard play beside an intruding client")
    table = read_measurement(output)
    touching = table.column("contact").astype(bool)
    x_mm = table.column("x")[touching] * 1e3
    assert x_mm.max() == pytest.approx(18.0, abs=0.3)  # never the injected 70 mm
    assert not np.any(table.column("echo") == 0.000777)
    conditions = table.conditions
    hardware = 2.5e-6  # the E-ViTa's amplitude limit (spec section 13): never lowered
    assert conditions["limits"]["max_amplitude_m"] == pytest.approx(hardware)
    assert "limits_at_start" not in conditions


# ---------------------------------------------------------------------- the server's log

def test_closes_are_logged_with_their_reason_and_the_log_never_blocks_the_server():
    """A reconnect flood closes hundreds of connections a second; their log lines once filled
    a stderr pipe nobody read and stopped the accept loop."""
    command = [sys.executable, "-m", "hcard_device.usb.server", "--port", "0"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        assert process.stdout is not None
        line = process.stdout.readline().decode()
        port = int(line.split("usbip://127.0.0.1:")[1].split("/")[0])
        with clients.hostile_process("giant-out-urb", "127.0.0.1", port) as stats:
            time.sleep(3.0)  # stderr is not read meanwhile: a 64 KiB pipe would fill
        assert stats["connections"] >= 20
        sock = clients.import_device("127.0.0.1", port)  # still accepting
        sock.close()
        process.send_signal(2)
        _out, err = process.communicate(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5)
    text = err.decode()
    assert "declares a transfer of 2147483647 bytes (OUT transfers: 0..4096)" in text
    assert "more lines not logged: over 20 a second" in text


def test_refused_requests_of_a_raw_client_do_not_crash_its_connection(served):
    """An unknown command, a bad direction: the connection closes with a reason; others go on."""
    for header in (struct.pack(">IIIII", 7, 1, clients.DEVID, 0, 0) + bytes(28),
                   struct.pack(">IIIII", 1, 1, clients.DEVID, 5, 1) + bytes(28)):
        sock = clients.import_device(served.host, served.port)
        with sock:
            sock.sendall(header)
            sock.settimeout(5.0)
            assert sock.recv(64) == b""  # closed
    with contextlib.suppress(SessionBusy), open_device(served.uri) as driver:
        assert driver.info().protocol_major == 1
    socket.create_connection((served.host, served.port), timeout=2).close()


# ---------------------------------------------------------------------- the stated bounds

def test_the_bounds_stated_in_the_spec_and_the_server_docstring_are_the_servers():
    """spec/device-protocol.md section 13 and hcard_device.usb.server state the bounds of the
    server's code; a change to one shows here."""
    from hcard_device.usb import server, transport
    from hcard_device.usb.device import DEFAULT_IN_QUEUE

    limits = DEFAULT_LIMITS
    spec = (Path(__file__).resolve().parents[2] / "spec" / "device-protocol.md").read_text()
    rows = {
        "connections served at once (handshakes and device lists included)":
            f"{transport.MAX_CONNECTIONS}",
        "connections accepted per second":
            f"{transport.ACCEPT_RATE_HZ:g} ({transport.ACCEPT_BURST} at once)",
        "import handshake (OP_REQ_IMPORT or OP_REQ_DEVLIST)": f"{limits.handshake_timeout_s:g} s",
        "STATE reports queued per connection": f"{DEFAULT_IN_QUEUE} ({DEFAULT_IN_QUEUE} ms)",
        "interrupt-IN URBs parked per connection (usbhid keeps 1)":
            f"{limits.max_parked_in_urbs}",
        "length of an OUT transfer (a report is at most 64 bytes)":
            f"{limits.max_out_bytes} bytes",
        "length of an IN transfer": f"{limits.max_in_bytes:,} bytes".replace(",", " "),
        "interrupt-OUT URBs completed per connection (a full-speed bus carries one report a "
        "frame)": f"{limits.out_reports_per_s:g} a second ({limits.out_report_burst} at once)",
        "answers waiting for a client that does not read, beyond its socket buffers":
            f"{limits.max_pending_bytes // 1024} KiB",
        "control transfers waiting behind a card check": f"{limits.max_queued_controls}",
        "check of one COMMIT or COMMIT_PROFILE (PU12), in a worker process":
            f"{CHECK_TIMEOUT_S:g} s",
    }
    for bound, value in rows.items():
        assert f"| {bound} | {value} |" in spec, bound
    doc = server.__doc__ or ""
    for value in (transport.MAX_CONNECTIONS, DEFAULT_IN_QUEUE, limits.max_parked_in_urbs,
                  limits.max_out_bytes, limits.max_in_bytes, limits.max_queued_controls):
        assert f" {value} " in doc, value
    assert f"{limits.max_pending_bytes // 1024} KiB" in doc
    assert f"{CHECK_TIMEOUT_S:g} s" in doc and f"{limits.handshake_timeout_s:g} s" in doc
    assert f" {limits.out_reports_per_s:g} /s " in doc
    assert f"({limits.out_report_burst} pass at once)" in doc
