"""Check ``device.refusals`` (spec/conformance.md 4.9, X1): the reference device passes every
case; the control that drops refused reports silently fails every output case, by the count
it did not keep; a device rendered on the host is not judged by it."""

from __future__ import annotations

from hcard.device.protocol import FaultBits, State, StateFlags
from hcard_conformance.context import Context
from hcard_conformance.device_checks import refusals
from hcard_conformance.result import CheckResult
from hcard_conformance.runner import run_suite


def _cases(uri: str) -> dict[str, CheckResult]:
    report = run_suite(Context.for_driver(uri), ("device",), select=("device.refusals",))
    return {r.case: r for r in report.results}


def test_the_reference_device_passes_every_case() -> None:
    results = _cases("sim://")
    assert list(results) == list(refusals.REFUSAL_CASES)
    for case, r in results.items():
        assert r.outcome == "PASS", (case, r.detail)
    assert "200 rejection(s) counted" in results["flood"].detail
    assert "INVALID_REQUEST flagged" in results["short-report"].detail
    assert "INVALID_REQUEST" not in results["padded-report"].detail


def test_a_device_that_drops_refused_reports_silently_fails_each_output_case() -> None:
    """``silent-refusals`` neither counts nor flags (PE2): 0 of 1 counted in four cases, 0 of
    200 in the flood; a padded report and the STALLed feature (counted elsewhere) pass."""
    results = _cases("control:silent-refusals")
    failed = {case for case, r in results.items() if r.outcome == "FAIL"}
    assert failed == {"short-report", "unknown-output", "unknown-command", "bad-stream",
                      "flood"}
    assert results["flood"].value == 200
    assert "0 rejections counted, 1 required" in results["short-report"].detail
    assert "no STATE report flagged INVALID_REQUEST (PE2)" in results["bad-stream"].detail


def test_the_bytes_sent_are_what_each_case_names() -> None:
    """The empty STREAM is the protocol's 64-byte report with count 0; the short and padded
    reports are a KEEPALIVE one byte short and padded to 64."""
    stream = refusals._empty_stream()
    assert len(stream) == refusals.REPORT_BYTES and stream[0] == 0x11 and stream[3] == 0
    keepalive = refusals._keepalive()
    assert len(keepalive) == 3 and keepalive[0] == 0x12


def test_a_device_rendered_on_the_host_is_not_judged() -> None:
    report = run_suite(Context.for_driver("faulty://none"), ("device",),
                       select=("device.refusals",))
    assert report.results == [] and "device.refusals" in report.not_applicable


def _state(sequence: int, rejected: int, faults: int = 0) -> State:
    return State(timestamp_us=sequence * 1000, sequence=sequence, flags=int(StateFlags.RUNNING),
                 x_10um=0, y_10um=0, corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0,
                 amplitude_nm=0, voltage_dv=0, current_10na=0, target_uv_x1e4=10_000,
                 target_ev_x1e4=10_000, texture=-1, faults=faults, dropped_reports=0,
                 rejected_requests=rejected, stream_queued=0, host_time_echo_us=0,
                 card_generation=0)


def test_the_flag_is_required_only_where_the_host_read_every_report() -> None:
    """PE2's INVALID_REQUEST rides on one report: a host that read every report after the
    request must see it; one that lost reports (a guest under software emulation reads a few
    hundred of 1000 a second) cannot, and only the count is judged."""
    short = refusals.refusals()["short-report"]
    before = _state(100, 7)
    every = [_state(101 + i, 8) for i in range(20)]
    assert refusals.all_read(before, every)
    unflagged = refusals.judge("short-report", short, before, every, "")
    assert not unflagged.passed and "no STATE report flagged INVALID_REQUEST" in unflagged.detail
    flagged = [_state(101, 8, int(FaultBits.INVALID_REQUEST)), *every[1:]]
    assert refusals.judge("short-report", short, before, flagged, "").passed
    lossy = every[::3]  # two of every three reports never read
    assert not refusals.all_read(before, lossy)
    waived = refusals.judge("short-report", short, before, lossy[:2] + [_state(200 + i, 8)
                                                                       for i in range(10)], "")
    assert waived.passed and "INVALID_REQUEST not judged" in waived.detail
    uncounted = refusals.judge("short-report", short, before, [_state(101 + i, 7)
                                                               for i in range(20)], "")
    assert not uncounted.passed and "0 rejections counted, 1 required" in uncounted.detail


def _refusals_through(driver: object, timing: str) -> dict[str, CheckResult]:
    ctx = Context.for_driver("sim://")
    ctx.open_driver = lambda: driver
    ctx.options["timing"] = timing
    return {r.case: r for r in refusals.check_refusals(ctx)}


def test_a_host_reading_late_waits_for_a_report_that_covers_the_request() -> None:
    """A host whose reads lag the device by 300 ms (as a QEMU guest's do): every report it
    reads in the first 50 ms was made before the request. Under software emulation it reads
    on until a report echoes the FINGER it sent after the request, and the reference passes
    every case with the counts of a prompt host; a real-time host reading that late gives up
    after 20 ms more and finds nothing counted, which X1 fails."""
    from tests.helpers.late_transport import LateReaderDriver

    late = _refusals_through(LateReaderDriver(), "software-emulation")
    assert list(late) == list(refusals.REFUSAL_CASES)
    for case, r in late.items():
        assert r.outcome == "PASS", (case, r.detail)
    assert "200 rejection(s) counted" in late["flood"].detail
    strict = _refusals_through(LateReaderDriver(), "real-time")
    assert strict["short-report"].outcome == "FAIL"
    assert "0 rejections counted, 1 required" in strict["short-report"].detail


def test_a_host_whose_reads_stall_reads_on_before_each_case() -> None:
    """A host that reads nothing for 60 ms of every 120 ms (a QEMU guest's emulated USB stack
    held its reports so, and the flood case was left unassessed: "no STATE report in 20 ms"):
    under software emulation the read before each case goes on for the class's report wait, so
    every case is assessed, and the reference passes them all."""
    from tests.helpers.late_transport import StallingReaderDriver

    results = _refusals_through(StallingReaderDriver(), "software-emulation")
    assert list(results) == list(refusals.REFUSAL_CASES)
    for case, r in results.items():
        assert r.outcome == "PASS", (case, r.outcome, r.detail)


def test_the_device_keeps_running_by_its_sequence_not_by_the_reports_read() -> None:
    """PE3 counts the reports the device produced after the request (sequence numbers, PT5):
    three reports read that span 40 produced pass; 5 produced (the device all but stopped)
    fail, however many of them were read."""
    short = refusals.refusals()["short-report"]
    before = _state(100, 7)
    sparse = [_state(110, 8, int(FaultBits.INVALID_REQUEST)), _state(125, 8), _state(140, 8)]
    assert refusals.judge("short-report", short, before, sparse, "").passed
    stalled = [_state(101 + i, 8, int(FaultBits.INVALID_REQUEST) if i == 0 else 0)
               for i in range(5)]
    result = refusals.judge("short-report", short, before, stalled, "")
    assert not result.passed and "5 STATE reports produced after it (5 read)" in result.detail
