"""A device whose clock runs at another rate than the host's leaves gaps between its reports on
the host's time line (PI3 maps a report to the echoed sample's host time plus its echo age on
the device clock). That is not report loss, and the diagnosis must say what it is."""

from __future__ import annotations

import pytest

from hcard.device.protocol import State
from hcard_conformance.realtime import clock_mismatch, clock_rate, sequence_gaps


def reports(device_rate: float, *, drop: int | None = None) -> list[State]:
    """1 s of 1 kHz reports on the device clock (each timestamp 1000 us after the previous,
    device time) of a host that sends a FINGER every 20 ms of host time: on a device clock of
    ``device_rate`` the k-th sample is placed at 20 000 k device_rate device us."""
    out = []
    for n in range(1000):
        t_dev = 1000 * n
        k = int(t_dev / (20_000 * device_rate))            # the last sample placed by then
        placed = round(20_000 * k * device_rate)
        out.append(State(
            timestamp_us=t_dev, sequence=n, flags=0, x_10um=0, y_10um=0,
            corner_forces_mn=(0, 0, 0, 0), lateral_force_mn=0, amplitude_nm=0, voltage_dv=0,
            current_10na=0, target_uv_x1e4=10_000, target_ev_x1e4=10_000, texture=-1,
            faults=0, dropped_reports=0, rejected_requests=0, stream_queued=0,
            host_time_echo_us=1_000_000 + 20_000 * k, card_generation=1,
            echo_age_us=t_dev - placed))
    if drop is not None:
        del out[drop]
    return out


@pytest.mark.parametrize("rate", [0.9, 1.0, 1.1])
def test_the_clock_rate_is_recovered_from_the_echoes(rate: float) -> None:
    assert clock_rate(reports(rate)) == pytest.approx(rate, abs=1e-4)


def test_a_slow_clock_is_named_not_taken_for_lost_reports() -> None:
    why = clock_mismatch(reports(0.9))
    assert "no report was lost" in why and "runs 10.0% slow against the host's" in why


def test_clocks_that_agree_or_lost_reports_leave_the_diagnosis_to_report_loss() -> None:
    assert clock_mismatch(reports(1.0)) == ""
    assert clock_mismatch(reports(1.005)) == ""              # within 1 %
    assert sequence_gaps(reports(0.9, drop=500)) == 1
    assert clock_mismatch(reports(0.9, drop=500)) == ""      # a report is missing: loss
