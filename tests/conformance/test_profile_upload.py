"""Check ``device.profile-upload`` (spec/conformance.md 4.10, U4-U5; protocol PU9-PU11): the
reference devices pass every case, measured; the controls that let a profile raise a limit,
that keep the host's profile after DEVICE_PROFILE and that skip the CRC-32 fail their case by
the number the check measures; a device that takes no profile, or is rendered on the host, or a
host that does not keep real time, is not judged by it."""

from __future__ import annotations

import dataclasses

import pytest

from hcard.device.protocol import (
    FRICTION_SCALE,
    Capability,
    DeviceInfo,
    State,
    StateFlags,
    UploadState,
    UploadStatus,
)
from hcard.device.published_profiles import published_profile
from hcard.device.uri import parse_uri
from hcard_conformance.context import Context
from hcard_conformance.device_checks import host_profiles, profile_upload
from hcard_conformance.device_checks.upload_integrity import Attempt, link_card
from hcard_conformance.result import FAIL, PASS, CheckResult
from hcard_conformance.runner import run_suite
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import SimDriver

CHECK = "device.profile-upload"


def _cases(uri: str) -> dict[str, CheckResult]:
    report = run_suite(Context.for_driver(uri), ("device",), select=(CHECK,))
    assert CHECK not in report.not_applicable
    return {r.case: r for r in report.results}


@pytest.fixture(scope="module")
def evita() -> dict[str, CheckResult]:
    return _cases("sim://")


def _info(uri: str) -> DeviceInfo:
    from hcard.device import open_device

    with open_device(uri) as driver:
        return driver.info()


def test_the_e_vita_passes_every_case(evita: dict[str, CheckResult]) -> None:
    assert list(evita) == list(profile_upload.PROFILE_CASES)
    for case, r in evita.items():
        assert r.outcome == PASS, (case, r.detail)
    for case in ("profile-committed", "profile-bad-crc", "profile-truncated", "invalid-profile",
                 "own-profile-restored"):
        assert evita[case].threshold == 0.08
        assert evita[case].value < 0.03, (case, evita[case].detail)  # RMS relative, A1 0.08
    assert "HOST_PROFILE set from report" in evita["profile-committed"].detail
    assert "0 reports without HOST_PROFILE" in evita["profile-bad-crc"].detail
    assert "EV channel: the device has none" in evita["invalid-profile"].detail  # PU9 detail
    limits = evita["limits-not-raised"]
    assert limits.value == 0 and "LIMITS read back unchanged" in limits.detail
    assert "largest output 1.000 x its limit" in limits.detail  # driven to it, never past


def test_the_coupled_stimulator_passes_every_case() -> None:
    results = _cases("sim://coupled")
    assert {r.outcome for r in results.values()} == {PASS}, {
        c: r.detail for c, r in results.items() if r.outcome != PASS}
    assert "EV channel: the profile has none" in results["invalid-profile"].detail


@pytest.mark.parametrize(("uri", "parameter"), [("sim://", "mu0"), ("sim://coupled", "uv_mu0")])
def test_the_profile_put_in_force_cannot_pass_for_the_devices_own(uri: str,
                                                                    parameter: str) -> None:
    """mu0 halved doubles the plate amplitude UV 0.7 needs (Psi ~ 1 / (w mu0), Eq. 2.30), so
    the own profile's commands read through it give 0.91 and its commands read through the own
    profile 0.452: 30 % and 35 % off the target, both over twice A1's 8 %."""
    info = _info(uri)
    own = published_profile(info)
    assert own is not None
    distinct = host_profiles.distinct_profile(own, info, 0.7, 0.08)
    assert (distinct.parameter, distinct.factor) == (parameter, 0.5)
    assert distinct.own_through_it == pytest.approx(0.21 / 0.7, abs=1e-3)
    assert distinct.it_through_own == pytest.approx(0.248 / 0.7, abs=1e-3)
    a_own, _, _ = host_profiles.commands_for(own, 0.7, True)
    a_it, _, _ = host_profiles.commands_for(distinct.profile, 0.7, True)
    assert a_it == pytest.approx(2 * a_own, rel=1e-9)


def test_the_profiles_that_must_be_refused_or_clamped() -> None:
    """On a UV-only device the wrong profile renders EV as well; on a coupled one it lacks EV
    (PU9). The raised profile asks for twice the hardware limits (PU10)."""
    evita, coupled = _info("sim://"), _info("sim://coupled")
    assert host_profiles.wrong_channels(evita).ev_model is not None
    wrong = host_profiles.wrong_channels(coupled)
    assert wrong.ev_model is None and wrong.uv_model is not None
    own = published_profile(evita)
    assert own is not None and own.limits is not None
    raised = host_profiles.raised_limits(own, evita).limits
    assert raised is not None
    assert raised.max_amplitude == pytest.approx(2 * evita.max_amplitude_nm * 1e-9)


def test_a_profile_that_raises_the_limits_fails_limits_not_raised() -> None:
    """``profile-raises-limits`` puts the profile's limits in force (clamped to the hardware's):
    with the host's 1250 nm lowered limit, the greedy card drives the plate to its 2500 nm
    hardware limit, every report under the profile over the limit."""
    results = _cases("control:profile-raises-limits")
    assert {c for c, r in results.items() if r.outcome == FAIL} == {"limits-not-raised"}
    limits = results["limits-not-raised"]
    assert limits.value > 50  # reports over the limit, of ~120 under the profile
    assert "largest output 2.000 x its limit" in limits.detail
    assert "LIMITS read back Limits(max_amplitude_nm=2500" in limits.detail


def test_a_device_profile_that_keeps_the_host_profile_fails_own_profile_restored(
        evita: dict[str, CheckResult]) -> None:
    """``sticky-profile`` clears HOST_PROFILE but renders with the host's profile: through the
    device's own profile its amplitude reads 0.452 for the card's 0.7 (35 % off)."""
    results = _cases("control:sticky-profile")
    assert {c for c, r in results.items() if r.outcome == FAIL} == {"own-profile-restored"}
    restored = results["own-profile-restored"]
    assert restored.value == pytest.approx(0.248 / 0.7, abs=0.02)
    assert "HOST_PROFILE clear from report" in restored.detail  # the flag alone would pass
    assert evita["own-profile-restored"].value < 0.03


def test_a_device_that_skips_the_crc_commits_the_corrupt_profile() -> None:
    """``accepts-bad-crc`` (its upload store never compares the CRC-32, for cards and
    profiles alike) commits the device's own profile sent with a wrong CRC: the friction read
    through the profile that should have stayed misses by ~0.26 RMS over the attempt."""
    results = _cases("control:accepts-bad-crc")
    bad = results["profile-bad-crc"]
    assert bad.outcome == FAIL and bad.value > 0.16
    assert "device said COMMITTED" in bad.detail
    assert results["profile-committed"].outcome == PASS


class _NoProfileFirmware(Firmware):
    """The reference firmware advertising no capability PROFILE (a protocol 1.0 device)."""

    def device_info(self) -> DeviceInfo:
        info = super().device_info()
        return dataclasses.replace(info, capabilities=info.capabilities & ~Capability.PROFILE)


def test_devices_that_take_no_profile_or_are_rendered_on_the_host_are_not_judged() -> None:
    def no_profile() -> SimDriver:
        return SimDriver(parse_uri("sim://"),
                         _NoProfileFirmware(DeviceSimulation(DeviceConfig.evita())))

    for ctx in (Context("no-profile", no_profile), Context.for_driver("faulty://none"),
                Context.for_driver("sim://", options={"timing": "software-emulation"})):
        report = run_suite(ctx, ("device",), select=(CHECK,))
        assert report.results == [] and report.not_applicable == [CHECK], ctx.driver_name


def test_the_check_leaves_the_device_as_it_found_it() -> None:
    """Run on one driver: afterwards the limits are those found, the device's own profile is
    in force (HOST_PROFILE clear), the device is stopped as found and the touch source is the
    internal sensor again."""
    from hcard.device import open_device

    with open_device("sim://") as driver:
        before = driver.limits()
        results = list(profile_upload.measure_profile_upload(driver))
        assert {r.outcome for r in results} == {PASS}
        assert driver.limits() == before
        driver.keepalive()
        state = driver.read_inputs(max_count=5)[-1]
    assert not state.flags & (StateFlags.HOST_PROFILE | StateFlags.RUNNING
                              | StateFlags.HOST_FINGER)
    assert state.flags & StateFlags.CARD_LOADED  # card K stays (no card can be read back)


def _state(flags: int, amplitude_nm: int, k: int) -> State:
    return State(timestamp_us=1000 * k, sequence=k, flags=flags, x_10um=0, y_10um=0,
                 corner_forces_mn=(125, 125, 125, 125), lateral_force_mn=0,
                 amplitude_nm=amplitude_nm, voltage_dv=0, current_10na=0,
                 target_uv_x1e4=7000, target_ev_x1e4=FRICTION_SCALE, texture=0, faults=0,
                 dropped_reports=0, rejected_requests=0, stream_queued=0, host_time_echo_us=k,
                 card_generation=3)


def test_the_own_profile_rendered_is_not_enough_when_host_profile_stays_set() -> None:
    """PU11 asks for both: reports that render through the own profile exactly but keep
    HOST_PROFILE set fail, saying so; the same reports with the flag cleared pass."""
    info = _info("sim://")
    own = published_profile(info)
    assert own is not None
    card = link_card(info, profile_upload.CARD_FRICTION)
    amplitude, _, _ = host_profiles.commands_for(own, 0.7, True)
    playing = int(StateFlags.CONTACT | StateFlags.RUNNING | StateFlags.CARD_LOADED)
    status = UploadStatus(UploadState.COMMITTED, 0, 0, 0, 0, card.crc, 3, "")
    for flags, passes, says in ((playing | StateFlags.HOST_PROFILE, False,
                                 "HOST_PROFILE never cleared"),
                                (playing, True, "HOST_PROFILE clear from report 0 on")):
        states = [_state(int(flags), round(amplitude * 1e9), k) for k in range(80)]
        result = profile_upload.judge_restored(Attempt(status, states=states), card, 3, own,
                                               info, 0.08)
        assert result.passed is passes and says in result.detail, result.detail
        assert result.value < 0.01  # the rendering itself is the own profile's
