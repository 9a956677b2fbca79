"""Finding installed plugins: the entry points of a group, listed and imported, or remembered
from an earlier run and imported when a hook they implement is first called.

Entry points of the ``hcard`` distribution come first (:data:`CORE_DISTRIBUTION`), then the
others sorted by distribution and entry-point name, so the outcome does not depend on
``sys.path`` order. What discovery found (each entry point and the hooks its plugin implements)
is remembered between runs (:mod:`hcard.plugins.command_cache`) when no plugin had a problem;
with it, a plugin module is imported only when a hook it implements is first called, and the
entry points are not listed again (no :mod:`importlib.metadata`).

:class:`EntryPoints` does this for a registry without knowing it: it hands each plugin it
imports to a ``register`` callable (which returns the hooks the plugin implements) and each
problem to a ``report`` callable (:class:`hcard.plugins.registry.PluginRegistry` gives its
own).
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from hcard.plugins import command_cache
from hcard.plugins.command_cache import CachedEntryPoint
from hcard.plugins.records import PluginSource, describe_exception

if TYPE_CHECKING:
    from importlib import metadata

CORE_DISTRIBUTION = "hcard"
"""Distribution whose entry points are loaded first, so built-in names cannot be shadowed."""

Register = Callable[[Any, PluginSource, int], tuple[str, ...] | None]
"""Registers a plugin found (where it came from, its place in discovery order) and returns the
names of the hooks it implements, or None when it had a problem (it is then not remembered)."""

Report = Callable[[str, str], None]
"""Records and warns a problem: (entry-point name, the full message)."""


class _Pending:
    """A remembered entry point whose plugin is imported when a hook it implements is called."""

    __slots__ = ("entry_point", "group", "order")

    def __init__(self, group: str, entry_point: CachedEntryPoint, order: int) -> None:
        self.group = group
        self.entry_point = entry_point
        self.order = order


class EntryPoints:
    """The entry points of one registry's groups: those listed and imported now
    (:meth:`load_listed`), and those remembered (:meth:`add_pending`) whose plugins are
    imported when a hook they implement is asked for (:meth:`load_pending`).

    The registry serialises the calls that touch the remembered ones (its collecting lock).
    """

    __slots__ = ("_orders", "_pending", "_register", "_report")

    def __init__(self, register: Register, report: Report, orders: Iterator[int]) -> None:
        self._register = register
        self._report = report
        self._orders = orders
        """Shared with the registry, which numbers the plugins registered in code after."""
        self._pending: list[_Pending] = []
        """Remembered entry points not imported yet, in discovery order."""

    def add_pending(self, group: str, remembered: list[CachedEntryPoint]) -> None:
        """Take ``group``'s entry points from an earlier run's discovery (its plugins numbered
        in discovery order now, imported later)."""
        self._pending += [_Pending(group, entry, next(self._orders)) for entry in remembered]

    def load_listed(self, group: str) -> None:
        """List, import and register every entry point of ``group`` now, and remember what was
        found when none had a problem (and every module has a file to check later)."""
        from importlib import metadata

        try:
            found = list(metadata.entry_points(group=group))
        except Exception as exc:  # a malformed entry_points.txt somewhere on sys.path
            self._report("entry points", f"cannot list entry points of '{group}': {exc}")
            return
        discovered: list[CachedEntryPoint] = []
        modules: list[str] = []
        clean = True
        for entry_point in sorted(found, key=_entry_point_order):
            cached = self._load_entry_point(entry_point)
            path = getattr(sys.modules.get(entry_point.module), "__file__", None)
            if cached is None:
                clean = False
            elif isinstance(path, str):
                discovered.append(cached)
                modules.append(path)
        # A problem, or a module without a file (that cannot be checked): nothing remembered.
        if clean and len(discovered) == len(found):
            command_cache.store_entry_points(group, discovered, modules)

    def _load_entry_point(self, entry_point: metadata.EntryPoint) -> CachedEntryPoint | None:
        """Import and register ``entry_point``'s plugin; what to remember of it (None when it
        cannot be imported, or had a problem)."""
        dist = entry_point.dist
        source = PluginSource(
            entry_point=entry_point.name,
            package=dist.name if dist is not None else "unknown",
            version=dist.version if dist is not None else "",
        )
        try:
            plugin = entry_point.load()
        except (Exception, SystemExit) as exc:
            self._report(
                source.entry_point,
                f"{source.label()} failed to import '{entry_point.value}': "
                f"{describe_exception(exc)}",
            )
            return None
        hooks = self._register(plugin, source, next(self._orders))
        if hooks is None:
            return None
        return CachedEntryPoint(source.entry_point, entry_point.value, source.package,
                                source.version, tuple(sorted(hooks)))

    def load_pending(self, hook_name: str | None) -> None:
        """Import and register the remembered entry points whose plugins implement
        ``hook_name`` (all of them when None), in discovery order."""
        due = [p for p in self._pending if hook_name is None or hook_name in p.entry_point.hooks]
        if not due:
            return
        self._pending = [p for p in self._pending if p not in due]
        for pending in due:
            entry = pending.entry_point
            source = PluginSource(entry.name, entry.package, entry.version)
            try:
                plugin = _import_target(entry.value)
            except (Exception, SystemExit) as exc:
                # Remembered but no longer importable (a dependency changed): discover again.
                command_cache.forget(command_cache.entry_point_cache_name(pending.group))
                self._report(
                    source.entry_point,
                    f"{source.label()} failed to import '{entry.value}': "
                    f"{describe_exception(exc)}",
                )
                continue
            self._register(plugin, source, pending.order)


def remembered_entry_points(group: str) -> list[CachedEntryPoint] | None:
    """``group``'s entry points as an earlier run's discovery found them, when that is still
    valid (:func:`hcard.plugins.command_cache.load_entry_points`), else None."""
    return command_cache.load_entry_points(group)


def distribution_of(obj: Any) -> tuple[str, str]:
    """(distribution name, version) providing the module of ``obj``, best effort."""
    from importlib import metadata

    module = obj.__name__ if isinstance(obj, types.ModuleType) else type(obj).__module__
    top = (module or "").partition(".")[0]
    try:
        names = metadata.packages_distributions().get(top, [])
    except Exception:  # a malformed distribution elsewhere must not break registration
        names = []
    for name in names:
        try:
            return name, metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return top or "unknown", ""


def _import_target(value: str) -> Any:
    """The object an entry point's ``value`` names (``module`` or ``module:attribute``,
    optionally followed by ``[extras]``), importing its module."""
    import pkgutil

    return pkgutil.resolve_name(value.partition("[")[0].strip())


def _entry_point_order(entry_point: metadata.EntryPoint) -> tuple[bool, str, str]:
    dist = entry_point.dist
    package = dist.name if dist is not None else ""
    return (package != CORE_DISTRIBUTION, package.lower(), entry_point.name)
