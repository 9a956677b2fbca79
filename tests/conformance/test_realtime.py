"""Runs not kept in real time (spec/conformance.md QT3; device protocol 1.4, PI4): measured again
at most three times, then UNASSESSED with every reason; never a FAIL of the device, and never a
pass. The tests' own helper (tests/helpers/realtime.py) fails saying the machine could not keep real
time."""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import pytest

from hcard.device.protocol import Counters, FaultBits, State, UploadStatus
from hcard.device.uri import parse_uri
from hcard_conformance.context import Context
from hcard_conformance.device_checks import report_loss, upload_integrity
from hcard_conformance.device_checks.latency import check_latency
from hcard_conformance.realtime import (
    ATTEMPTS,
    NOT_KEPT,
    HostWatch,
    NotKept,
    attempted_case,
    attempts,
    device_lag,
    not_kept_results,
)
from hcard_conformance.result import FAIL, PASS, UNASSESSED, CannotAssess, CheckResult, unassessed
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import SimDriver
from tests.helpers.realtime import MACHINE, assert_conforms, in_real_time, kept_run

pytestmark = pytest.mark.wall_clock


def _state(faults: int = 0) -> State:
    return State(timestamp_us=0, sequence=0, flags=0, x_10um=0, y_10um=0,
                 corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0, amplitude_nm=0,
                 voltage_dv=0, current_10na=0, target_uv_x1e4=10_000, target_ev_x1e4=10_000,
                 texture=-1, faults=faults, dropped_reports=0, rejected_requests=0,
                 stream_queued=0, host_time_echo_us=0, card_generation=0)


def test_attempts_measure_again_while_not_kept_and_stop_at_three() -> None:
    calls: list[int] = []

    def twice_late() -> str:
        calls.append(1)
        if len(calls) < 3:
            raise NotKept(f"late {len(calls)}")
        return "kept"

    assert attempts(twice_late, "the run") == "kept" and len(calls) == 3

    def never() -> str:
        calls.append(1)
        raise NotKept("the host did not run for 40 ms")

    calls.clear()
    with pytest.raises(CannotAssess) as caught:
        attempts(never, "the run")
    assert len(calls) == ATTEMPTS == 3
    text = str(caught.value)
    assert f"the run {NOT_KEPT} in 3 attempts" in text
    assert all(f"attempt {k}: the host did not run for 40 ms" in text for k in (1, 2, 3))
    assert not isinstance(caught.value, NotKept)  # a verdict, not one more retry

    def broken() -> str:
        calls.append(1)
        raise CannotAssess("no HOST_FINGER")

    calls.clear()
    with pytest.raises(CannotAssess, match="no HOST_FINGER"):
        attempts(broken, "the run")
    assert len(calls) == 1  # a case that cannot be measured at all is not measured again


def test_a_case_never_kept_is_unassessed_with_its_reasons_never_failed() -> None:
    def late() -> CheckResult:
        raise NotKept("the device flagged 12 of 300 reports REALTIME_LAG")

    result = attempted_case("device.x", "device", "case", late)
    assert result.status == UNASSESSED and not result.passed
    assert NOT_KEPT in result.detail and "attempt 3: the device flagged 12" in result.detail
    assert not_kept_results([result]) == [result]
    failed = CheckResult("device.x", "device", "other", False, detail="7 reports over")
    kept = attempted_case("device.x", "device", "other", lambda: failed)
    assert kept.status == FAIL  # a run that was kept is judged: the device fails
    assert not_kept_results([kept, unassessed("d.y", "device", "c", "no card")]) == []


def test_device_lag_names_the_flagged_reports() -> None:
    states = [_state(), _state(int(FaultBits.REALTIME_LAG)), _state(int(FaultBits.WATCHDOG))]
    assert "1 of 3 reports REALTIME_LAG" in device_lag(states) and "PI4" in device_lag(states)
    assert device_lag(states[:1]) == "" and device_lag([]) == ""


def test_host_watch_sees_its_loop_and_a_process_that_did_not_run() -> None:
    ticks = iter([0.0, 0.001, 0.002, 0.030, 0.031])
    watch = HostWatch(bound_s=0.02, clock=lambda: next(ticks))
    for _ in range(3):
        watch.tick()
    assert watch.late == ""  # 1 ms between iterations
    watch.tick()  # 28 ms without iterating
    assert watch.longest_s == pytest.approx(0.028) and watch.late_count == 1
    assert "did not run for up to 28 ms" in watch.late
    # a thread that holds the interpreter for 60 ms keeps the watch from running
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1.0)
    try:
        with HostWatch(bound_s=0.02) as busy:
            time.sleep(0.005)  # the watch thread runs
            end = time.monotonic() + 0.06
            while time.monotonic() < end:
                pass
    finally:
        sys.setswitchinterval(interval)
    assert busy.longest_s >= 0.03, busy.longest_s
    with HostWatch(bound_s=0.5) as idle:
        time.sleep(0.05)
    assert idle.late == ""


def test_an_upload_case_that_failed_while_disturbed_is_measured_again() -> None:
    failed = CheckResult("device.upload-integrity", "device", "bad-crc", False,
                         detail="expected FAILED CRC_MISMATCH, device said COMMITTED")
    status = UploadStatus(2, 0, 0, 10, 10, 0, 1, "")
    paused = upload_integrity.Attempt(status, longest_pause_s=0.05)
    with pytest.raises(NotKept, match="the host paused 50 ms"):
        upload_integrity.kept(failed, paused)
    lagging = upload_integrity.Attempt(status, states=[_state(int(FaultBits.REALTIME_LAG))])
    with pytest.raises(NotKept, match="REALTIME_LAG"):
        upload_integrity.kept(failed, lagging)
    on_time = upload_integrity.Attempt(status, longest_pause_s=0.005, states=[_state()])
    assert upload_integrity.kept(failed, on_time) is failed  # kept: the device fails
    passed = replace(failed, passed=True, outcome="")
    assert upload_integrity.kept(passed, paused).status == PASS


def _session(unexcused: int, *, pause_s: float = 0.0, late: int = 0) -> report_loss.LossSession:
    stats = report_loss.SequenceStats(3000 - unexcused, 3000, unexcused, 0, 0, 0, unexcused)
    return report_loss.LossSession(stats, Counters(3000, 0, 0, 0, 0, 0, 0, 0), 0, 0, 3.0, 1.0,
                                   pause_s, device_late=late)


def test_report_loss_of_a_session_not_kept_is_not_judged() -> None:
    assert report_loss.loss_not_kept(_session(0, pause_s=0.05), 3) == ""  # nothing lost: judged
    assert report_loss.loss_not_kept(_session(40), 3) == ""  # kept, lost 40: judged (a FAIL)
    why = report_loss.loss_not_kept(_session(40, pause_s=0.05), 3)
    assert NOT_KEPT in why and "paused 50 ms" in why
    why = report_loss.loss_not_kept(_session(40, late=12), 3)
    assert "12 reports late" in why and "REALTIME_LAG" in why


class LaggingFirmware(Firmware):
    """The reference firmware on a device that falls behind its real-time clock all the time:
    every report it produces carries REALTIME_LAG (rule PI4)."""

    def _run_block(self, block, queued_before):  # type: ignore[no-untyped-def]
        self._late_before_us = 1 << 62
        try:
            super()._run_block(block, queued_before)
        finally:
            self._late_before_us = -1


def test_latency_of_a_device_that_never_keeps_real_time_is_unassessed_not_failed() -> None:
    def open_lagging() -> SimDriver:
        return SimDriver(parse_uri("sim://"),
                         LaggingFirmware(DeviceSimulation(DeviceConfig.evita())))

    results = {r.case: r for r in check_latency(Context("lagging", open_lagging))}
    move = results["boundary-move"]
    assert move.status == UNASSESSED, move.detail
    assert f"{NOT_KEPT} in 3 attempts" in move.detail and "REALTIME_LAG" in move.detail
    results = {r.case: r for r in check_latency(Context.for_driver("sim://"))}
    assert results["boundary-move"].status == PASS  # the same device on time


def test_the_tests_fail_saying_the_machine_could_not_keep_real_time() -> None:
    runs: list[int] = []

    def late() -> None:
        runs.append(1)
        raise NotKept("the host did not run for up to 45 ms")

    with pytest.raises(pytest.fail.Exception) as caught:
        in_real_time(late, "two clients")
    assert len(runs) == 3
    assert str(caught.value).startswith(f"{MACHINE} for two clients in 3 attempts")
    assert in_real_time(lambda: 7, "a kept run") == 7
    with (pytest.raises(NotKept, match=r"REALTIME_LAG.*the run found: 12 of 900 lost"),
          kept_run([_state(int(FaultBits.REALTIME_LAG))])):
        raise AssertionError("12 of 900 lost")
    with (pytest.raises(AssertionError, match="12 of 900 lost"),  # kept: the device's fault
          kept_run([_state()])):
        raise AssertionError("12 of 900 lost")
    with pytest.raises(NotKept, match="DID NOT RAISE"), kept_run() as watch:
        watch.note(0.045)  # the host did not run for 45 ms
        with pytest.raises(ValueError):
            pass
    with kept_run() as watch:  # nothing wrong: nothing to say, however late
        watch.note(0.045)
    never = attempted_case("device.latency", "device", "boundary-move",
                           lambda: (_ for _ in ()).throw(NotKept("late")))
    with pytest.raises(pytest.fail.Exception, match=f"^{MACHINE} for 1 cases"):
        assert_conforms([never])
    failed = CheckResult("device.safety", "device", "host-limits", False, detail="3 over")
    with pytest.raises(pytest.fail.Exception, match=r"host-limits.*3 over"):
        assert_conforms([never, failed])
    assert_conforms([replace(failed, passed=True, outcome="")])



def test_a_render_that_failed_on_a_late_play_is_played_again_then_unassessed() -> None:
    """Renderer level over a device (QT3): an entry that failed on a play the host did not keep
    is played again, three plays in all, then UNASSESSED; a play that was kept is judged (a
    faulty device fails); a pass on a late play stands."""
    from types import SimpleNamespace

    from hcard_conformance.renderer_level import _each_entry

    entry = SimpleNamespace(name="grating@stroke")
    key = ("renderer-case", entry.name)

    def judged(lateness: list[str], passes: bool) -> tuple[CheckResult, int]:
        ctx = Context("usbip://served")
        plays: list[str] = []

        def judge(_entry: object) -> CheckResult:
            if key not in ctx.cache:  # a play of the entry (case() caches it)
                late = lateness[min(len(plays), len(lateness) - 1)]
                plays.append(late)
                ctx.cache[key] = {"late": late, "replayed_after": [], "unreported_frames": 0}
            return CheckResult("renderer.friction_error", "renderer", entry.name, passes,
                               detail="RMS relative error 0.11")

        [result] = _each_entry(ctx, "renderer.friction_error", [entry], judge)
        return result, len(plays)

    late = "the host did not run for up to 45 ms (1 times over 20 ms)"
    result, plays = judged([late], passes=False)
    assert (result.status, plays) == (UNASSESSED, 3)
    assert f"{NOT_KEPT} in 3 plays" in result.detail and "0.11" in result.detail
    result, plays = judged([late, ""], passes=False)
    assert (result.status, plays) == (FAIL, 2)  # the second play was kept: the device fails
    result, plays = judged([late], passes=True)
    assert (result.status, plays) == (PASS, 1)


def test_only_a_device_on_the_wall_clock_is_judged_by_the_hosts_lateness() -> None:
    """sim:// runs in simulated time: however late the host ran, its plays are kept (a faulty
    control fails whatever the load); a served device runs on the wall clock."""
    from hcard import build
    from hcard.render import RenderOptions
    from hcard.track import straight_stroke
    from hcard_conformance.context import REALTIME_KEY

    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[build.texture(0.5, channel="uv")])
    track = straight_stroke((2.0, 5.0), (40.0, 0.0), 0.1)
    for uri, realtime in (("sim://", False), ("usbip://loopback", True)):
        ctx = Context.for_driver(uri)
        ctx.render(card, track, RenderOptions())
        assert ctx.cache[REALTIME_KEY] is realtime, uri
