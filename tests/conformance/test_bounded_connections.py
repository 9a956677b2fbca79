"""The cases of bounded connections of ``device.session-ownership`` (spec/device-protocol.md
PN15; spec/conformance.md 4.8, O9): how a run is judged, with numbers; where the cases are
named; and the ``blocking-writes`` control, whose connections wait on their clients, failing
``beside-non-reader``. The reference served in another process passes them in
tests/conformance/test_session_ownership.py."""

from __future__ import annotations

import os

import pytest

from hcard.device import open_device
from hcard.device.priority import REALTIME_PRIORITY
from hcard_conformance import usbip_clients
from hcard_conformance.context import Context
from hcard_conformance.device_checks import connections as conn
from hcard_conformance.device_checks.connections import (
    BOUND_CASES,
    CONNECTION_CASES,
    DELIVERY_SHARE,
    HALT_CASE,
    Beside,
    judge_beside,
)
from hcard_conformance.realtime import NotKept, attempted_case
from hcard_conformance.result import FAIL, PASS
from hcard_device.controls import CATCHES
from tests.conformance.test_session_ownership import judged
from tests.helpers.served_device import served_device

CASE = "beside-non-reader"


def delivery(received: int, gap_ms: float = 3.0, seconds: float = 1.0) -> usbip_clients.Delivery:
    """What a client received over ``seconds``: ``received`` reports, the longest gap."""
    return usbip_clients.Delivery(seconds, received, gap_ms, 1000, 0)


def run(alone: int, beside: int, gap_ms: float = 3.0, **late: str) -> Beside:
    return Beside(delivery(alone), delivery(beside, gap_ms), **late)


def test_the_share_beside_is_judged_against_the_share_alone() -> None:
    kept = judge_beside(CASE, run(1000, 900))
    assert kept.outcome == PASS and kept.value == pytest.approx(0.9) and kept.threshold == 0.9
    assert "0.900 of the 1000 reports a second beside the client, 1.000 alone" in kept.detail
    low = judge_beside(CASE, run(1000, 899))
    assert low.outcome == FAIL and low.value == pytest.approx(0.899)
    assert "the share fell by more than the stated fraction (PN15)" in low.detail
    # over the share alone, not over 1000 a second: 720 of 800 keeps 0.9 of it
    assert judge_beside(CASE, run(800, 720)).outcome == PASS
    assert judge_beside(CASE, run(800, 719)).outcome == FAIL
    assert DELIVERY_SHARE == 0.9


def test_a_device_class_may_state_its_own_fraction() -> None:
    assert judge_beside(CASE, run(1000, 850), share=0.8).outcome == PASS
    assert judge_beside(CASE, run(1000, 950), share=0.96).outcome == FAIL


def test_a_stream_stopped_for_a_second_fails_whatever_the_share() -> None:
    stopped = judge_beside(CASE, run(1000, 990, gap_ms=1000.0))
    assert stopped.outcome == FAIL and stopped.value == pytest.approx(0.99)
    assert "the STATE stream stopped for 1.0 s (gaps must stay under 1 s)" in stopped.detail
    assert judge_beside(CASE, run(1000, 990, gap_ms=999.0)).outcome == PASS


def test_a_run_that_measured_the_host_alone_is_not_kept() -> None:
    with pytest.raises(NotKept, match=r"alone, the client received 0\.499 of the reports"):
        judge_beside(CASE, run(499, 0))
    with pytest.raises(NotKept, match="did not run for up to 40 ms"):
        judge_beside(CASE, run(1000, 0, late_alone="the host did not run for up to 40 ms"))
    # a failure while the host itself did not run beside the client is not kept either ...
    with pytest.raises(NotKept, match=r"the case failed so: 0\.500 of the 1000"):
        judge_beside(CASE, run(1000, 500, late_beside="the host did not run for up to 60 ms"))
    # ... but a pass on such a run stands
    assert judge_beside(CASE, run(1000, 950, late_beside="late")).outcome == PASS


def test_the_cases_are_named_only_where_the_uri_is_a_usbip_server_over_tcp() -> None:
    """``usbip://loopback`` tells connections apart but serves the device in the host's
    process, over a socket pair: no raw client can reach it."""
    assert conn.connection_case_names(Context.for_driver("usbip://loopback")) == (
        *CONNECTION_CASES, HALT_CASE)
    assert conn.connection_case_names(Context.for_driver("sim://")) == ()
    names = conn.connection_case_names(Context.for_driver("control:blocking-writes"))
    assert names == (*CONNECTION_CASES, HALT_CASE, *BOUND_CASES)
    assert set(BOUND_CASES.values()) == set(usbip_clients.HOSTILE_KINDS)


def test_the_measuring_client_reads_at_the_devices_real_time_priority() -> None:
    assert REALTIME_PRIORITY == 10
    with usbip_clients.real_time_thread() as granted:
        if granted:
            assert os.sched_getscheduler(0) == os.SCHED_RR
            assert os.sched_getparam(0).sched_priority == REALTIME_PRIORITY


@pytest.mark.wall_clock
def test_the_reference_served_in_another_process_keeps_its_share_beside_each_client() -> None:
    """Measured 0.997-1.001 of the share alone, longest gap 3-7 ms, beside every client."""
    with served_device() as served:
        for case in BOUND_CASES:
            result = judged(attempted_case(
                "device.session-ownership", "device", case,
                lambda case=case: conn.case_beside(lambda: open_device(served.uri), case)))
            assert result.outcome == PASS and result.value >= 0.9, result.detail
            assert "longest gap" in result.detail and "the hostile client:" in result.detail


@pytest.mark.wall_clock
def test_the_blocking_writes_control_fails_beside_a_client_that_stops_reading() -> None:
    """Its connections write each answer with a send that waits for the client: once the
    non-reader's socket is full, the pump waits on it and no connection gets a report (the
    control measured 0.000 of its share alone, no report for the whole second)."""
    assert CATCHES["blocking-writes"] == ("device.session-ownership", CASE)
    result = judged(attempted_case(
        "device.session-ownership", "device", CASE,
        lambda: conn.case_beside(lambda: open_device("control:blocking-writes"), CASE)))
    assert result.outcome == FAIL and result.value < 0.1, result.detail
    assert "the STATE stream stopped for" in result.detail
