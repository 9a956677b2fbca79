"""Check ``device.saturation`` (spec/conformance.md 4.13, threshold S3; protocol PI2): a value
past the range of its STATE field is sent as the nearest end of the range, never wrapped.

The one value a host can drive past its field from outside is a corner force: a FINGER
report carries up to 50 N (PO2's ``fn_mn``), a STATE corner force at most 32.767 N (an i16 of
mN). The host's finger presses 50 N at :data:`CORNER_MM` from the top-left corner, where a
plate on four corner supports carries ``F (1 - x/W)(1 - y/H)`` of it there, 49.2 N on the
E-ViTa's 81 x 54 mm: PI2 requires 32 767 mN in every report that applies the sample, where a
field written with the value's low 16 bits reads -16 306 mN (a finger that seems to pull the
plate) and a device that clamps elsewhere reads less.

Case ``corner-force``: metric = reports applying the sample whose top-left force is not
32 767 mN, of at least :data:`MIN_REPORTS`. Where the forces do not follow the host's finger
(a device whose sensors weigh the real finger, not the host's), the three small corners'
forces stay far from their bilinear shares (:data:`FOLLOW_TOLERANCE`), and the case is
UNASSESSED, saying so: nothing the host sends then drives a field out of range.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

from hcard.device.base import Driver
from hcard.device.protocol import Capability, State
from hcard_conformance.check_names import DEVICE_SATURATION as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, on_one_driver
from hcard_conformance.device_checks.host_finger import HostFinger
from hcard_conformance.device_checks.link_session import LinkSession
from hcard_conformance.result import CannotAssess, CheckResult
from hcard_conformance.timing import REAL_TIME, timing_class

SATURATION_CASES = ("corner-force",)
"""The cases of ``device.saturation``."""
PRESS_N = 50.0
"""The host finger's normal force, N: the top of FINGER ``fn_mn`` (PO2)."""
CORNER_MM = 0.5
"""Distance of the finger from the top-left corner along x and along y, mm."""
READ_S = 0.1
"""Reports read after the sample was sent, s (100 reports at 1 kHz)."""
MIN_REPORTS = 10
"""Fewest reports that must apply the sample."""
FORCE_MAX_MN = 32_767
"""Largest STATE corner force, mN (i16)."""
FOLLOW_TOLERANCE = 0.5
"""The three other corners follow the host's finger when their sum is within this fraction of
their bilinear share of :data:`PRESS_N` (0.77 N on the E-ViTa)."""


def bilinear_shares(width_mm: float, height_mm: float, x_mm: float, y_mm: float,
                    force_n: float) -> tuple[float, float, float, float]:
    """Corner loads (N) of ``force_n`` at (``x_mm``, ``y_mm``) on a ``width_mm`` x
    ``height_mm`` plate on four corner supports, in STATE's order: top-left (0, 0), top-right,
    bottom-left, bottom-right."""
    u, v = x_mm / width_mm, y_mm / height_mm
    return (force_n * (1 - u) * (1 - v), force_n * u * (1 - v), force_n * (1 - u) * v,
            force_n * u * v)


def judge(states: list[State], shares: tuple[float, float, float, float]) -> CheckResult:
    """The verdict of ``corner-force`` from the reports that apply the pressing sample."""
    if len(states) < MIN_REPORTS:
        raise CannotAssess(f"{len(states)} reports applied the pressing sample, "
                           f"{MIN_REPORTS} needed")
    others_n = sum(shares[1:])
    seen_n = sum(sum(s.corner_forces_mn[1:]) for s in states) / len(states) / 1000
    if abs(seen_n - others_n) > FOLLOW_TOLERANCE * others_n:
        raise CannotAssess(
            f"the corner forces do not follow the host's finger (the three small corners read "
            f"{seen_n:.3f} N, their share of {PRESS_N:g} N is {others_n:.3f} N): the device "
            "weighs its own load, and no field is driven out of range")
    wrong = [s.corner_forces_mn[0] for s in states if s.corner_forces_mn[0] != FORCE_MAX_MN]
    detail = (f"top-left share {shares[0]:.2f} N, past the field's {FORCE_MAX_MN / 1000:g} N: "
              f"{len(states) - len(wrong)} of {len(states)} reports read {FORCE_MAX_MN} mN")
    if wrong:
        detail += f"; others read {sorted(set(wrong))[:3]} mN (PI2: the nearest end, not wrapped)"
    return CheckResult(CHECK, LEVEL, "corner-force", not wrong, "reports_unsaturated",
                       float(len(wrong)), 0.0, "reports", detail)


def measure_saturation(driver: Driver, wants: Callable[[str], bool] | None = None,
                       lag_s: float = REAL_TIME.report_wait_s,
                       ) -> Iterator[CheckResult]:
    """``corner-force`` on one open driver (module docstring). The host reads :data:`READ_S`,
    then on until :data:`MIN_REPORTS` reports apply the sample, at most ``lag_s`` longer (s:
    the timing class's latency and host read lag; a guest under software emulation reads
    reports up to seconds late)."""
    if wants is not None and not wants("corner-force"):
        return
    info = driver.info()
    needed = Capability.HOST_FINGER | Capability.CORNER_FORCES
    if info.capabilities & needed != needed:
        raise CannotAssess("the device lacks HOST_FINGER or CORNER_FORCES: no host finger "
                           "drives a corner force")
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    shares = bilinear_shares(width, height, CORNER_MM, CORNER_MM, PRESS_N)
    session = LinkSession(driver)
    session.finger = HostFinger(driver, lambda _t: (CORNER_MM, CORNER_MM), force_n=PRESS_N)
    session.begin()
    try:
        session.finger.mark()
        session.finger.send()
        read = session.run_until_echoed(READ_S, lag_s, MIN_REPORTS)
        pressed = [s for s in read if s.host_time_echo_us in session.finger.after_us]
        yield judge(pressed, shares)
    finally:
        session.restore()


def check_saturation(ctx: Context) -> Iterator[CheckResult]:
    """A corner force past its field's range reads as the range's end (PI2)."""
    lag_s = timing_class(ctx).report_wait_s
    yield from on_one_driver(ctx, CHECK, SATURATION_CASES,
                             lambda driver, wants: measure_saturation(driver, wants, lag_s))
