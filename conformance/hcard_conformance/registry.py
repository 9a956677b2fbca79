"""The registry of conformance checks: the built-in checks' table, the ``@check`` decorator and
plugin-provided checks.

A check is a function ``(ctx: Context) -> Iterable[CheckResult]``; it yields one result per case
(vector, track, fault...). A check may also *declare* its cases, the names it will report,
before it runs: a sequence of names, or a function of the Context returning them (from the
vectors' manifest, or the device's DEVICE_INFO); :func:`declared_cases` reads the declaration,
so that a case can be listed and chosen before anything is measured (the pytest plugin's
``--collect-only``, ``-k`` and node IDs). A check that can measure some of its cases alone asks
:meth:`Context.wants` which ones a run wants.

The built-in checks are the rows of :data:`BUILTIN_CHECKS`, each a :class:`LazyCheck`: name,
level and description there and only there (the name's spelling is a constant of
:mod:`hcard_conformance.check_names`, which the check's own results use too), the function,
and its case declaration, named by import path and imported when needed (``hcard plugins``
lists the checks without importing a check module, a driver or the reference device). A vendor
adds checks with a plugin implementing the hook ``hcard_conformance_checks`` (entry-point group
``hcard.plugins``) that returns :class:`Check` objects, :class:`LazyCheck` rows, or any object
with ``name``, ``level``, ``description`` and ``run(ctx)``::

    from hcard.plugins import hookimpl
    from hcard_conformance.registry import check

    @check(name="acme.wake-time", level="device", description="wakes within 50 ms",
           cases=("cold",))
    def wake_time(ctx):
        ...
        yield measured("acme.wake-time", "device", "cold", "wake_ms", wake_ms, 50.0, unit="ms")

    @hookimpl
    def hcard_conformance_checks():
        return [wake_time]

This module is itself such a plugin (the built-ins), so ``hcard plugins`` lists them.
"""

from __future__ import annotations

import pkgutil
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

from hcard.plugins.hookspecs import hookimpl
from hcard_conformance import check_names
from hcard_conformance.result import LEVELS, CheckResult, level_index

if TYPE_CHECKING:
    from hcard.plugins.registry import PluginRegistry
    from hcard_conformance.context import Context

CheckFunction = Callable[["Context"], Iterable[CheckResult]]
CaseDeclaration = Sequence[str] | Callable[["Context"], Iterable[str]]
"""What a check declares of its cases: their names, or a function of the Context naming them."""


@dataclass(frozen=True)
class Check:
    """One registered check (also a plugin object of kind ``conformance-check``).

    Attributes:
        name: unique name, ``level.what`` by convention (``renderer.friction``).
        level: ``format``, ``renderer`` or ``device``.
        description: one line: what it verifies.
        func: the function yielding :class:`CheckResult` objects.
        applies: predicate on the Context: False when the check does not concern this kind of
            implementation (it is then listed as not applicable, not run). None: the level's
            default (device checks need a driver, see :func:`applies_to`).
        cases: the cases it reports, declared before it runs (:data:`CaseDeclaration`); None:
            known only by running it.
    """

    kind: ClassVar[str] = "conformance-check"
    name: str
    level: str
    description: str
    func: CheckFunction
    applies: Callable[[Context], bool] | None = None
    cases: CaseDeclaration | None = None

    def run(self, ctx: Context) -> Iterable[CheckResult]:
        """The check's results on ``ctx`` (a generator: the runner times each case)."""
        return self.func(ctx)

    def __call__(self, ctx: Context) -> Iterable[CheckResult]:
        return self.run(ctx)


class LazyCheck(NamedTuple):  # a row of the table: defined in microseconds, nothing imported
    """A check named by import path (a :class:`~hcard.plugins.kinds.CheckPlugin`): the
    function, and its ``applies`` predicate, are imported when the check runs.

    Attributes:
        name: unique name, ``level.what``.
        level: ``format``, ``renderer`` or ``device``.
        description: one line: what it verifies.
        target: ``"package.module:function"`` yielding the :class:`CheckResult` objects.
        applies_target: ``"package.module:predicate"`` on the Context (see :class:`Check`);
            None: the level's default.
        cases_target: ``"package.module:NAME"`` of its case declaration, a tuple of names or a
            function of the Context (see :class:`Check`); None: known only by running it.
    """

    name: str
    level: str
    description: str
    target: str
    applies_target: str | None = None
    cases_target: str | None = None

    @property
    def kind(self) -> str:
        """``"conformance-check"``."""
        return "conformance-check"

    @property
    def func(self) -> CheckFunction:
        """The check's function (imported)."""
        func: CheckFunction = pkgutil.resolve_name(self.target)
        return func

    @property
    def applies(self) -> Callable[[Context], bool] | None:
        """The check's predicate (imported), or None."""
        if self.applies_target is None:
            return None
        predicate: Callable[[Context], bool] = pkgutil.resolve_name(self.applies_target)
        return predicate

    @property
    def cases(self) -> CaseDeclaration | None:
        """The check's case declaration (imported), or None."""
        if self.cases_target is None:
            return None
        declaration: CaseDeclaration = pkgutil.resolve_name(self.cases_target)
        return declaration

    def run(self, ctx: Context) -> Iterable[CheckResult]:
        """The check's results on ``ctx`` (a generator: the runner times each case)."""
        return self.func(ctx)

    def __call__(self, ctx: Context) -> Iterable[CheckResult]:
        return self.run(ctx)


BUILTIN_CHECKS: tuple[LazyCheck, ...] = (
    LazyCheck(check_names.FORMAT_PARSE, "format",
              "Q2: every vector card parses and validates, binary and JSON",
              "hcard_conformance.format_level:check_parse",
              cases_target="hcard_conformance.format_level:parse_cases"),
    LazyCheck(check_names.FORMAT_ROUND_TRIP, "format",
              "Q3: binary and JSON round trips are bit exact",
              "hcard_conformance.format_level:check_round_trip",
              cases_target="hcard_conformance.format_level:round_trip_cases"),
    LazyCheck(check_names.FORMAT_REJECT, "format",
              "Q4: every invalid vector is rejected with its documented error",
              "hcard_conformance.format_level:check_reject",
              cases_target="hcard_conformance.format_level:reject_cases"),
    LazyCheck(check_names.FORMAT_COMPAT, "format",
              "Q4b: other writers' files: unknown fields kept (V3, V4), the form read from "
              "the content (F4), JSON written by the mapping's rules (F2)",
              "hcard_conformance.format_compat:check_compat",
              cases_target="hcard_conformance.format_compat:compat_cases"),
    LazyCheck(check_names.RENDERER_EXACT, "renderer",
              "A0: every golden render reproduced frame for frame within 1e-5",
              "hcard_conformance.renderer_level:check_exact",
              "hcard_conformance.renderer_level:frame_exact",
              cases_target="hcard_conformance.renderer_level:exact_cases"),
    LazyCheck(check_names.RENDERER_FRICTION_ERROR, "renderer",
              "A1: RMS relative friction error within the 8% JND on every golden render",
              "hcard_conformance.renderer_level:check_friction_error",
              cases_target="hcard_conformance.renderer_level:friction_error_cases"),
    LazyCheck(check_names.RENDERER_COMPONENT_AMPLITUDE, "renderer",
              "A2: amplitude of each golden spectral peak within 8% of the mean friction",
              "hcard_conformance.renderer_level:check_component_amplitude",
              cases_target="hcard_conformance.renderer_level:component_amplitude_cases"),
    LazyCheck(check_names.RENDERER_COMPONENT_FREQUENCY, "renderer",
              "A3: frequency of each golden spectral peak within 5%",
              "hcard_conformance.renderer_level:check_component_frequency",
              cases_target="hcard_conformance.renderer_level:component_frequency_cases"),
    LazyCheck(check_names.RENDERER_SPATIAL_PHASE, "renderer",
              "A4: position-locked features within 2.5 mm of where they are drawn",
              "hcard_conformance.renderer_level:check_spatial_phase",
              cases_target="hcard_conformance.renderer_level:spatial_phase_cases"),
    LazyCheck(check_names.RENDERER_BOUNDARY, "renderer",
              "A5: taxtel boundaries within 2.5 mm of where they are drawn",
              "hcard_conformance.renderer_level:check_boundary",
              cases_target="hcard_conformance.renderer_level:boundary_cases"),
    LazyCheck(check_names.DEVICE_FRICTION, "device",
              "rendered friction (measured actuation) matches the card's target",
              "hcard_conformance.device_checks.friction:check_friction",
              "hcard_conformance.timing:needs_real_time_host",
              cases_target="hcard_conformance.device_checks.friction:friction_case_names"),
    LazyCheck(check_names.DEVICE_DYNAMICS, "device",
              "plate amplitude -3 dB bandwidth and rise time meet the device class",
              "hcard_conformance.device_checks.dynamics:check_dynamics",
              "hcard_conformance.timing:needs_real_time_host",
              cases_target="hcard_conformance.device_checks.dynamics:DYNAMICS_CASES"),
    LazyCheck(check_names.DEVICE_LATENCY, "device",
              "finger move to friction change, median within 10 ms (real-time host)",
              "hcard_conformance.device_checks.latency:check_latency",
              cases_target="hcard_conformance.device_checks.latency:LATENCY_CASES"),
    LazyCheck(check_names.DEVICE_SAFETY, "device",
              "measured amplitude, voltage and current never exceed the limits",
              "hcard_conformance.device_checks.safety:check_safety",
              cases_target="hcard_conformance.device_checks.safety:SAFETY_CASES"),
    LazyCheck(check_names.DEVICE_WATCHDOG, "device",
              "outputs ramp to zero and WATCHDOG is reported when the host goes silent",
              "hcard_conformance.device_checks.watchdog:check_watchdog",
              cases_target="hcard_conformance.device_checks.watchdog:WATCHDOG_CASES"),
    LazyCheck(check_names.DEVICE_UPLOAD_INTEGRITY, "device",
              "refused uploads (CRC, short, order, timeout, size) leave the card playing",
              "hcard_conformance.device_checks.upload_integrity:check_upload_integrity",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target="hcard_conformance.device_checks.upload_integrity:UPLOAD_CASES"),
    LazyCheck(check_names.DEVICE_REPORT_LOSS, "device",
              "STATE reports arrive in sequence, lose at most 0.1 %, drops are counted",
              "hcard_conformance.device_checks.report_loss:check_report_loss",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target="hcard_conformance.device_checks.report_loss:LOSS_CASES"),
    LazyCheck(check_names.DEVICE_REFUSALS, "device",
              "malformed, unknown and refused reports are counted and flagged; the device runs on",
              "hcard_conformance.device_checks.refusals:check_refusals",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target="hcard_conformance.device_checks.refusals:REFUSAL_CASES"),
    LazyCheck(check_names.DEVICE_DESCRIPTOR, "device",
              "the HID report descriptor is section 4.1's, announced at its length (PD1, PD2)",
              "hcard_conformance.device_checks.descriptor:check_descriptor",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target="hcard_conformance.device_checks.descriptor:DESCRIPTOR_CASES"),
    LazyCheck(check_names.DEVICE_SESSION_OWNERSHIP, "device",
              "a second host is refused, a takeover is reported, STOP releases the device; "
              "over USB/IP other connections cannot change, feed or halt a session",
              "hcard_conformance.device_checks.session_ownership:check_session_ownership",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target=("hcard_conformance.device_checks.session_ownership:"
                            "session_case_names")),
    LazyCheck(check_names.DEVICE_PROFILE_UPLOAD, "device",
              "a host's profile is checked and put in force, raises no limit; DEVICE_PROFILE "
              "restores the own",
              "hcard_conformance.device_checks.profile_upload:check_profile_upload",
              "hcard_conformance.wire_protocol:takes_host_profiles",
              cases_target="hcard_conformance.device_checks.profile_upload:PROFILE_CASES"),
    LazyCheck(check_names.DEVICE_HOST_DRIVER, "device",
              "the host driver refuses another major, takes any minor, reports undecodable "
              "reports and looks before changing a busy device",
              "hcard_conformance.device_checks.host_driver:check_host_driver",
              "hcard_conformance.device_checks.host_link:judges_host_driver",
              cases_target="hcard_conformance.device_checks.host_driver:CASES"),
    LazyCheck(check_names.DEVICE_SATURATION, "device",
              "a corner force past its STATE field reads as the range's end, not wrapped (PI2)",
              "hcard_conformance.device_checks.saturation:check_saturation",
              "hcard_conformance.wire_protocol:speaks_wire_protocol",
              cases_target="hcard_conformance.device_checks.saturation:SATURATION_CASES"),
)
"""The built-in checks, in level order: the one place their names (spelled in
:mod:`~hcard_conformance.check_names`), levels and descriptions are given."""


def check(*, name: str, level: str, description: str = "",
          applies: Callable[[Context], bool] | None = None,
          cases: CaseDeclaration | None = None,
          registry: dict[str, Check] | None = None) -> Callable[[CheckFunction], Check]:
    """Decorator: make a function a :class:`Check` (a vendor's; the built-ins are the rows of
    :data:`BUILTIN_CHECKS`), returned from a plugin's ``hcard_conformance_checks`` hook.

    ``registry``: a dict to add it to by name (a plugin's own collection), refused when the
    name is there already; None: not collected. The description defaults to the function's
    docstring's first line. ``cases``: the cases it reports, declared (:class:`Check`).

    Raises:
        ValueError: unknown level, empty name, or a name already registered.
    """
    level_index(level)
    if not name.strip():
        raise ValueError("a check needs a non-empty name")

    def decorate(func: CheckFunction) -> Check:
        doc = (func.__doc__ or "").strip().splitlines()
        made = Check(name, level, description or (doc[0] if doc else ""), func, applies, cases)
        if registry is not None:
            if name in registry and registry[name].func is not func:
                raise ValueError(f"conformance check {name!r} is already registered")
            registry[name] = made
        return made

    return decorate


def applies_to(chk: Any, ctx: Context) -> bool:
    """Whether ``chk`` concerns ``ctx``: its own ``applies`` predicate when it has one, else
    every check applies except device-level ones on an implementation without a driver."""
    predicate = getattr(chk, "applies", None)
    if predicate is not None:
        return bool(predicate(ctx))
    return chk.level != "device" or ctx.open_driver is not None


def declared_cases(chk: Any, ctx: Context) -> tuple[str, ...] | None:
    """The cases ``chk`` declares it reports on ``ctx``, in order, before it runs; None when it
    declares none (its ``cases`` is None or absent: known only by running it). Reading the
    declaration measures nothing (it may read the vectors, or open the device for its
    DEVICE_INFO, :meth:`Context.device_info`).

    Raises:
        ValueError: a name that is not a non-empty string, or one named twice.
        Exception: whatever the declaration raises (vectors unreadable, device unreachable).
    """
    declaration = getattr(chk, "cases", None)
    if declaration is None:
        return None
    names = tuple(declaration(ctx) if callable(declaration) else declaration)
    seen: set[str] = set()
    for case in names:
        if not isinstance(case, str) or not case.strip():
            raise ValueError(f"check {chk.name} declares a case {case!r}: not a non-empty name")
        if case in seen:
            raise ValueError(f"check {chk.name} declares case {case!r} twice")
        seen.add(case)
    return names


def builtin_checks() -> list[LazyCheck]:
    """The built-in checks (:data:`BUILTIN_CHECKS`), in level order."""
    return sorted(BUILTIN_CHECKS, key=lambda c: level_index(c.level))


@hookimpl
def hcard_conformance_checks() -> list[LazyCheck]:
    """The built-in conformance checks (format, renderer and device levels)."""
    return list(builtin_checks())


def _valid_plugin_check(obj: Any) -> bool:
    level = getattr(obj, "level", None)
    return (isinstance(getattr(obj, "name", None), str) and level in LEVELS
            and callable(getattr(obj, "run", None)))


def all_checks(levels: Sequence[str] = LEVELS, *, plugins: bool = True,
               registry: PluginRegistry | None = None) -> list[LazyCheck | Check | Any]:
    """Checks of ``levels``: built-ins first, then plugin checks, grouped in level order.

    ``registry`` defaults to the installed plugins (:func:`hcard.plugins.get_registry`); a
    plugin check whose name is a built-in's, or which lacks ``name``/``level``/``run``, is
    skipped with a warning.
    """
    wanted = {level_index(level) for level in levels}
    found: list[Any] = list(builtin_checks())
    names = {c.name for c in found}
    if plugins:
        if registry is None:
            from hcard.plugins import get_registry

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # `hcard plugins` reports broken plugins
                registry = get_registry()
                plugin_checks = registry.conformance_checks
        else:
            plugin_checks = registry.conformance_checks
        for name, obj in sorted(plugin_checks.items()):
            if name in names:
                if obj is not next(c for c in found if c.name == name):
                    warnings.warn(f"plugin conformance check {name!r} shadows a built-in one; "
                                  "it is ignored", stacklevel=2)
                continue
            if not _valid_plugin_check(obj):
                warnings.warn(f"plugin conformance check {name!r} has no valid level "
                              f"({', '.join(LEVELS)}) or run(ctx); it is ignored", stacklevel=2)
                continue
            found.append(obj)
            names.add(name)
    chosen = [c for c in found if level_index(c.level) in wanted]
    return sorted(chosen, key=lambda c: level_index(c.level))
