"""Link checks (spec/conformance.md sections 4.6-4.7): upload integrity and STATE report loss.

The reference device passes both on ``sim://`` and over ``usbip://`` served in real time by
another process, twice against the same running server; the negative controls
``accepts-bad-crc`` and ``drops-reports`` fail the case made to catch them, by a margin, and
pass the cases their defect does not touch; ``unplayed-commit`` (committed, never played) fails
every upload case. Two test-only firmwares show that the other two
loss cases can fail too: one that loses reports without counting them, one that loses them
without numbering them.
"""

from __future__ import annotations

import pytest

from hcard.device import open_device
from hcard.device.base import DEFAULT_TIMEOUT_S
from hcard.device.protocol import FaultBits, State, StateFlags, UploadAction, crc32
from hcard.device.uri import parse_uri
from hcard_conformance.context import Context
from hcard_conformance.device_checks import report_loss, upload_integrity
from hcard_conformance.registry import all_checks
from hcard_conformance.result import CheckResult
from hcard_conformance.runner import run_suite
from hcard_device.controls import DROPPED_FRACTION, LossyFirmware
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import SimDriver
from tests.helpers.realtime import assert_conforms
from tests.helpers.repository import REPO
from tests.helpers.served_device import served_device

pytestmark = pytest.mark.wall_clock

LINK_CHECKS = ("device.upload-integrity", "device.report-loss")
REFUSALS = {"bad-crc": "CRC_MISMATCH", "truncated": "SHORT", "out-of-order": "OUT_OF_ORDER",
            "interrupted": "TIMEOUT", "restarted": "OUT_OF_ORDER", "oversize": "TOO_LARGE",
            "unknown-major": "INVALID_CARD", "invalid-card": "INVALID_CARD"}


def _cases(ctx: Context, check: object) -> dict[str, CheckResult]:
    return {r.case: r for r in check(ctx)}  # type: ignore[operator]


def _failures(results: dict[str, CheckResult]) -> list[tuple[str, str, str]]:
    return [(case, r.outcome, r.detail) for case, r in results.items() if not r.passed]


# ---------------------------------------------------------------------- the analysis alone

def test_sequence_stats_counts_a_gap_across_the_u16_wrap() -> None:
    stats = report_loss.sequence_stats([65533, 65534, 65535, 0, 2, 3])
    assert (stats.received, stats.expected, stats.lost, stats.longest_gap) == (6, 7, 1, 1)
    assert (stats.duplicates, stats.reordered, stats.misnumbered) == (0, 0, 0)
    assert stats.loss_fraction == pytest.approx(1 / 7)


def test_sequence_stats_finds_duplicates_reordering_and_misnumbering() -> None:
    stats = report_loss.sequence_stats([10, 11, 11, 13, 12, 14])
    assert (stats.duplicates, stats.reordered, stats.lost) == (1, 1, 0)
    # a device that numbers only what it sends: 1 ms steps in sequence, a 2 ms step in time
    hidden = report_loss.sequence_stats([1, 2, 3, 4], [1000, 2000, 4000, 5000], 1000.0)
    assert (hidden.lost, hidden.misnumbered) == (0, 1)
    # time stamps wrap at 2^32 us without a false step
    wrapped = report_loss.sequence_stats([7, 8], [0xFFFF_FC18, 0], 1000.0)
    assert wrapped.misnumbered == 0
    assert report_loss.sequence_stats([]).received == 0


def test_gaps_at_the_hosts_own_pauses_are_excused() -> None:
    sequences = [1, 2, 3, 9, 10, 12]
    arrivals = [0.001, 0.002, 0.003, 0.060, 0.061, 0.062]  # s: the host paused 3 -> 60 ms
    stats = report_loss.sequence_stats(sequences, None, 1000.0, arrivals, [(0.003, 0.060)])
    assert (stats.lost, stats.excused, stats.unexcused) == (6, 5, 1)  # 11 lost while reading
    assert stats.loss_fraction == pytest.approx(1 / 12)
    assert report_loss.count_error(stats, 5) == 0  # the device counted the 5 it could not deliver
    assert report_loss.count_error(stats, 0) == 1  # ... but not the one lost while the host read
    assert report_loss.count_error(stats, 9) == 3  # it claims more drops than were missing
    assert report_loss.sequence_stats(sequences, None, 1000.0, arrivals, []).excused == 0


def _state(timestamp_us: int, echo_us: int, target_uv: int, texture: int) -> State:
    return State(timestamp_us=timestamp_us, sequence=timestamp_us // 1000 % 65536, flags=7,
                 x_10um=0, y_10um=0, corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0,
                 amplitude_nm=0, voltage_dv=0, current_10na=0, target_uv_x1e4=target_uv,
                 target_ev_x1e4=10000, texture=texture, faults=0, dropped_reports=0,
                 rejected_requests=0, stream_queued=0, host_time_echo_us=echo_us,
                 card_generation=3)


def test_neutral_frames_count_against_the_card_unless_the_finger_came_late() -> None:
    card = upload_integrity.LinkCard(b"", (4500, 10000))
    on_time = [_state(1000 * k, 10_000 * (k // 10), 4500, 0) for k in range(40)]
    assert upload_integrity.off_card(on_time, card, 3) == (40, 0, 0)
    assert upload_integrity.off_card(on_time, card, 4) == (0, 0, 40)  # another generation
    # a device that renders nothing for 10 ms while the finger samples come every 10 ms
    stopped = [*on_time[:20], *(_state(1000 * k, 10_000 * (k // 10), 10000, -1)
                                for k in range(20, 30)), *on_time[30:]]
    assert upload_integrity.off_card(stopped, card, 3) == (30, 0, 10)
    # the same neutral frames after an 80 ms gap in the finger stream: the renderer's answer
    late = [*on_time[:20], *(_state(1000 * k, 95_000, 10000, -1) for k in range(100, 110)),
            *(_state(1000 * k, 105_000, 4500, 0) for k in range(110, 120))]
    late_samples = upload_integrity.late_finger(late)
    assert late_samples[20:22] == [True, True] and not any(late_samples[:20])
    assert upload_integrity.off_card(late, card, 3) == (30, 10, 0)


def test_bad_uploads_end_with_commit_and_name_their_result() -> None:
    data = (REPO / "spec" / "vectors" / "cards" / "button.hcard").read_bytes()  # 46 chunks
    uploads = upload_integrity.bad_uploads(data, 4096)
    assert {case: r.name for case, (_steps, r) in uploads.items()} == REFUSALS
    for steps, _result in uploads.values():
        assert getattr(steps[-1], "action", None) == UploadAction.COMMIT
    assert uploads["oversize"][0][0].total_length == 4097
    assert uploads["bad-crc"][0][0].crc32 == crc32(data) ^ 1  # one bit off
    assert uploads["truncated"][0][0].crc32 == crc32(data)  # the others declare it right
    for case in ("unknown-major", "invalid-card"):  # another card, transferred intact
        begin, *parts, _commit = uploads[case][0]
        sent = b"".join(part.data for part in parts)
        assert sent != data and len(sent) == begin.total_length and crc32(sent) == begin.crc32
    with pytest.raises(ValueError, match="too short"):
        upload_integrity.bad_uploads(data[:150], 4096)


def test_link_checks_are_registered_and_need_a_driver() -> None:
    names = [c.name for c in all_checks(("device",), plugins=False)]
    assert set(LINK_CHECKS) <= set(names)
    reference = Context.for_driver("reference")
    assert list(upload_integrity.check_upload_integrity(reference)) == []
    assert list(report_loss.check_report_loss(reference)) == []


# ---------------------------------------------------------------------- the reference device

@pytest.fixture(scope="module")
def sim_results() -> dict[tuple[str, str], CheckResult]:
    report = run_suite(Context.for_driver("sim://"), ("device",), select=LINK_CHECKS)
    return {(r.check, r.case): r for r in report.results}


def test_reference_passes_both_checks_on_sim(
        sim_results: dict[tuple[str, str], CheckResult]) -> None:
    failed = [(k, r.detail) for k, r in sim_results.items() if not r.passed]
    assert not failed, failed
    assert {case for check, case in sim_results if check == "device.upload-integrity"} == \
        set(upload_integrity.UPLOAD_CASES)
    for case, reason in REFUSALS.items():
        result = sim_results["device.upload-integrity", case]
        assert result.value == 0
        assert f"expected FAILED {reason}, device said FAILED {reason}" in result.detail
    assert "device said COMMITTED" in sim_results["device.upload-integrity", "valid-after"].detail
    loss = sim_results["device.report-loss", "loss-fraction"]
    assert loss.value == 0.0 and loss.threshold == pytest.approx(0.1)  # %
    assert "0 of 30" in loss.detail  # ~3050 reports, none lost
    assert sim_results["device.report-loss", "sequence-gaps"].value == 0
    assert sim_results["device.report-loss", "drops-counted"].value == 0


def test_reference_passes_twice_over_usbip_served_by_another_process() -> None:
    with served_device("evita", cli=True) as served:
        with open_device(served.uri) as driver:
            info, hardware = driver.info(), driver.limits()
        runs = [run_suite(Context.for_driver(served.uri), ("device",), select=LINK_CHECKS)
                for _ in range(2)]
        with open_device(served.uri) as driver:
            after, status = driver.limits(), driver.upload_status()
            flags = driver.read_inputs(max_count=1)[0].flags
    for report in runs:
        assert_conforms(report.results)  # a run the machine could not keep fails saying so
        cases = {(r.check, r.case) for r in report.results}
        assert cases == {("device.upload-integrity", c) for c in upload_integrity.UPLOAD_CASES} | \
            {("device.report-loss", c) for c in report_loss.LOSS_CASES}
        loss = next(r for r in report.results if r.case == "loss-fraction")
        print(f"usbip: {loss.detail}")
    assert after == hardware  # the checks leave the limits alone
    card_a = upload_integrity.link_card(info, upload_integrity.CARD_A_FRICTION)
    assert status.active_crc32 == card_a.crc  # card A left
    assert not flags & StateFlags.RUNNING  # stopped, as found


# ---------------------------------------------------------------------- negative controls

def test_accepts_bad_crc_fails_the_bad_crc_case_only() -> None:
    results = _cases(Context.for_driver("control:accepts-bad-crc"),
                     upload_integrity.check_upload_integrity)
    bad = results["bad-crc"]
    assert not bad.passed and bad.outcome == "FAIL"
    assert "expected FAILED CRC_MISMATCH, device said COMMITTED" in bad.detail
    assert "card A" in bad.detail and "replaced" in bad.detail
    assert bad.value >= 20  # reports after the wrong commit show card B, not A
    assert not _failures({c: r for c, r in results.items() if c != "bad-crc"})


def test_reads_any_major_fails_the_unknown_major_case_only() -> None:
    """A device that reads a card of major version 2 as version 1 commits it (PU3 asks
    INVALID_CARD): the card B it was sent plays instead of A, and only ``unknown-major``
    fails; ``invalid-card`` (version 1, a baseline that is not finite) is still refused."""
    results = _cases(Context.for_driver("control:reads-any-major"),
                     upload_integrity.check_upload_integrity)
    wrong = results["unknown-major"]
    assert wrong.outcome == "FAIL"
    assert "expected FAILED INVALID_CARD, device said COMMITTED" in wrong.detail
    assert wrong.value >= 10  # reports after the wrong commit show card B, not A
    assert results["invalid-card"].passed
    assert not _failures({c: r for c, r in results.items() if c != "unknown-major"})


def test_the_invalid_cards_differ_from_card_b_only_where_the_case_says() -> None:
    """The PU3 uploads are card B with one field changed: the major version (2), or the
    baseline (not finite); the reference reader refuses each naming that field, and reads B."""
    from hcard.card_io import parse_card
    from hcard.errors import CardError

    with open_device("sim://") as driver:
        info = driver.info()
    card_b = upload_integrity.link_card(info, upload_integrity.CARD_B_FRICTION)
    parse_card(card_b.data)  # B itself is valid
    for mutate, field in ((upload_integrity.unknown_major, "version.major"),
                          (upload_integrity.broken_rule, "textures[0].baseline")):
        with pytest.raises(CardError) as caught:
            parse_card(mutate(card_b.data))
        assert caught.value.field_path == field


def test_a_commit_that_never_plays_fails_every_case_saying_why() -> None:
    """``unplayed-commit`` reports card A COMMITTED and renders nothing: every case fails (the
    card in force must play, U2; a committed one must play, U3), where they were UNASSESSED."""
    results = _cases(Context.for_driver("control:unplayed-commit"),
                     upload_integrity.check_upload_integrity)
    assert list(results) == list(upload_integrity.UPLOAD_CASES)
    for case, r in results.items():
        assert r.outcome == "FAIL", (case, r.detail)
        assert r.detail.startswith("card A committed, UPLOAD_STATUS COMMITTED"), r.detail
        assert "but 0 of" in r.detail and "a committed card must play (U2, U3)" in r.detail
        assert r.metric == "reports_off_card_a" and r.value >= 10


def test_drops_reports_fails_the_loss_fraction_only() -> None:
    results = _cases(Context.for_driver("control:drops-reports"), report_loss.check_report_loss)
    loss = results["loss-fraction"]
    assert not loss.passed
    assert 4.0 <= loss.value <= 6.0  # %, 5 % dropped at random over ~3050 reports
    assert DROPPED_FRACTION == 0.05
    assert results["sequence-gaps"].passed and results["sequence-gaps"].value == 0
    counted = results["drops-counted"]
    assert counted.passed and counted.value <= report_loss.DROP_COUNT_SLACK  # counted honestly


class SilentLossFirmware(LossyFirmware):
    """Loses 5 % of its STATE reports and numbers them, but counts none (test only)."""

    def _emit(self, data: bytes, faults: int) -> None:
        if self._draws.random() >= self.dropped_fraction:
            super(LossyFirmware, self)._emit(data, faults)
            return
        self._sequence = (self._sequence + 1) & 0xFFFF
        self.counts.input_reports += 1


class UnnumberedLossFirmware(LossyFirmware):
    """Loses 5 % of its STATE reports without numbering or counting them (test only)."""

    def _emit(self, data: bytes, faults: int) -> None:
        if self._draws.random() >= self.dropped_fraction:
            super(LossyFirmware, self)._emit(data, faults)


def _firmware_context(name: str, firmware_cls: type[LossyFirmware]) -> Context:
    return Context(name, lambda: SimDriver(
        parse_uri("sim://"), firmware_cls(DeviceSimulation(DeviceConfig.evita())),
        timeout_s=DEFAULT_TIMEOUT_S))


def test_uncounted_loss_fails_drops_counted() -> None:
    results = _cases(_firmware_context("test:silent-loss", SilentLossFirmware),
                     report_loss.check_report_loss)
    counted = results["drops-counted"]
    assert not counted.passed and counted.value > 100  # ~150 lost, 0 counted
    assert "COUNTERS input_dropped 0" in counted.detail
    assert not results["loss-fraction"].passed
    assert results["sequence-gaps"].passed


def test_unnumbered_loss_fails_sequence_gaps() -> None:
    results = _cases(_firmware_context("test:unnumbered-loss", UnnumberedLossFirmware),
                     report_loss.check_report_loss)
    gaps = results["sequence-gaps"]
    assert not gaps.passed and gaps.value > 100  # misnumbered: time steps of 2 ms, seq of 1
    assert results["loss-fraction"].passed  # the sequence alone shows no gap
    assert results["drops-counted"].passed  # nothing seen missing, nothing counted


def test_an_invalid_card_refusal_must_name_the_field() -> None:
    """PU8: INVALID_CARD's detail is the field path of the card's first error; a device that
    refuses with another detail fails the case, saying so."""
    from hcard.device.protocol import UploadResult, UploadState, UploadStatus

    card_a = upload_integrity.LinkCard(b"card A", (4500, 10000))
    for detail, named in (("textures[0].baseline", True), ("bad card", False)):
        status = UploadStatus(state=UploadState.FAILED, result=UploadResult.INVALID_CARD,
                              detail_flags=0, received=10, total_length=10,
                              active_crc32=card_a.crc, card_generation=1, detail=detail)
        result = upload_integrity.judge_refusal("invalid-card",
                                                upload_integrity.Attempt(status),
                                                UploadResult.INVALID_CARD, card_a, 1)
        assert ("(PU8)" not in result.detail) == named, result.detail
        assert "detail 'bad card', not the field path 'textures[0].baseline'" in result.detail \
            or named


class UnflaggedClipFirmware(Firmware):
    """Plays a card that asks too much clipped, as PU5 asks, but never flags CARD_CLIPPED in
    STATE (test only)."""

    def _faults(self, sim_faults: int, clipped: int) -> int:
        return super()._faults(sim_faults, clipped) & ~int(FaultBits.CARD_CLIPPED)


def test_a_clipped_card_must_commit_and_be_flagged() -> None:
    """PU5, PF3: the reference commits the UV 0 card, flags every report of it CARD_CLIPPED and
    lists it in CLIP_REPORT; a firmware that never flags it fails the case, saying how many of
    its reports went unflagged, and passes every other case."""
    reference = _cases(Context.for_driver("sim://"), upload_integrity.check_upload_integrity)
    assert reference["clipped-card"].outcome == "PASS", reference["clipped-card"].detail
    assert "CLIP_REPORT gen" in reference["clipped-card"].detail
    unflagged = _cases(Context("test:unflagged-clip", lambda: SimDriver(
        parse_uri("sim://"), UnflaggedClipFirmware(DeviceSimulation(DeviceConfig.evita())),
        timeout_s=DEFAULT_TIMEOUT_S)), upload_integrity.check_upload_integrity)
    case = unflagged["clipped-card"]
    assert case.outcome == "FAIL" and case.value >= upload_integrity.MIN_PLAYING_REPORTS
    assert "0 of" in case.detail and "flag CARD_CLIPPED" in case.detail
    assert not _failures({c: r for c, r in unflagged.items() if c != "clipped-card"})


class _TimedSim(SimDriver):
    """``sim://`` that records, for every SET_REPORT(Feature), its report ID, first byte after
    it and the timeout the driver's transport would wait for the status stage (s)."""

    def __init__(self) -> None:
        super().__init__(parse_uri("sim://"), Firmware(DeviceSimulation(DeviceConfig.evita())),
                         timeout_s=DEFAULT_TIMEOUT_S)
        self.sets: list[tuple[int, int, float]] = []

    def _set_feature(self, report: bytes) -> None:
        self.sets.append((report[0], report[1] if len(report) > 1 else -1, self.timeout_s))
        super()._set_feature(report)


def test_the_suite_waits_for_a_commit_as_long_as_the_driver_does() -> None:
    """PU12: the device holds a COMMIT's status stage until its checks end; the suite's raw
    uploads wait for it up to the driver's commit timeout (a served device's checker beside
    two busy processes took over 1 s: CI found `control OUT got no answer within 1 s`), and
    every other request keeps the driver's own 1 s."""
    from hcard.device.base import COMMIT_TIMEOUT_S
    from hcard.device.protocol.constants import ReportId

    driver = _TimedSim()
    results = list(upload_integrity.measure_upload_integrity(
        driver, lambda case: case in ("bad-crc", "valid-after")))
    assert [r.outcome for r in results] == ["PASS", "PASS"]
    ends = [(action, timeout) for rid, action, timeout in driver.sets
            if rid == ReportId.UPLOAD_END]
    commits = [t for action, t in ends if action == UploadAction.COMMIT]
    assert len(commits) >= 2 and all(t == COMMIT_TIMEOUT_S for t in commits)
    others = {t for rid, _a, t in driver.sets if rid != ReportId.UPLOAD_END}
    assert others == {DEFAULT_TIMEOUT_S}
    assert driver.timeout_s == DEFAULT_TIMEOUT_S
