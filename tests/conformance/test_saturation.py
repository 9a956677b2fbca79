"""Check ``device.saturation`` (spec/conformance.md 4.13, S3; protocol PI2): the reference
devices read a corner force past 32.767 N as 32 767 mN; the control that keeps the low 16
bits fails by every report; a device whose forces do not follow the host's finger and one
rendered on the host are not judged."""

from __future__ import annotations

import pytest

from hcard.device.protocol import State, StateFlags
from hcard_conformance.context import Context
from hcard_conformance.device_checks import saturation
from hcard_conformance.result import CannotAssess, CheckResult
from hcard_conformance.runner import run_suite


def _case(uri: str) -> CheckResult:
    report = run_suite(Context.for_driver(uri), ("device",), select=("device.saturation",))
    (result,) = report.results
    return result


@pytest.mark.parametrize("uri", ["sim://", "sim://coupled"])
def test_the_reference_devices_saturate_the_loaded_corner(uri: str) -> None:
    result = _case(uri)
    assert result.outcome == "PASS" and result.value == 0.0, result.detail
    assert "100 of 100 reports read 32767 mN" in result.detail


def test_a_device_that_wraps_the_force_fails_on_every_report() -> None:
    """49.23 N kept to 16 bits reads 49 230 - 65 536 = -16 306 mN (5 mN of sensor noise on
    top): every report applying the sample is wrong."""
    result = _case("control:wrapped-forces")
    assert result.outcome == "FAIL" and result.value == 100.0
    wrapped = [int(v) for v in result.detail.split("others read [")[1].split("]")[0].split(",")]
    assert all(-16_306 - 30 <= v <= -16_306 + 30 for v in wrapped)


def test_the_corner_shares_of_a_plate_on_four_supports() -> None:
    """Bilinear statics: the loads sum to the force, and at the centre each corner takes a
    quarter; 0.5 mm from the top-left corner of 81 x 54 mm the top-left takes 49.23 N of 50."""
    shares = saturation.bilinear_shares(81.0, 54.0, 40.5, 27.0, 2.0)
    assert shares == pytest.approx((0.5, 0.5, 0.5, 0.5))
    corner = saturation.bilinear_shares(81.0, 54.0, 0.5, 0.5, 50.0)
    assert sum(corner) == pytest.approx(50.0)
    assert corner[0] == pytest.approx(50 * (80.5 / 81) * (53.5 / 54))
    assert corner[0] == pytest.approx(49.23, abs=0.01) and corner[0] > 32.767


def _state(forces: tuple[int, int, int, int]) -> State:
    return State(timestamp_us=0, sequence=0, flags=int(StateFlags.RUNNING), x_10um=50,
                 y_10um=50, corner_forces_mn=forces, lateral_force_mn=0, amplitude_nm=0,
                 voltage_dv=0, current_10na=0, target_uv_x1e4=10_000, target_ev_x1e4=10_000,
                 texture=-1, faults=0, dropped_reports=0, rejected_requests=0,
                 stream_queued=0, host_time_echo_us=1, card_generation=0)


def test_forces_that_do_not_follow_the_host_finger_are_not_judged() -> None:
    """A device that weighs its own (absent) load reads ~0 at every corner: nothing drives a
    field out of range, so the case cannot be assessed; too few reports cannot either."""
    shares = saturation.bilinear_shares(81.0, 54.0, 0.5, 0.5, 50.0)
    with pytest.raises(CannotAssess, match="do not follow the host's finger"):
        saturation.judge([_state((3, -2, 4, 1))] * 20, shares)
    with pytest.raises(CannotAssess, match="3 reports applied the pressing sample"):
        saturation.judge([_state((32_767, 306, 460, 3))] * 3, shares)
    clamped_low = saturation.judge([_state((32_000, 306, 460, 3))] * 20, shares)
    assert not clamped_low.passed and clamped_low.value == 20.0


def test_a_device_rendered_on_the_host_is_not_judged() -> None:
    report = run_suite(Context.for_driver("faulty://none"), ("device",),
                       select=("device.saturation",))
    assert report.results == [] and "device.saturation" in report.not_applicable


def test_a_host_reading_late_reads_on_until_reports_apply_the_press() -> None:
    """A host whose reads lag 300 ms (a QEMU guest's backlog): under software emulation it reads
    on until reports echo the pressing FINGER, and the reference passes; a real-time host that
    late stops 20 ms after its 100 ms with none, and the case is not assessed."""
    from tests.helpers.late_transport import LateReaderDriver

    def run(timing: str) -> CheckResult:
        ctx = Context.for_driver("sim://")
        ctx.open_driver = LateReaderDriver
        ctx.options["timing"] = timing
        (result,) = saturation.check_saturation(ctx)
        return result

    late = run("software-emulation")
    assert late.outcome == "PASS" and late.value == 0.0, late.detail
    strict = run("real-time")
    assert strict.outcome == "UNASSESSED" and "0 reports applied" in strict.detail
