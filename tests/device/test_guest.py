"""Tier 3 of the reference-device tests: a real Linux kernel.

A QEMU guest (TCG software emulation) boots the Debian kernel with vhci-hcd, usbhid and hidraw;
the host root is mounted read-only over 9p; `usbip attach` inside the guest turns the device the
host serves on 127.0.0.1 into /dev/hidraw0, and the host's own Python drives it from inside the
guest.  reference_device/guest/README.md describes the machinery.

The guest tier must be installed first: `bash reference_device/guest/install.sh` (root; CI's
.ci/run does it). Under CI (environment variable CI set) a missing guest is a failure; on a
developer's machine without it these tests are skipped with the command to install it, like a
hardware test on a machine without the hardware. HCARD_SKIP_GUEST=1 skips them on request.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
GUEST = REPO / "reference_device" / "guest"
RUN_GUEST = GUEST / "run_guest.py"
# The runner's own limit is 240 s (540 s for the conformance mode, whose runs a loaded machine
# repeats, spec/conformance.md QT3); this one only catches a runner that hangs itself.
SUBPROCESS_TIMEOUT_S = 600

pytestmark = [
    pytest.mark.wall_clock,
    pytest.mark.skipif(os.environ.get("HCARD_SKIP_GUEST") == "1",
                       reason="HCARD_SKIP_GUEST=1: the QEMU guest tier is skipped on request"),
]


def _load(name: str, path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def require_guest() -> None:
    """Fail under CI, skip elsewhere, when the guest tier is not installed (CI installs it)."""
    runner = _load("hcard_guest_run_guest", RUN_GUEST)
    missing = runner.missing_parts()
    if missing:
        message = (
            f"the QEMU guest tier is not installed (missing: {', '.join(missing)}). Run "
            f"`bash reference_device/guest/install.sh` as root (CI does)."
        )
        if os.environ.get("CI", "").lower() not in ("", "0", "false"):
            pytest.fail(message, pytrace=False)
        pytest.skip(message)


def run_guest(mode: str, tmp_path: Path, *extra: str) -> dict[str, Any]:
    """Run the guest tier in `mode`; the runner's JSON summary, or a failure with the log tail."""
    log = tmp_path / f"console-{mode}.log"
    proc = subprocess.Popen(
        [sys.executable, str(RUN_GUEST), "--mode", mode, "--log", str(log), *extra],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, with QEMU and the device server
    )
    try:
        stdout, stderr = proc.communicate(timeout=SUBPROCESS_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"run_guest.py hung past {SUBPROCESS_TIMEOUT_S} s; console log: {log}")
    lines = stdout.strip().splitlines()
    summary: dict[str, Any] = json.loads(lines[-1]) if lines else {}
    if proc.returncode != 0 or not summary.get("ok"):
        pytest.fail(
            f"guest tier ({mode}) failed with exit {proc.returncode}: "
            f"{summary.get('error', 'no summary')}\n{stderr[-6000:]}",
            pytrace=False,
        )
    print(f"guest tier {mode}: boot {summary.get('boot_s')} s, total {summary.get('total_s')} s")
    return summary


def test_guest_kernel_attaches_echo_hid_device(tmp_path: Path) -> None:
    """The kernel path alone, with the usbip package's HID class: attach -> /dev/hidraw0 -> I/O."""
    require_guest()
    echo = _load("hcard_guest_echo_device", GUEST / "echo_device.py")
    summary = run_guest("echo", tmp_path)
    payload = summary["payload"]
    assert payload["kernel"].endswith("-amd64")  # the Debian kernel, not the host's
    assert payload["hidraw"] == "/dev/hidraw0"
    # The kernel's HID stack (usbhid + hid-generic) bound it on the USB/IP virtual host controller.
    assert any("hidraw0" in line and "vhci_hcd" in line for line in payload["kernel_hid_lines"])
    info = payload["raw_info"]
    assert (info["bustype"], info["vid"], info["pid"]) == (0x03, echo.VID, echo.PID)
    assert info["report_descriptor_bytes"] == len(echo.report_descriptor())
    assert payload["raw_round_trips"] == 20  # output report out, transformed input report back
    assert payload["hidapi_ok"] is True  # the hidapi package's hidraw backend, same node
    assert payload["hidapi_product"] == "hcard guest echo HID"


def test_guest_hidapi_driver_uploads_card_and_streams_track(tmp_path: Path) -> None:
    """The product path: the reference device served on 127.0.0.1, attached in the guest, driven
    by the unmodified hidapi driver: card upload with its CRC, a finger track, STATE reports."""
    require_guest()
    payload_module = _load("hcard_guest_payload", GUEST / "payload.py")
    from hcard.card_io import to_bytes
    from hcard.device.protocol import INPUT_RATE_HZ, DeviceKind, crc32

    summary = run_guest("hcard", tmp_path)
    payload = summary["payload"]
    assert payload["kernel"].endswith("-amd64")
    assert payload["hidraw"] == "/dev/hidraw0"
    assert any("hidraw0" in line and "vhci_hcd" in line for line in payload["kernel_hid_lines"])
    assert payload["device"]["device_kind"] == DeviceKind.EVITA

    # The card arrived intact: the device's active CRC-32 is the one of the card's bytes.
    expected_crc = crc32(to_bytes(payload_module.default_card()))
    upload = payload["upload"]
    assert upload["card_crc32"] == expected_crc
    assert upload["device_crc32"] == expected_crc
    assert upload["card_generation"] == 1

    # STATE reports flowed while the track played, none malformed, and the device applied the
    # host's finger updates.  The counts are loose on purpose: on an idle machine ~1800 of the
    # nominal 1 kHz x 1.8 s arrive, but a loaded machine starves the TCG guest and the device
    # then drops reports rather than queue them (by design); throughput is tier 2's business.
    nominal = INPUT_RATE_HZ * payload["track_s"]
    assert payload["inputs"] >= 100, f"{payload['inputs']} of ~{nominal:.0f} reports"
    assert payload["malformed_inputs"] == 0
    # Echoes are counted from the reports the (emulated, slow) guest manages to read: it
    # decodes a few hundred of the device's 1000 reports/s and falls behind its 50 Hz sends,
    # which then leave in bursts (only the last of a burst is ever echoed; 3-66 of 81 seen on
    # a loaded 2-core machine, sometimes all from one burst). That the device applied the
    # samples along the whole track is shown by the targets below, left and right.
    assert payload["echoed_fingers"] >= 3, payload

    # The friction target followed the finger: where the STATE reports put the finger on the
    # left half the target is that texture's constant 0.85; on the right half (baseline 0.45 with
    # a grating, clipped to what E-ViTa reaches) it goes well below that; and it changed after
    # the finger crossed x = 10 mm.  The finger dwells at either end until the guest has read 30
    # touching reports placing it there (one CI run played the track blind with the guest's
    # reads 1.3 s late and saw none on the left).  Median on the left, minimum on the right: a
    # guest starved of CPU (a loaded machine) sends its finger updates late and in bursts; then
    # the watchdog ramps the outputs to zero (target 1.0) in some reports, and some reports pair
    # a position on one side with a target from the other (seen with echo latencies of seconds).
    left, right = payload["target_uv_left"], payload["target_uv_right"]
    context = (
        f"left {left}, right {right}; finger echo latency {payload['finger_echo_latency_ms']} "
        f"ms (over ~100 ms: the guest was starved of CPU)"
    )
    assert left["reports"] >= 20 and right["reports"] >= 20, context
    assert abs(left["median"] - round(payload_module.CARD_LEFT_BASELINE * 1e4)) <= 100, context
    assert right["min"] < left["median"] - 2000, context  # x 1e-4 relative friction
    assert payload["friction_latency_ms"] is not None
    print(
        f"guest tier: {payload['inputs']} STATE reports ({payload['reports_lost']} lost); latency "
        f"finger -> device echo {payload['finger_echo_latency_ms']} ms, finger crossing -> "
        f"target change {payload['friction_latency_ms']} ms"
    )


def test_guest_device_level_conforms_over_hid_under_software_emulation(tmp_path: Path) -> None:
    """The device level of the conformance suite over hid:// on the guest kernel, judged with
    the software-emulation timing class (spec/conformance.md 5.2): every case the class
    applies is reported and passes, latency and report loss within the class's finite bounds,
    and the checks that need a real-time host are declared not applicable, not dropped."""
    require_guest()
    from hcard_conformance.timing import SOFTWARE_EMULATION

    summary = run_guest("conformance", tmp_path, "--timeout", "540")
    payload = summary["payload"]
    results = payload["results"]
    # Under software emulation a case that needs the host to keep real time may be
    # UNASSESSED, saying so (spec 5.2 QT2): the stream behind limits-while-driven, the first
    # host's session kept alive while a second host uploads. Nothing may FAIL or raise.
    host_timed = {("device.safety", "limits-while-driven"),
                  ("device.session-ownership", "second-host-refused")}
    # hidapi reads the report descriptor the kernel holds, never the HID descriptor that
    # announces its length: that case is UNASSESSED over hid://, saying so (PD1)
    unread = ("device.descriptor", "announced-length")
    failed = [(r["check"], r["case"], r["outcome"], r["value"], r["detail"]) for r in results
              if r["outcome"] != "PASS"
              and not (r["outcome"] == "UNASSESSED" and (r["check"], r["case"]) in host_timed
                       and "real time" in r["detail"])
              and not (r["outcome"] == "UNASSESSED" and (r["check"], r["case"]) == unread
                       and "never the HID descriptor" in r["detail"])]
    assert not failed, failed
    required = {("device.latency", "boundary-move"), ("device.watchdog", "host-silent"),
                ("device.watchdog", "fault-reported"), ("device.report-loss", "sequence-gaps"),
                ("device.latency", "host-read-lag"),
                ("device.report-loss", "loss-fraction"), ("device.report-loss", "drops-counted"),
                ("device.session-ownership", "takeover-reported"),
                ("device.session-ownership", "released-by-stop"),
                ("device.descriptor", "exact-bytes"), ("device.descriptor", "declares-reports")}
    required |= {("device.safety", c) for c in ("card-over-limit", "host-limits",
                                                "stream-extremes")}
    required |= {("device.upload-integrity", c) for c in (
        "bad-crc", "truncated", "out-of-order", "interrupted", "restarted", "oversize",
        "valid-after")}
    passed = {(r["check"], r["case"]) for r in results if r["outcome"] == "PASS"}
    assert required <= passed, sorted(required - passed)
    assert payload["conditions"]["timing_class"] == "software-emulation"
    assert payload["conditions"]["device_class"] == "e-vita"
    assert set(payload["not_applicable"]) == {"device.friction", "device.dynamics",
                                              "device.profile-upload"}
    by_case = {(r["check"], r["case"]): r for r in results}
    assert {("device.latency", "boundary-move"), ("device.safety", "card-over-limit"),
            ("device.safety", "host-limits"), ("device.safety", "stream-extremes"),
            ("device.watchdog", "host-silent"),
            ("device.watchdog", "fault-reported")} <= set(by_case)
    latency = by_case[("device.latency", "boundary-move")]
    assert latency["threshold"] == SOFTWARE_EMULATION.latency_s * 1e3
    # ms, by the device's account (PI3): its own response, without the guest's read backlog
    assert 0.0 < latency["value"] <= latency["threshold"]
    read_lag = by_case[("device.latency", "host-read-lag")]
    assert read_lag["threshold"] == SOFTWARE_EMULATION.read_lag_s * 1e3
    # ms: a report is read after it was sent (> 0), and the backlog stays within the class's
    # bound; how long it is depends on the machine (12 ms to 1 s seen), so no floor above 0
    assert 0.0 < read_lag["value"] <= read_lag["threshold"]
    loss = by_case[("device.report-loss", "loss-fraction")]
    assert loss["threshold"] == SOFTWARE_EMULATION.host_report_loss * 100  # % of reports
    assert 0.0 <= loss["value"] <= loss["threshold"]
    print(f"guest conformance: {len(results)} cases in {payload['suite_s']} s; latency "
          f"{latency['value']:.1f} ms; host read lag {read_lag['value']:.0f} ms; reports lost "
          f"{loss['value']:.2f} %")
