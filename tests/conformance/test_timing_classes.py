"""Timing classes (spec/conformance.md section 5.2) and the run conditions every report states."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from hcard.cli.main import cli
from hcard.device.uri import parse_uri
from hcard_conformance.conformance_cmd import TIMING_NAMES
from hcard_conformance.context import Context
from hcard_conformance.device_checks.dynamics import (
    BANDWIDTH_UV_MEAN,
    BANDWIDTH_UV_SWING,
    amplitude_gain,
)
from hcard_conformance.result import CannotAssess
from hcard_conformance.runner import run_suite
from hcard_conformance.streaming import FED_ATTEMPTS, STARVED_FRACTION, require_fed, stream
from hcard_conformance.timing import REAL_TIME, TIMING_CLASSES
from hcard_device.sim_driver import SimDriver, make_firmware


def test_cli_timing_names_are_the_timing_classes_default_first() -> None:
    assert tuple(TIMING_CLASSES) == TIMING_NAMES
    assert TIMING_NAMES[0] == REAL_TIME.name


def test_software_emulation_declares_host_timed_checks_not_applicable_and_loosens_d3() -> None:
    ctx = Context.for_driver("sim://")
    ctx.options["timing"] = "software-emulation"
    report = run_suite(ctx, ("device",), select=("device.latency", "device.friction",
                                                  "device.dynamics"))
    assert set(report.not_applicable) == {"device.friction", "device.dynamics"}
    latency, read_lag = report.results
    assert latency.case == "boundary-move"
    assert latency.threshold == 250.0 and latency.passed  # ms; the sim's latency is ~1 ms
    assert read_lag.case == "host-read-lag"
    assert read_lag.threshold == 2000.0 and read_lag.passed and read_lag.value < 1.5
    assert report.conditions["timing_class"] == "software-emulation"
    assert report.conditions["device_class"] == "e-vita"
    assert "DEVICE_INFO" in report.conditions["device_class_why"]


def test_the_report_states_the_conditions_and_rejects_an_unknown_class(tmp_path) -> None:
    out = tmp_path / "r.json"
    runner = CliRunner()
    result = runner.invoke(cli, ["conformance", "--driver", "sim://", "--level", "device",
                                 "--check", "device.latency", "-q", "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert "timing class: real-time" in result.output
    report = json.loads(out.read_text())
    assert report["conditions"]["timing_class"] == "real-time"
    assert report["results"][0]["threshold"] == 10.0  # ms, D3 of a real-time host
    bad = runner.invoke(cli, ["conformance", "--driver", "sim://", "--option", "timing=warp"])
    assert bad.exit_code == 2 and "unknown timing class 'warp'" in bad.output


def test_a_starved_stream_is_not_assessed_only_beyond_the_fraction() -> None:
    reports = 700
    require_fed(int(STARVED_FRACTION * reports), reports, "at the bound")  # 35 of 700: judged
    with pytest.raises(CannotAssess, match="36 of 700 reports"):
        require_fed(int(STARVED_FRACTION * reports) + 1, reports, "one more")
    # a device that flagged reports REALTIME_LAG fell behind its own clock: the reason names
    # it, not the host
    lag = "the device flagged 38 of 700 reports REALTIME_LAG"
    with pytest.raises(CannotAssess, match="empty in 36 of 700 reports and the device flagged"
                       ) as raised:
        require_fed(int(STARVED_FRACTION * reports) + 1, reports, "lagging", lag)
    assert "the host left" not in str(raised.value)


class StallingHost(SimDriver):
    """The simulated device behind a host that is descheduled for ``stall_s`` in the middle of
    its first ``stalls`` streams (a busy machine): the device plays on while nothing is sent."""

    def __init__(self, *args: Any, stall_s: float, stalls: int, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.stall_s, self.stalls_left, self.starts = stall_s, stalls, 0
        self.frames_sent, self.stalled = 0, False

    def start(self, *args: Any, **kwargs: Any) -> Any:
        self.starts += 1
        self.frames_sent, self.stalled = 0, False
        return super().start(*args, **kwargs)

    def stream_frames(self, uv: Any, ev: Any) -> Any:
        self.frames_sent += len(uv)
        if self.stalls_left and not self.stalled and self.frames_sent > 2000:
            self.stalls_left -= 1
            self.stalled = True
            self.advance(self.stall_s)
        return super().stream_frames(uv, ev)


def stalling_host(stalls: int, stall_s: float = 0.13) -> StallingHost:
    uri = parse_uri("sim://evita")
    return StallingHost(uri, make_firmware(uri.variant, uri.seed, uri.effects),
                        stall_s=stall_s, stalls=stalls)


def test_a_stream_the_host_let_run_dry_is_played_again() -> None:
    """130 ms of host stall outlasts the 100 ms lead: the queue runs dry and the 390 Hz gain
    measures low. stream_fed plays the sine again and keeps the attempt the host fed whole,
    whose gain is that of a host that never stalled."""
    sine = BANDWIDTH_UV_MEAN + BANDWIDTH_UV_SWING * np.sin(2 * np.pi * 390.0 * np.arange(7000)
                                                          / 1e4)
    with stalling_host(stalls=1) as host:
        starved = stream(host, sine)
    assert starved.underruns >= 25  # ~30 ms of empty queue, one report per ms
    starved.require_fed("under the starved bound")  # which alone would judge it
    with stalling_host(stalls=0) as steady:
        fed_gain = amplitude_gain(steady, 390.0)
    with stalling_host(stalls=1) as host:
        again = amplitude_gain(host, 390.0)
        assert host.starts == 2
    assert again.underruns == 0
    assert again.relative == pytest.approx(fed_gain.relative, rel=0.01)
    # a host that stalls 300 ms in every attempt: starved past the bound, not assessed
    with stalling_host(stalls=FED_ATTEMPTS, stall_s=0.3) as hopeless:
        with pytest.raises(CannotAssess, match="queue empty"):
            amplitude_gain(hopeless, 390.0)
        assert hopeless.starts == FED_ATTEMPTS


def _latency(driver: SimDriver, timing: str) -> dict[str, Any]:
    from hcard_conformance.device_checks.latency import check_latency

    ctx = Context.for_driver("sim://")
    ctx.open_driver = lambda: driver
    ctx.options["timing"] = timing
    return {r.case: r for r in check_latency(ctx)}


def test_a_host_reading_late_is_timed_by_the_device_under_software_emulation() -> None:
    """A host whose reads lag the device by 300 ms: under software-emulation D3 dates each
    report by the device's account (PI3) and measures the device (~1 ms, as with a prompt
    host), while case host-read-lag measures the 300 ms backlog; a real-time host that read
    this late fails both."""
    from tests.helpers.late_transport import READ_LAG_S, LateReaderDriver

    prompt = _latency(SimDriver.open("sim://"), "real-time")
    late = _latency(LateReaderDriver(), "software-emulation")
    assert prompt["boundary-move"].passed and prompt["boundary-move"].value < 3.0  # ms
    assert prompt["host-read-lag"].passed and prompt["host-read-lag"].value < 1.5
    assert late["boundary-move"].passed
    assert late["boundary-move"].value == pytest.approx(prompt["boundary-move"].value, abs=1.0)
    lag = late["host-read-lag"]
    assert lag.passed and lag.value == pytest.approx(READ_LAG_S * 1e3, abs=2.0)
    strict = _latency(LateReaderDriver(), "real-time")
    assert not strict["boundary-move"].passed and strict["boundary-move"].value > 250.0
    assert not strict["host-read-lag"].passed
