"""The registry of conformance checks: the ``@check`` decorator and plugin-provided checks.

A check is a function ``(ctx: Context) -> Iterable[CheckResult]`` decorated with
:func:`check`; it yields one result per case (vector, track, fault...). Built-in checks live in
:data:`BUILTIN_MODULES`; a vendor adds checks with a plugin implementing the hook
``hcard_conformance_checks`` (entry-point group ``hcard.plugins``) that returns
:class:`Check` objects (or any object with ``name``, ``level``, ``description`` and
``run(ctx)``)::

    from hcard.plugins import hookimpl
    from hcard_conformance.registry import check

    @check(name="acme.wake-time", level="device", description="wakes within 50 ms")
    def wake_time(ctx):
        ...
        yield measured("acme.wake-time", "device", "cold", "wake_ms", wake_ms, 50.0, unit="ms")

    @hookimpl
    def hcard_conformance_checks():
        return [wake_time]

This module is itself such a plugin (the built-ins), so ``hcard plugins`` lists them.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from hcard.plugins.hookspecs import hookimpl
from hcard_conformance.result import LEVELS, CheckResult, level_index

if TYPE_CHECKING:
    from hcard.plugins.registry import PluginRegistry
    from hcard_conformance.context import Context

CheckFunction = Callable[["Context"], Iterable[CheckResult]]

BUILTIN_MODULES: tuple[str, ...] = (
    "hcard_conformance.format_level",
    "hcard_conformance.renderer_level",
    "hcard_conformance.device_level",
    "hcard_conformance.link_checks",
    "hcard_conformance.session_checks",
)
"""Modules whose ``@check`` functions are the built-in checks, in level order."""


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
    """

    kind: ClassVar[str] = "conformance-check"
    name: str
    level: str
    description: str
    func: CheckFunction
    applies: Callable[[Context], bool] | None = None

    def run(self, ctx: Context) -> Iterable[CheckResult]:
        """The check's results on ``ctx`` (a generator: the runner times each case)."""
        return self.func(ctx)

    def __call__(self, ctx: Context) -> Iterable[CheckResult]:
        return self.run(ctx)


_BUILTIN: dict[str, Check] = {}


def check(*, name: str, level: str, description: str = "",
          applies: Callable[[Context], bool] | None = None,
          registry: dict[str, Check] | None = None) -> Callable[[CheckFunction], Check]:
    """Decorator: make a function a :class:`Check` and register it.

    ``registry`` defaults to the built-in checks (used by this package's modules); a vendor
    plugin passes its own dict, or ``{}``, and returns the Check from its
    ``hcard_conformance_checks`` hook. The description defaults to the function's docstring's
    first line.

    Raises:
        ValueError: unknown level, empty name, or a name already registered.
    """
    level_index(level)
    if not name.strip():
        raise ValueError("a check needs a non-empty name")
    target = _BUILTIN if registry is None else registry

    def decorate(func: CheckFunction) -> Check:
        doc = (func.__doc__ or "").strip().splitlines()
        made = Check(name, level, description or (doc[0] if doc else ""), func, applies)
        if name in target and target[name].func is not func:
            raise ValueError(f"conformance check {name!r} is already registered")
        target[name] = made
        return made

    return decorate


def applies_to(chk: Any, ctx: Context) -> bool:
    """Whether ``chk`` concerns ``ctx``: its own ``applies`` predicate when it has one, else
    every check applies except device-level ones on an implementation without a driver."""
    predicate = getattr(chk, "applies", None)
    if predicate is not None:
        return bool(predicate(ctx))
    return chk.level != "device" or ctx.open_driver is not None


def builtin_checks() -> list[Check]:
    """The built-in checks (importing :data:`BUILTIN_MODULES`), in level order."""
    for module in BUILTIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
            warnings.warn(f"built-in conformance module {module} is not installed; its checks "
                          "are not run", stacklevel=2)
    return sorted(_BUILTIN.values(), key=lambda c: level_index(c.level))


@hookimpl
def hcard_conformance_checks() -> list[Check]:
    """The built-in conformance checks (format, renderer and device levels)."""
    return list(builtin_checks())


def _valid_plugin_check(obj: Any) -> bool:
    level = getattr(obj, "level", None)
    return (isinstance(getattr(obj, "name", None), str) and level in LEVELS
            and callable(getattr(obj, "run", None)))


def all_checks(levels: Sequence[str] = LEVELS, *, plugins: bool = True,
               registry: PluginRegistry | None = None) -> list[Check | Any]:
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
