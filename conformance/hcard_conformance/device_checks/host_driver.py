"""Check ``device.host-driver`` (spec/conformance.md 4.10, rules HD1-HD4; protocol PV2, PV3, PE4,
PN8): the rules of the device protocol that bind the host driver, not the device.

The implementation's driver is opened as every device check opens it, and closed at once: the
check keeps its class and the attributes it was opened with
(:class:`~.host_link.DriverTemplate`). Each case connects a fresh driver of that class to a
device the suite scripts (:mod:`.host_link`: the device simulated in this process, altered for
the case, recording every request the driver sends) and runs host operations on it: the host
library's procedure (:func:`hcard.device.play.play`) and the driver's own methods. The cases
(:data:`CASES`) are those of :mod:`.host_versions` (PV2, PV3), :mod:`.host_inputs` (PE4) and
:mod:`.host_sessions` (PN8). Every verdict is a count (requests sent, operations refused,
requirements missed, sessions granted) against its rule.

The check does not apply to an implementation without a driver, to a driver that is not an
hcard :class:`~hcard.device.base.Driver` (the suite cannot put its transport on a scripted
device), or to a driver that renders on the host (its protocol is the host library's own
bookkeeping, with no transport under it: :func:`~.host_link.judges_host_driver`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

from hcard_conformance.check_names import DEVICE_HOST_DRIVER as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.device_checks.host_inputs import (
    BAD_INPUTS,
    short_feature,
    undecodable_input,
)
from hcard_conformance.device_checks.host_link import DriverTemplate
from hcard_conformance.device_checks.host_sessions import (
    abandoned_session,
    busy_device,
    takes_over,
)
from hcard_conformance.device_checks.host_versions import newer_minor, refuses_major
from hcard_conformance.result import CannotAssess, CheckResult, error_result, unassessed

Case = Callable[[DriverTemplate], CheckResult]


def _input_case(name: str) -> Case:
    return lambda template: undecodable_input(template, name)


HOST_CASES: dict[str, Case] = {
    "refuses-major": refuses_major,
    "newer-minor": newer_minor,
    **{name: _input_case(name) for name in BAD_INPUTS},
    "short-feature": short_feature,
    "busy-device": busy_device,
    "abandoned-session": abandoned_session,
    "takes-over": takes_over,
}
"""The cases by name, in order (the modules' docstrings say what each does)."""
CASES = tuple(HOST_CASES)
"""The cases of ``device.host-driver``."""


def check_host_driver(ctx: Context) -> Iterator[CheckResult]:
    """The host driver refuses an unknown major version and takes any minor of its own (PV2,
    PV3), reports undecodable reports and goes on (PE4), and looks before it changes a device
    another host's session holds (PN8)."""
    if ctx.open_driver is None:
        return
    wanted = [case for case in CASES if ctx.wants(CHECK, case)]
    try:
        with ctx.open_driver() as driver:
            template = DriverTemplate.of(driver)
    except Exception as exc:  # the driver cannot be opened: every case says why
        for case in wanted:
            yield error_result(CHECK, LEVEL, case, exc)
        return
    for case in wanted:
        try:
            yield HOST_CASES[case](template)
        except CannotAssess as exc:  # no simulated device to script
            yield unassessed(CHECK, LEVEL, case, str(exc))
        except Exception as exc:  # the suite's own failure on this case; the others go on
            yield error_result(CHECK, LEVEL, case, exc)
