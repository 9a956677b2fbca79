"""The firmware against the real device simulation (spec/device-protocol.md sections 6-11):
upload state machine, feature and output handling, limits, watchdog, pacing, robustness."""

from __future__ import annotations

import contextlib
import threading
import zlib
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hcard import build
from hcard.card_io import to_bytes, to_json
from hcard.device.protocol import (
    REPORT_CLASSES,
    ClipReason,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    FaultBits,
    Finger,
    Limits,
    ProtocolError,
    ReportId,
    State,
    StateFlags,
    Stream,
    TouchSource,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadResult,
    UploadState,
    UploadStatus,
    crc32,
    decode_feature,
    decode_input,
    stream_reports,
    upload_reports,
)
from hcard.track import make_track
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation

UV_HALF = 5000
"""Target of the uniform test card A (relative friction 0.5, x 1e4)."""


def uniform_card(baseline: float, channel: str = "uv", name: str = "flat") -> bytes:
    """An 81 x 54 mm card (the E-ViTa surface) of one constant texture."""
    texture = build.texture(baseline, channel=channel, locking="position", name=name)
    return to_bytes(build.card(81.0, 54.0, taxtel_mm=27.0, textures=[texture]))


CARD_A = uniform_card(0.5)
CARD_B = uniform_card(0.8)


def make_fw(config: DeviceConfig | None = None, **kwargs: object) -> Firmware:
    return Firmware(DeviceSimulation(config or DeviceConfig.evita(), seed=1), **kwargs)  # type: ignore[arg-type]


def feature(fw: Firmware, report_id: int) -> Any:
    """GET a feature report and decode it."""
    return decode_feature(fw.get_feature(report_id))


def status(fw: Firmware) -> UploadStatus:
    report = feature(fw, ReportId.UPLOAD_STATUS)
    assert isinstance(report, UploadStatus)
    return report


def upload(fw: Firmware, data: bytes) -> UploadStatus:
    for report in upload_reports(data):
        fw.set_feature(report)
    return status(fw)


def states(fw: Firmware) -> list[State]:
    return [decode_input(r) for r in fw.take_input_reports()]


def finger(fw: Firmware, x: float, y: float, *, t: float = 0.0, contact: bool = True) -> None:
    fw.handle_output(Finger.from_si(t, x, y, 0.5, contact).encode())


def control(fw: Firmware, command: Command, argument: int = 0) -> None:
    fw.handle_output(Control(command, argument).encode())


def touching(fw: Firmware, seconds: float = 0.02, x: float = 20.0) -> list[State]:
    """Run with the host finger resting at (x, 20 mm), fed every millisecond."""
    out: list[State] = []
    for k in range(round(seconds * 1000)):
        finger(fw, x, 20.0, t=k * 1e-3)
        fw.advance(1e-3)
        out += states(fw)
    return out


# ---- device information ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("config", "kind", "caps", "plate_hz", "voltage_dv", "surface"),
    [
        (DeviceConfig.evita(), 1, 0b11111101, 60_750, 0, (8100, 5400)),
        (DeviceConfig.coupled(), 2, 0b11111111, 38_220, 20_000, (8000, 5000)),
    ],
)
def test_device_info_describes_the_device(
    config: DeviceConfig, kind: int, caps: int, plate_hz: int, voltage_dv: int,
    surface: tuple[int, int],
) -> None:
    info = feature(make_fw(config), ReportId.DEVICE_INFO)
    assert isinstance(info, DeviceInfo)
    assert (info.protocol_major, info.protocol_minor) == (1, 4)  # this document, spec 8.1
    assert info.device_kind == kind
    assert info.capabilities == caps
    assert info.plate_frequency_hz == plate_hz
    assert (info.frame_rate_hz, info.touch_rate_hz, info.input_rate_hz) == (10_000, 50, 1000)
    assert info.max_amplitude_nm == 2500
    assert info.max_voltage_dv == voltage_dv
    assert info.max_current_10na == 25_000
    assert info.max_card_bytes == 2 * 1024 * 1024
    assert (info.watchdog_ms, info.stream_capacity_frames) == (100, 2000)
    assert (info.surface_width_10um, info.surface_height_10um) == surface
    assert info.ev_carrier_hz == (440 if kind == 2 else 0)


# ---- upload ---------------------------------------------------------------------------------


def test_successful_upload_swaps_the_card() -> None:
    fw = make_fw()
    control(fw, Command.START)
    result = upload(fw, CARD_A)
    assert (result.state, result.result, result.card_generation) == (UploadState.COMMITTED, 0, 1)
    assert result.active_crc32 == zlib.crc32(CARD_A)
    assert result.received == result.total_length == len(CARD_A)
    before = touching(fw)
    assert before[-1].target_uv_x1e4 == UV_HALF
    assert before[-1].flags & StateFlags.CARD_LOADED and before[-1].card_generation == 1
    result = upload(fw, CARD_B)
    assert (result.state, result.card_generation) == (UploadState.COMMITTED, 2)
    after = touching(fw)
    assert after[-1].target_uv_x1e4 == 8000
    assert after[-1].card_generation == 2
    assert fw.counters().rejected_requests == 0


def test_state_reports_the_active_texture() -> None:
    fw = make_fw()
    textures = [build.texture(0.5, channel="uv", name="left"),
                build.texture(0.7, channel="uv", name="right")]
    card = build.card(81.0, 54.0, taxtel_mm=27.0, textures=textures,
                      texture_index=[0, 0, 1, 0, 0, 1])
    upload(fw, to_bytes(card))
    control(fw, Command.START)
    fw.advance(0.002)
    assert states(fw)[-1].texture == -1  # no finger: neutral
    left = touching(fw, 0.01, x=20.0)[-1]
    right = touching(fw, 0.01, x=70.0)[-1]
    assert (left.texture, left.target_uv_x1e4) == (0, 5000)
    assert (right.texture, right.target_uv_x1e4) == (1, 7000)


def test_json_card_is_accepted() -> None:
    fw = make_fw()
    card = build.card(81.0, 54.0, taxtel_mm=27.0, textures=[build.texture(0.6, channel="uv")])
    assert upload(fw, to_json(card).encode()).state == UploadState.COMMITTED


def _start_upload(fw: Firmware, data: bytes, chunks: int) -> None:
    """BEGIN and the first ``chunks`` DATA reports of ``data``."""
    for report in upload_reports(data)[: 1 + chunks]:
        fw.set_feature(report)


def test_upload_cut_off_midway_keeps_the_old_card_and_reports_why() -> None:
    fw = make_fw()
    control(fw, Command.START)
    upload(fw, CARD_A)
    big = uniform_card(0.8, name="x" * 300)  # several chunks
    _start_upload(fw, big, 2)
    midway = status(fw)
    assert (midway.state, midway.received, midway.total_length) == (
        UploadState.RECEIVING, 116, len(big)
    )
    assert touching(fw)[-1].flags & StateFlags.UPLOADING
    fw.set_feature(UploadEnd(1).encode())  # COMMIT with the rest missing
    result = status(fw)
    assert (result.state, result.result) == (UploadState.FAILED, UploadResult.SHORT)
    assert result.received == 116
    assert result.card_generation == 1 and result.active_crc32 == zlib.crc32(CARD_A)
    last = touching(fw)[-1]
    assert last.target_uv_x1e4 == UV_HALF  # the old card still plays
    assert not last.flags & StateFlags.UPLOADING
    assert fw.counters().rejected_requests == 1


def test_upload_abandoned_by_the_host_times_out() -> None:
    fw = make_fw()
    upload(fw, CARD_A)
    _start_upload(fw, CARD_B, 1)
    fw.advance(1.9)
    assert status(fw).state == UploadState.RECEIVING
    fw.advance(0.2)  # 2.1 s of device time without upload traffic
    result = status(fw)
    assert (result.state, result.result) == (UploadState.FAILED, UploadResult.TIMEOUT)
    # a late chunk does not hide the original reason
    fw.set_feature(UploadData(58, CARD_B[58:116]).encode())
    assert status(fw).result == UploadResult.TIMEOUT
    assert status(fw).card_generation == 1


def test_crc_mismatch_is_refused() -> None:
    fw = make_fw()
    upload(fw, CARD_A)
    reports = upload_reports(CARD_B)
    reports[0] = UploadBegin(len(CARD_B), crc32(CARD_B) ^ 1).encode()
    for report in reports:
        fw.set_feature(report)
    result = status(fw)
    assert (result.state, result.result) == (UploadState.FAILED, UploadResult.CRC_MISMATCH)
    assert result.active_crc32 == crc32(CARD_A)


def test_out_of_order_chunk_fails_the_upload() -> None:
    fw = make_fw()
    reports = upload_reports(CARD_B)
    fw.set_feature(reports[0])
    fw.set_feature(reports[2])  # offset 58 while 0 bytes were received
    result = status(fw)
    assert (result.state, result.result, result.received) == (
        UploadState.FAILED, UploadResult.OUT_OF_ORDER, 0
    )
    for report in reports[1:]:  # the rest is refused and the first reason stays
        fw.set_feature(report)
    assert status(fw).result == UploadResult.OUT_OF_ORDER
    assert status(fw).card_generation == 0
    assert fw.counters().rejected_requests == len(reports)


def test_too_large_uploads_are_refused() -> None:
    fw = make_fw(max_card_bytes=100)
    fw.set_feature(UploadBegin(101, 0).encode())
    assert (status(fw).state, status(fw).result) == (UploadState.FAILED, UploadResult.TOO_LARGE)
    fw.set_feature(UploadBegin(60, 0).encode())
    fw.set_feature(UploadData(0, bytes(58)).encode())
    fw.set_feature(UploadData(58, bytes(3)).encode())  # 61 bytes of 60
    result = status(fw)
    assert (result.result, result.received) == (UploadResult.TOO_LARGE, 58)


def test_empty_not_started_and_aborted_uploads() -> None:
    fw = make_fw()
    fw.set_feature(UploadBegin(0, 0).encode())
    assert status(fw).result == UploadResult.EMPTY
    fresh = make_fw()
    fresh.set_feature(UploadData(0, b"abc").encode())
    assert (status(fresh).state, status(fresh).result) == (
        UploadState.FAILED, UploadResult.NOT_STARTED
    )
    fresh.set_feature(UploadEnd(2).encode())  # ABORT outside an upload: ignored, no error
    assert status(fresh).result == UploadResult.NOT_STARTED
    _start_upload(fresh, CARD_A, 1)
    fresh.set_feature(UploadEnd(2).encode())
    assert (status(fresh).state, status(fresh).result) == (
        UploadState.FAILED, UploadResult.ABORTED
    )
    committed = make_fw()
    upload(committed, CARD_A)
    committed.set_feature(UploadEnd(1).encode())  # COMMIT again without BEGIN
    assert status(committed).result == UploadResult.NOT_STARTED
    assert status(committed).card_generation == 1


def test_invalid_card_reports_the_field_path() -> None:
    fw = make_fw()
    upload(fw, CARD_A)
    card = build.card(81.0, 54.0, taxtel_mm=27.0, textures=[
        build.texture(0.5, channel="uv"),
        build.texture(0.5, [build.spatial(1.0, 0.1), build.spatial(60.0, 0.1)], channel="uv"),
    ])
    result = upload(fw, to_bytes(card))
    assert (result.state, result.result) == (UploadState.FAILED, UploadResult.INVALID_CARD)
    assert result.detail == "textures[1].components[1].frequency"
    assert result.detail_flags == 0
    assert result.card_generation == 1 and touching(fw)[-1].target_uv_x1e4 == UV_HALF


def test_corrupt_card_reports_a_truncated_reason() -> None:
    fw = make_fw()
    result = upload(fw, b"\x0a\xff\xff\xff\xff\xff")  # a length prefix far past the end
    assert result.result == UploadResult.INVALID_CARD
    assert result.detail.startswith("corrupt or truncated card bytes")
    assert len(result.detail) == 46
    assert result.detail_flags == UploadStatus.DETAIL_TRUNCATED
    wrong_version = build.card(81.0, 54.0, taxtel_mm=27.0, textures=[build.texture(0.5)])
    wrong_version.version.major = 2
    assert upload(fw, to_bytes(wrong_version)).detail == "version.major"


def test_upload_reports_read_back() -> None:
    fw = make_fw()
    assert feature(fw, ReportId.UPLOAD_BEGIN) == UploadBegin(0, 0)
    _start_upload(fw, CARD_B, 1)
    assert feature(fw, ReportId.UPLOAD_BEGIN) == UploadBegin(len(CARD_B), crc32(CARD_B))
    assert feature(fw, ReportId.UPLOAD_DATA) == UploadData(58, b"")
    assert feature(fw, ReportId.UPLOAD_END) == UploadEnd(0)


def test_malformed_upload_reports_stall_and_change_nothing() -> None:
    fw = make_fw()
    _start_upload(fw, CARD_B, 1)
    for bad in (
        b"\x23" + bytes(4) + b"\x00" + bytes(58),  # length 0
        b"\x24\x00",  # action NONE
        b"\x24\x07",  # unknown action
        b"\x22\x01\x00",  # short BEGIN
    ):
        with pytest.raises(ProtocolError):
            fw.set_feature(bad)
    assert (status(fw).state, status(fw).received) == (UploadState.RECEIVING, 58)
    assert fw.counters().rejected_requests == 4


# ---- unknown and misdirected requests -------------------------------------------------------


@pytest.mark.parametrize("report_id", [0x00, 0x01, 0x10, 0x11, 0x12, 0x28, 0x99, 0xFF])
def test_unknown_feature_ids_stall(report_id: int) -> None:
    fw = make_fw()
    with pytest.raises(ProtocolError, match="no feature report"):
        fw.get_feature(report_id)
    with pytest.raises(ProtocolError, match="no feature report"):
        fw.set_feature(bytes([report_id]) + bytes(63))
    assert fw.counters().rejected_requests == 2
    fw.advance(0.003)
    assert len(states(fw)) == 3  # still running


@pytest.mark.parametrize(
    "report_id",
    [ReportId.DEVICE_INFO, ReportId.UPLOAD_STATUS, ReportId.COUNTERS],
)
def test_read_only_features_stall_on_set(report_id: int) -> None:
    fw = make_fw()
    data = fw.get_feature(report_id)
    with pytest.raises(ProtocolError, match="read-only"):
        fw.set_feature(data)
    with pytest.raises(ProtocolError, match="empty"):
        fw.set_feature(b"")


def test_padded_feature_sets_are_accepted_and_oversized_ones_stall() -> None:
    fw = make_fw()
    fw.set_feature(Limits(1200, 0, 25_000).encode() + bytes(57))  # padded to 64 bytes
    assert feature(fw, ReportId.LIMITS) == Limits(1200, 0, 25_000)
    with pytest.raises(ProtocolError, match="64-byte"):
        fw.set_feature(Limits(1000, 0, 25_000).encode() + bytes(58))  # 65 bytes
    with pytest.raises(ProtocolError, match="shorter"):
        fw.set_feature(Limits(1000, 0, 25_000).encode()[:-1])
    assert feature(fw, ReportId.LIMITS) == Limits(1200, 0, 25_000)
    assert fw.counters().rejected_requests == 2


def test_every_feature_report_can_be_read() -> None:
    fw = make_fw()
    for cls in REPORT_CLASSES:
        if cls.KIND.name == "FEATURE":
            data = fw.get_feature(cls.REPORT_ID)
            assert len(data) == cls.size() and data[0] == cls.REPORT_ID


def test_unknown_and_malformed_outputs_are_counted_and_flagged() -> None:
    fw = make_fw()
    for bad in (
        b"",
        b"\x13" + bytes(10),  # unknown ID
        b"\x20" + bytes(36),  # a feature ID on the output path
        b"\x10" + bytes(5),  # short FINGER
        b"\x12\x09\x00",  # unknown command
        bytes(70),  # longer than 64 bytes
    ):
        fw.handle_output(bad)
    fw.advance(0.001)
    first, = states(fw)
    assert first.faults & FaultBits.INVALID_REQUEST
    assert first.rejected_requests == 6
    fw.advance(0.001)
    second, = states(fw)
    assert not second.faults & FaultBits.INVALID_REQUEST  # an event, reported once
    assert fw.counters().output_reports == 0


# ---- limits and out-of-range values ---------------------------------------------------------


def test_limits_can_only_be_lowered() -> None:
    fw = make_fw(DeviceConfig.coupled())
    assert feature(fw, ReportId.LIMITS) == Limits(2500, 20_000, 25_000)
    fw.set_feature(Limits(60_000, 65_535, 65_535).encode())  # above the hardware: clamped
    assert feature(fw, ReportId.LIMITS) == Limits(2500, 20_000, 25_000)
    fw.set_feature(Limits(1000, 5000, 10_000).encode())
    assert feature(fw, ReportId.LIMITS) == Limits(1000, 5000, 10_000)
    fw.set_feature(Limits(2000, 30_000, 25_000).encode())  # back up, at most the hardware
    assert feature(fw, ReportId.LIMITS) == Limits(2000, 20_000, 25_000)
    evita = make_fw()
    evita.set_feature(Limits(2500, 10_000, 25_000).encode())
    assert feature(evita, ReportId.LIMITS).max_voltage_dv == 0  # no EV, no voltage


def test_lowered_amplitude_limit_holds_in_the_measurements() -> None:
    fw = make_fw()
    upload(fw, uniform_card(0.0))  # asks for full friction reduction: the largest amplitude
    control(fw, Command.START)
    free = touching(fw, 0.05)
    assert max(s.amplitude_nm for s in free[-20:]) > 1500
    fw.set_feature(Limits(800, 0, 25_000).encode())
    limited = touching(fw, 0.05)
    assert max(s.amplitude_nm for s in limited[-30:]) <= 800
    assert any(s.faults & FaultBits.AMPLITUDE_LIMIT for s in limited)


def test_out_of_range_finger_is_rejected_not_applied() -> None:
    fw = make_fw()
    finger(fw, 10.0, 10.0, t=0.25)
    bad = bytearray(Finger.from_si(0.5, 10.0, 10.0, 0.5, True).encode())
    bad[13:15] = (50_001).to_bytes(2, "little")  # 50.001 N
    fw.handle_output(bytes(bad))
    fw.advance(0.001)
    state, = states(fw)
    assert state.host_time_echo_us == 250_000  # the first report, not the refused one
    assert state.faults & FaultBits.INVALID_REQUEST
    assert fw.counters().rejected_requests == 1 and fw.counters().output_reports == 1


def test_out_of_range_stream_is_rejected_not_queued() -> None:
    fw = make_fw()
    good = Stream(0, (5000,) * 15, (10_000,) * 15).encode()
    bad = bytearray(good)
    bad[4:6] = (10_001).to_bytes(2, "little")  # UV above 1
    fw.handle_output(bytes(bad))
    fw.handle_output(good)
    assert fw.sim.queued_frames == 15
    assert fw.counters().rejected_requests == 1


def test_flooding_host_never_gets_past_the_limits() -> None:
    fw = make_fw(DeviceConfig.coupled())
    fw.set_feature(Limits(1500, 8000, 5000).encode())  # 1.5 um, 800 V, 50 uA
    control(fw, Command.START)
    out: list[State] = []
    for k in range(60):  # 60 ms, a STREAM flood far above the frame rate
        finger(fw, 30.0, 20.0, t=k * 1e-3)
        for report in stream_reports([0.0] * 150, [4.0] * 150, first_seq=k * 10):
            fw.handle_output(report)
        fw.advance(1e-3)
        out += states(fw)
    assert max(s.amplitude_nm for s in out) <= 1500
    assert max(s.voltage_dv for s in out) <= 8000
    assert max(s.current_10na for s in out) <= 5000
    assert any(s.faults & FaultBits.STREAM_OVERRUN for s in out)
    assert fw.counters().stream_frames_dropped > 0
    assert out[-1].stream_queued <= 2000
    assert out[-1].flags & StateFlags.STREAMING


# ---- watchdog -------------------------------------------------------------------------------


def test_watchdog_fires_when_the_host_goes_silent() -> None:
    fw = make_fw()
    upload(fw, uniform_card(0.0))
    control(fw, Command.START)
    alive = touching(fw, 0.05)
    assert not any(s.faults & FaultBits.WATCHDOG for s in alive)
    assert alive[-1].amplitude_nm > 1500
    fw.advance(0.2)  # silence: the watchdog (100 ms) expires
    silent = states(fw)
    tripped = [s for s in silent if s.faults & FaultBits.WATCHDOG]
    assert len(tripped) == pytest.approx(101, abs=2)  # from 100 ms of silence on
    assert silent[-1].amplitude_nm < 20  # ramped to zero
    assert fw.counters().watchdog_trips == 1
    assert feature(fw, ReportId.COUNTERS).latched_faults & FaultBits.WATCHDOG
    control(fw, Command.KEEPALIVE)  # the host is back
    fw.advance(0.002)
    assert not states(fw)[-1].faults & FaultBits.WATCHDOG


# ---- input report pacing --------------------------------------------------------------------


def test_input_reports_are_paced_at_1_khz() -> None:
    fw = make_fw()
    fw.advance(0.1)
    reports = states(fw)
    assert len(reports) == 100
    assert [r.sequence for r in reports] == list(range(100))
    assert [r.timestamp_us for r in reports] == [999 * 0 + 900 + 1000 * k for k in range(100)]
    for _ in range(10):
        fw.advance(0.00035)  # 3.5 frames each: fractions carry over
    assert len(states(fw)) == 3
    assert fw.counters().input_reports == 103


def test_input_queue_is_bounded_and_drops_the_oldest() -> None:
    fw = make_fw(input_queue=16)
    fw.advance(0.1)
    kept = states(fw)
    assert len(kept) == 16
    assert kept[0].sequence == 84  # 84 oldest dropped: a gap in the sequence
    assert kept[-1].dropped_reports == 83  # counted as they happened
    fw.advance(0.001)
    nxt, = states(fw)
    assert nxt.faults & FaultBits.INPUT_DROPPED and nxt.dropped_reports == 84
    assert fw.counters().input_dropped == 84
    assert fw.latest_input_report() == nxt.encode()
    assert fw.take_input_reports(5) == []


def test_take_input_reports_honours_max_count() -> None:
    fw = make_fw()
    fw.advance(0.01)
    assert len(fw.take_input_reports(4)) == 4
    assert fw.queued_input_reports == 6
    assert len(fw.take_input_reports()) == 6


def test_latest_input_report_before_any_frame() -> None:
    state = decode_input(make_fw().latest_input_report())
    assert (state.sequence, state.texture, state.target_uv_x1e4) == (0, -1, 10_000)


# ---- streaming, commands, touch source, clip report ----------------------------------------


def test_stream_frames_are_rendered_and_gaps_counted() -> None:
    fw = make_fw()
    control(fw, Command.START)
    frames = [0.25] * 30
    for report in stream_reports(frames, [1.0] * 30, first_seq=7):
        fw.handle_output(report)
    fw.handle_output(Stream(20, (2500,), (10_000,)).encode())  # 9 expected: a gap
    assert fw.counts.stream_gaps == 1
    fw.advance(0.002)
    first, second = states(fw)
    assert first.target_uv_x1e4 == 2500 and first.flags & StateFlags.STREAMING
    assert (first.stream_queued, second.stream_queued) == (21, 11)


def test_play_card_leaves_streaming() -> None:
    fw = make_fw()
    control(fw, Command.PLAY_CARD)  # no card yet: refused
    assert fw.counters().rejected_requests == 1
    upload(fw, CARD_A)
    control(fw, Command.START)
    fw.handle_output(Stream(0, (9000,), (10_000,)).encode())
    assert touching(fw, 0.005)[-1].flags & StateFlags.STREAMING
    control(fw, Command.PLAY_CARD)
    last = touching(fw, 0.01)[-1]
    assert not last.flags & StateFlags.STREAMING and last.target_uv_x1e4 == UV_HALF


def test_start_stop_and_clear_counters() -> None:
    fw = make_fw()
    upload(fw, CARD_A)
    control(fw, Command.START)
    assert touching(fw, 0.01)[-1].flags & StateFlags.RUNNING
    control(fw, Command.STOP)
    stopped = touching(fw, 0.03)
    assert not stopped[-1].flags & StateFlags.RUNNING
    assert stopped[-1].amplitude_nm < 20
    fw.handle_output(b"\x12\x09\x00")
    assert fw.counters().rejected_requests == 1
    control(fw, Command.CLEAR_COUNTERS)
    assert fw.counters() == Counters(0, 0, 0, 0, 0, 0, 0, 0)


def test_touch_source_internal_sensor_sees_the_track() -> None:
    track = make_track(np.array([0.0, 1.0]), np.array([10.0, 60.0]), np.array([20.0, 20.0]))
    fw = make_fw(internal_track=track)
    finger(fw, 5.0, 5.0)
    fw.advance(0.001)
    assert states(fw)[-1].flags & StateFlags.HOST_FINGER
    control(fw, Command.SET_TOUCH_SOURCE, TouchSource.INTERNAL)
    fw.advance(0.1)
    last = states(fw)[-1]
    assert not last.flags & StateFlags.HOST_FINGER
    assert last.contact
    assert last.x_mm == pytest.approx(14.0, abs=1.5)  # 50 mm/s for ~0.08-0.1 s from 10 mm
    assert sum(last.corner_forces_mn) == pytest.approx(500, abs=40)
    control(fw, Command.SET_TOUCH_SOURCE, TouchSource.HOST)
    fw.advance(0.001)
    assert states(fw)[-1].flags & StateFlags.HOST_FINGER


def test_clip_report_lists_what_the_device_cannot_render() -> None:
    fw = make_fw()  # E-ViTa: no EV
    assert feature(fw, ReportId.CLIP_REPORT).item_count == 0
    card = build.card(81.0, 54.0, taxtel_mm=27.0, texture_index=[0, 1, 0, 1, 0, 1], textures=[
        build.texture(0.5, channel="uv", name="low"),
        build.texture(1.6, channel="ev", name="h\u00e9igh"),
    ])
    upload(fw, to_bytes(card))
    clip = feature(fw, ReportId.CLIP_REPORT)
    assert isinstance(clip, ClipReport)
    assert (clip.card_generation, clip.item_count, clip.clipped_textures) == (1, 1, 1)
    assert (clip.texture, clip.channel, clip.reason) == (1, 2, ClipReason.NO_EV)
    assert clip.flags == 1 << ClipReason.NO_EV
    assert (clip.target, clip.achievable) == (1.6, 1.0)
    assert clip.texture_name == "h?igh"
    assert (clip.reference_speed_mm_s, clip.reference_force_mn) == (120, 500)
    fw.set_feature(ClipReport.select(0).encode())
    with pytest.raises(ProtocolError, match="beyond the 1 clipped items"):
        fw.set_feature(ClipReport.select(1).encode())
    control(fw, Command.START)
    assert touching(fw, 0.005)[-1].faults & FaultBits.CARD_CLIPPED


def test_clip_report_follows_the_limits() -> None:
    fw = make_fw()
    upload(fw, uniform_card(0.6))
    assert feature(fw, ReportId.CLIP_REPORT).item_count == 0
    fw.set_feature(Limits(300, 0, 25_000).encode())  # 0.3 um cannot reach 0.6 at 120 mm/s
    clip = feature(fw, ReportId.CLIP_REPORT)
    assert (clip.item_count, clip.reason, clip.channel) == (1, ClipReason.AMPLITUDE, 1)
    assert clip.target == pytest.approx(0.6) and clip.achievable > 0.6
    fw.set_feature(Limits(2500, 0, 25_000).encode())
    assert feature(fw, ReportId.CLIP_REPORT).item_count == 0


# ---- robustness -----------------------------------------------------------------------------

_FEATURE_IDS = [0x20, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27]
_OUTPUT_IDS = [0x10, 0x11, 0x12]


def _sized(ids: list[int]) -> st.SearchStrategy[bytes]:
    """Bytes with a known report ID and that report's size (so many decode), or random."""
    sizes = {c.REPORT_ID: c.size() for c in REPORT_CLASSES}
    well_sized = st.sampled_from(ids).flatmap(
        lambda rid: st.binary(min_size=sizes[rid] - 1, max_size=sizes[rid] - 1).map(
            lambda body: bytes([rid]) + body
        )
    )
    return st.one_of(well_sized, st.binary(max_size=70))


_OPS = st.one_of(
    st.tuples(st.just("set"), _sized(_FEATURE_IDS)),
    st.tuples(st.just("out"), _sized(_OUTPUT_IDS)),
    st.tuples(st.just("get"), st.integers(0, 255)),
    st.tuples(st.just("run"), st.integers(1, 30)),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=st.lists(_OPS, min_size=1, max_size=40))
def test_fuzz_random_host_traffic_never_breaks_the_device(ops: list[tuple[str, object]]) -> None:
    fw = make_fw(DeviceConfig.coupled())
    upload(fw, uniform_card(1.0, channel="bipolar"))
    produced: list[State] = []
    for op, arg in ops:
        if op == "set":
            with contextlib.suppress(ProtocolError):
                fw.set_feature(arg)  # type: ignore[arg-type]
        elif op == "out":
            fw.handle_output(arg)  # type: ignore[arg-type]
        elif op == "get":
            try:
                data = fw.get_feature(arg)  # type: ignore[arg-type]
            except ProtocolError:
                assert arg not in _FEATURE_IDS
            else:
                assert arg == decode_feature(data).REPORT_ID
        else:
            fw.advance(int(arg) * 1e-3)  # type: ignore[call-overload]
        produced += states(fw)
    fw.advance(0.003)
    produced += states(fw)
    assert len(produced) >= 3  # still producing input reports
    assert max(s.amplitude_nm for s in produced) <= 2500
    assert max(s.voltage_dv for s in produced) <= 20_000
    assert max(s.current_10na for s in produced) <= 25_000
    limits = feature(fw, ReportId.LIMITS)
    assert limits.max_amplitude_nm <= 2500 and limits.max_voltage_dv <= 20_000
    assert limits.max_current_10na <= 25_000
    sequences = [s.sequence for s in produced]
    assert sequences == list(range(sequences[0], sequences[0] + len(sequences)))


@settings(max_examples=300, deadline=None)
@given(data=_sized(_OUTPUT_IDS + _FEATURE_IDS))
def test_fuzz_single_reports_only_raise_protocol_error(data: bytes) -> None:
    fw = make_fw()
    fw.handle_output(data)  # never raises
    try:
        fw.set_feature(data)
    except ProtocolError as exc:
        assert str(exc)
    fw.advance(0.001)
    assert len(states(fw)) == 1


# ---- real time ------------------------------------------------------------------------------


def test_run_realtime_follows_the_clock_and_caps_the_lag() -> None:
    fw = make_fw()
    stop = threading.Event()
    ticks = iter([0.0, 0.010, 0.020, 0.500, 0.501])

    def clock() -> float:
        try:
            return next(ticks)
        except StopIteration:
            stop.set()
            return 0.501

    fw.run_realtime(stop, period_s=0.0, clock=clock)
    # 10 + 10 ms, then 480 ms due of which 50 ms are run (lag cap), then 1 ms
    assert fw.sim.time_s == pytest.approx(0.071, abs=1e-4)
    assert len(fw.take_input_reports(1000)) == 71


def test_reports_produced_late_on_the_real_time_clock_are_flagged_and_counted() -> None:
    """Rule PI4: on time (a wake-up 1 ms after the last) nothing is flagged; a wake-up at 20 ms
    after one at 1 ms runs 19 ms at once, and the reports whose last frame is more than 5 ms
    before 20 ms (those at 1.9 .. 14.9 ms: 14 reports) are flagged, the last five not; a wake-up
    179 ms late runs 50 ms (the lag cap, the rest skipped) and every one of its 50 reports is
    flagged. COUNTERS late_reports counts them (14 + 50), latched_faults latches the bit."""
    fw = make_fw()
    stop = threading.Event()
    ticks = iter([0.0, 0.001, 0.020, 0.021, 0.200, 0.201])

    def clock() -> float:
        try:
            return next(ticks)
        except StopIteration:
            stop.set()
            return 0.201

    fw.run_realtime(stop, period_s=0.0, clock=clock)
    reports = states(fw)
    late = [s.timestamp_us for s in reports if s.faults & FaultBits.REALTIME_LAG]
    assert [s.timestamp_us for s in reports] == [900 + 1000 * k for k in range(72)]
    assert late == [1900 + 1000 * k for k in range(14)] + [21900 + 1000 * k for k in range(50)]
    counters = fw.counters()
    assert counters.late_reports == 64
    assert counters.latched_faults & FaultBits.REALTIME_LAG
    fw.handle_output(Control(Command.CLEAR_COUNTERS, 0).encode())
    assert fw.counters().late_reports == 0


def test_a_device_that_keeps_real_time_flags_nothing() -> None:
    """Wake-ups every millisecond, and a simulation stepped by hand (``sim://``, no real-time
    clock): no report carries REALTIME_LAG (PI4)."""
    fw = make_fw()
    stop = threading.Event()
    ticks = iter([k * 0.001 for k in range(101)])

    def clock() -> float:
        try:
            return next(ticks)
        except StopIteration:
            stop.set()
            return 0.1

    fw.run_realtime(stop, period_s=0.0, clock=clock)
    reports = states(fw)
    fw.advance(0.1)  # 100 ms at once, on no clock: not late
    reports += states(fw)
    assert len(reports) == 200
    assert not any(s.faults & FaultBits.REALTIME_LAG for s in reports)
    assert fw.counters().late_reports == 0


def test_a_served_device_takes_a_report_at_its_clock_not_the_lagging_simulations():
    """While run_realtime serves, the device's clock runs on between the simulation's wake-ups
    (and while its process waits for the CPU). A FINGER arriving 40 ms after the simulation's
    last step is timed at its true arrival, without running the simulation there (a step per
    report let a client flooding FINGER reports take a core): the frames before it keep the
    previous finger and the reports before it do not echo it. Taken at the simulation's last
    step, it fixed the host clock offset (PO2) 40 ms short for good, and every later sample,
    arriving on time, was placed 40 ms before it arrived."""
    fw = make_fw()
    wall = [0.0]
    stop = threading.Event()
    server = threading.Thread(target=fw.run_realtime, args=(stop,),
                              kwargs={"clock": lambda: wall[0], "period_s": 0.001})
    server.start()

    def run_until(t: float) -> None:
        while wall[0] < t - 1e-12:
            wall[0] = min(wall[0] + 0.01, t)
            while fw.sim.time_s < wall[0] - 0.0015:  # let the server catch up
                stop.wait(0.001)

    try:
        run_until(0.2)
        with fw.lock:  # the server's loop cannot step: the simulation lags the clock by 40 ms
            wall[0] += 0.040
            lagging_s = fw.sim.time_s
            assert lagging_s == pytest.approx(0.2, abs=0.002)
            fw.handle_output(Finger.from_si(10.000, 20.0, 20.0, 0.5, True).encode())
            assert fw.sim.time_s == lagging_s  # not run up to the arrival on this thread
        # later samples arrive on time: host time 10.000 is device time 0.240
        for k in range(1, 6):
            run_until(0.240 + 0.010 * k)
            fw.handle_output(Finger.from_si(10.000 + 0.010 * k, 20.0 + 0.2 * k, 20.0, 0.5,
                                            True).encode())
        run_until(0.300)
    finally:
        stop.set()
        server.join()
    reports = states(fw)
    first = [s for s in reports if s.host_time_echo_us == round(10.000 * 1e6)]
    assert first and min(s.timestamp_us for s in first) * 1e-6 >= 0.240 - 1e-6
    touching = [s for s in reports if s.flags & StateFlags.CONTACT]
    assert touching and min(s.timestamp_us for s in touching) * 1e-6 >= 0.240 - 1e-6
    for report in first:  # placed at its arrival, 0.240 s
        assert report.echo_age_us * 1e-6 == pytest.approx(report.timestamp_us * 1e-6 - 0.240,
                                                          abs=0.0015)
    last = [s for s in reports if s.host_time_echo_us == round(10.050 * 1e6)]
    assert last, "no report echoes the last sample"
    for report in last:  # placed at its arrival, 0.290 s: the age counts from there
        age_s = report.echo_age_us * 1e-6
        assert age_s == pytest.approx(report.timestamp_us * 1e-6 - 0.290, abs=0.0015)
