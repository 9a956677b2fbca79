"""Check ``device.host-driver`` (spec/conformance.md 4.10, HD1-HD4; protocol PV2, PV3, PE4, PN8):
the host library's drivers pass every case, each negative control of the host driver fails
its case by the number its defect makes and passes the cases it does not touch, the scripted
device records what a driver sends on its own clock, and the check does not apply where no
transport can be scripted."""

from __future__ import annotations

import types
from collections.abc import Callable

import pytest

from hcard.device.base import Driver
from hcard.device.errors import SessionBusy
from hcard.device.open import open_device
from hcard.device.protocol import (
    Command,
    Control,
    Finger,
    Limits,
    ReportId,
    State,
    UploadState,
)
from hcard.device.transports.hidapi_driver import HidapiDriver, hidapi_module
from hcard.device.uri import parse_uri
from hcard.plugins import hookimpl
from hcard.plugins import registry as registry_module
from hcard.plugins.registry import PluginRegistry
from hcard_conformance.context import Context
from hcard_conformance.device_checks.host_driver import CASES, check_host_driver
from hcard_conformance.device_checks.host_link import (
    DriverTemplate,
    Request,
    ScriptedDevice,
    judges_host_driver,
)
from hcard_conformance.device_checks.host_outcomes import (
    names_any,
    names_major,
    names_number,
    stroke_card,
)
from hcard_conformance.device_checks.host_sessions import EARLIER_SESSIONS, OTHER_TOKEN
from hcard_conformance.registry import all_checks, declared_cases
from hcard_conformance.result import FAIL, PASS, UNASSESSED, CheckResult
from hcard_conformance.runner import run_suite

HID_URI = "hid://1209:0001"


def _hid_driver() -> Driver:
    """The production hidapi driver on no device at all: the check replaces its transport,
    so an unopened hidapi handle is all it needs (the class is what is judged)."""
    return HidapiDriver(parse_uri(HID_URI), hidapi_module().device(), b"")


def _context(name: str) -> Context:
    if name == HID_URI:
        return Context(HID_URI, _hid_driver)
    return Context.for_driver(name)


def _run(ctx: Context) -> dict[str, CheckResult]:
    return {r.case: r for r in check_host_driver(ctx)}


@pytest.mark.parametrize("name", ["sim://", "pyusb://loopback", "usbip://loopback", HID_URI])
def test_the_host_librarys_drivers_pass_every_case(name: str) -> None:
    results = _run(_context(name))
    assert tuple(results) == CASES
    assert {case: r.status for case, r in results.items()} == dict.fromkeys(CASES, PASS), \
        {case: r.detail for case, r in results.items() if not r.passed}
    counts = {case: r.value for case, r in results.items()}
    assert counts == dict.fromkeys(CASES, 0.0)
    assert {r.threshold for r in results.values()} == {0.0}
    busy = results["busy-device"].detail
    assert f"session {EARLIER_SESSIONS + 1}" in busy and f"token {OTHER_TOKEN}" in busy
    assert "after 150 ms of silence" in busy  # watchdog_ms 100 + the driver's 50 ms margin
    assert "ended at 10" in results["abandoned-session"].detail  # ms: watchdog_ms 100 + a report
    assert "2.3" in results["refuses-major"].detail and "major 1" in results["refuses-major"].detail


CONTROL_FAILURES: dict[str, dict[str, Callable[[CheckResult], bool]]] = {
    "host-accepts-any-major": {
        # the whole upload, play and limits went to the 2.3 device, UPLOAD_BEGIN first
        "refuses-major": lambda r: r.value >= 30 and "SET 0x22" in r.detail},
    "host-refuses-newer-minor": {
        "newer-minor": lambda r: r.value == 2.0 and "1.99" in r.detail},
    "host-crashes-on-short-report": {
        # crashed, and nothing reported; the next report still decoded
        "short-state": lambda r: r.value == 2.0 and "crashed" in r.detail
        and "unpack_from" in r.detail},
    "host-barges-in": {
        "busy-device": lambda r: r.value >= 5 and "SET 0x22" in r.detail
        and "read no STATE report before changing the device" in r.detail,
        "abandoned-session": lambda r: r.value >= 4 and "BUSY" in r.detail},
}
"""Per negative control of the host driver: the cases it fails, each with what its number
and detail must show; every other case passes."""


@pytest.mark.parametrize("name", sorted(CONTROL_FAILURES))
def test_each_control_fails_its_case_by_its_defect_and_passes_the_others(name: str) -> None:
    results = _run(Context.for_driver(f"control:{name}"))
    failing = {case for case, r in results.items() if r.status != PASS}
    assert failing == set(CONTROL_FAILURES[name]), {c: results[c].detail for c in failing}
    for case, shows in CONTROL_FAILURES[name].items():
        assert results[case].outcome == FAIL and shows(results[case]), results[case].detail


def _sim_template() -> DriverTemplate:
    with open_device("sim://") as driver:
        return DriverTemplate.of(driver)


def test_a_fresh_driver_reads_device_info_before_anything_else() -> None:
    """PV2 in the base class: an upload on a driver nobody asked for DEVICE_INFO sends GET
    DEVICE_INFO first, once, and the scripted device records it in device time."""
    device = ScriptedDevice.open()
    driver = _sim_template().connect(device)
    try:
        outcome = driver.upload_card(stroke_card(device.info()))
    finally:
        driver.close()
    assert outcome.status.state == UploadState.COMMITTED
    first = device.requests[0]
    assert (first.kind, first.data) == ("get", bytes([ReportId.DEVICE_INFO]))
    assert sum(r.data[:1] == bytes([ReportId.DEVICE_INFO]) for r in device.requests
               if r.kind == "get") == 1
    assert device.requests[1].kind == "set" and device.requests[1].data[0] == ReportId.UPLOAD_BEGIN


def test_a_fed_session_keeps_the_driver_silent_for_watchdog_ms_and_the_margin() -> None:
    """PN8 measured on the scripted device's clock: start() reads, sends nothing for
    watchdog_ms + 50 ms, and raises SessionBusy naming the live session; the other host's
    session is still live afterwards."""
    device = ScriptedDevice.open()
    info = device.info()
    granted = device.begin_other_session(OTHER_TOKEN, EARLIER_SESSIONS, fed=True)
    assert (granted.session_number, granted.session_token) == (EARLIER_SESSIONS + 1, OTHER_TOKEN)
    driver = _sim_template().connect(device)
    try:
        driver.info()
        began, sent = device.clock(), len(device.requests)
        busy = f"session {EARLIER_SESSIONS + 1} .*token {OTHER_TOKEN}"
        with pytest.raises(SessionBusy, match=busy):
            driver.start()
        waited_s = device.clock() - began
    finally:
        driver.close()
    assert device.requests[sent:] == []
    assert info.watchdog_ms == 100
    assert 0.150 <= waited_s <= 0.180  # s: watchdog_ms + SESSION_MARGIN_S, read to the report
    last = State.decode(device.delivered[-1][1])
    assert last.session_live and last.session_number == EARLIER_SESSIONS + 1


def test_requests_that_change_the_device_are_those_pn8_names() -> None:
    keepalive = Control(int(Command.KEEPALIVE)).encode()
    start = Control(int(Command.START), 5).encode()
    finger = Finger.from_si(0.0, 10.0, 10.0, 0.5, True).encode()
    limits = Limits(1000, 0, 0).encode()
    assert not Request(0.0, "output", keepalive).changes_device
    assert Request(0.0, "output", start).changes_device
    assert Request(0.0, "output", finger).changes_device
    assert Request(0.0, "set", limits).changes_device
    assert not Request(0.0, "get", bytes([ReportId.LIMITS])).changes_device
    assert Request(0.012, "set", limits).text() == "SET 0x21 at 12 ms"


def test_a_message_names_numbers_as_numbers_of_their_own() -> None:
    busy = "device busy: session 7 of another host (token 201) is live after 150 ms (spec PN8)"
    assert names_number(busy, 7) and names_number(busy, 201)
    assert not names_number(busy, 8) and not names_number(busy, 15)
    assert not names_number("after 0.7 s, 17 reports (spec PN7)", 7)
    refused = "the device speaks protocol 2.3; this driver implements major 1 (spec PV2)"
    assert names_number(refused, "2.3") and names_major(refused, 1)
    assert not names_major("the device speaks protocol 2.3 (spec PV2)", 1)
    assert names_major("this driver speaks 1.x", 1) and names_major("speaks 1.4 only", 1)
    assert names_any("STATE: 30 bytes is shorter", ("STATE", "0x01"))
    assert names_any("no input report with ID 0x7e", ("0x7E", "126"))
    assert not names_any("a bad report", ("STATE", "0x01"))


def test_the_check_is_registered_with_its_cases_declared() -> None:
    chosen = {c.name: c for c in all_checks(("device",), plugins=False)}["device.host-driver"]
    ctx = Context.for_driver("sim://")
    assert declared_cases(chosen, ctx) == CASES
    assert len(CASES) == 9


def test_there_is_nothing_to_script_without_a_protocol_transport() -> None:
    """No driver (the reference renderer), or a driver rendering on the host (a frame device:
    the faulty device of QN2): not applicable, listed so."""
    assert not judges_host_driver(Context.for_driver("reference"))
    assert not judges_host_driver(Context.for_driver("faulty://none"))
    report = run_suite(Context.for_driver("faulty://none"), ("device",),
                       select=("device.host-driver",))
    assert report.results == [] and report.not_applicable == ["device.host-driver"]


def test_without_a_simulated_device_every_case_is_unassessed(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The scripted device is the one the driver plugin of ``sim`` provides: where no plugin
    does (the host library alone, with its hidapi driver), nothing can be judged, and every
    case says why instead of failing the driver."""
    plugin = types.ModuleType("hidapi_only")
    plugin.hcard_drivers = hookimpl(lambda: [HidapiDriver])  # type: ignore[attr-defined]
    registry = PluginRegistry()
    registry.register(plugin, package="hcard", version="0")
    monkeypatch.setattr(registry_module, "_default", registry)
    results = _run(_context(HID_URI))
    assert tuple(results) == CASES
    assert {r.status for r in results.values()} == {UNASSESSED}
    assert all("no device simulated in this process" in r.detail for r in results.values())
