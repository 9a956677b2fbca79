"""Discovery and bookkeeping of hcard plugins.

Plugins are found through the entry-point group ``hcard.plugins``, the built-ins included
(``hcard_builtins``), and registered with a ``pluggy.PluginManager("hcard")``. Discovery never
raises because of a third-party package: a plugin that fails to import, to register, whose hook
raises, or whose hook returns unusable objects is skipped with an :class:`HcardPluginWarning`
naming the entry point, its distribution and the reason, and is listed in
:attr:`PluginRegistry.broken`. What discovery found (each entry point and the hooks its plugin
implements) is remembered between runs (:mod:`hcard.plugins.command_cache`); with it, a plugin
module is imported only when a hook it implements is first called, and the entry points are
not listed again (no :mod:`importlib.metadata`). Every hook implementation is called on its
own, so one broken plugin never hides the others, and only when its kind is first asked for:
looking up the image encoder imports no predictor, effect or conformance check.

>>> from hcard.plugins import get_registry
>>> encoder = get_registry().get("encoder", "image")      # doctest: +SKIP
"""

from __future__ import annotations

import bisect
import itertools
import os
import sys
import threading
import traceback
import types
import warnings
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, NamedTuple

import pluggy

from hcard.errors import PluginError
from hcard.plugins import command_cache, hookspecs
from hcard.plugins.command_cache import CachedEntryPoint
from hcard.plugins.kinds import KINDS, CommandPlugin

if TYPE_CHECKING:
    from importlib import metadata

HOOK_KINDS: dict[str, str] = {
    "hcard_encoders": "encoder",
    "hcard_predictors": "predictor",
    "hcard_drivers": "driver",
    "hcard_calibration_effects": "calibration-effect",
    "hcard_conformance_checks": "conformance-check",
}
"""Hook name -> kind of the objects it returns (one entry per kind of :data:`KINDS`)."""

_HOOK_OF_KIND = {kind: hook_name for hook_name, kind in HOOK_KINDS.items()}

COMMAND_HOOK = "hcard_commands"
"""The hook contributing subcommands (:class:`~hcard.plugins.kinds.CommandPlugin`), which are
kept apart from the plugin kinds: ``hcard --help`` lists them, ``hcard plugins`` does not."""
ALL_HOOKS = (*HOOK_KINDS, COMMAND_HOOK)
"""Every hook a plugin may implement."""

_PLUGGY_DIR = os.path.dirname(pluggy.__file__)

CORE_DISTRIBUTION = "hcard"
"""Distribution whose entry points are loaded first, so built-in names cannot be shadowed."""


class HcardPluginWarning(UserWarning):
    """A plugin was skipped (wholly or in part); the message names entry point, package, reason."""


class BrokenPlugin(NamedTuple):
    """A plugin problem found during discovery or registration.

    ``entry_point`` is the entry-point name (or the registered name of a plugin added with
    :meth:`PluginRegistry.register`); ``reason`` is the full message, as warned.
    """

    entry_point: str
    reason: str


class PluginInfo(NamedTuple):  # not a dataclass: 0.06 ms to define instead of 0.4 ms
    """One usable plugin object and where it came from.

    Attributes:
        name: the object's ``name``, unique within its kind.
        kind: one of :data:`hcard.plugins.kinds.KINDS`.
        version: version of the distribution that provided it ("" when unknown).
        package: name of that distribution (for example ``"hcard"``).
        entry_point: entry-point name in the ``hcard.plugins`` group ("" when registered in code).
        obj: the plugin object itself.
    """

    name: str
    kind: str
    version: str
    package: str
    entry_point: str
    obj: Any

    @property
    def description(self) -> str:
        """The object's one-line description ("" when it has none)."""
        return str(getattr(self.obj, "description", "") or "")


class _Source:
    """Where a registered plugin (module or object) came from. (The private records of this
    module are slotted classes, not dataclasses or named tuples: a dataclass costs ~0.3 ms to
    define, a named tuple ~0.1 ms, a slotted class ~0.01 ms, and every command taking a plugin
    imports this module.)"""

    __slots__ = ("entry_point", "package", "version")

    def __init__(self, entry_point: str, package: str, version: str) -> None:
        self.entry_point = entry_point
        self.package = package
        self.version = version

    def label(self) -> str:
        version = f" (version {self.version})" if self.version else ""
        return f"plugin '{self.entry_point}' from package '{self.package}'{version}"


class _Registered:
    """A registered plugin and the hooks it has answered.

    ``order`` is its position in registration order: discovered entry points in discovery
    order, even when imported late (:class:`_Pending`), then plugins registered in code.
    """

    __slots__ = ("collected", "order", "plugin", "source")

    def __init__(self, plugin: Any, source: _Source, order: int) -> None:
        self.plugin = plugin
        self.source = source
        self.order = order
        self.collected: set[str] = set()


class _Pending:
    """A remembered entry point whose plugin is imported when a hook it implements is called."""

    __slots__ = ("entry_point", "group", "order")

    def __init__(self, group: str, entry_point: CachedEntryPoint, order: int) -> None:
        self.group = group
        self.entry_point = entry_point
        self.order = order


def _describe(exc: BaseException) -> str:
    """``Type: message (at file:line)`` of an exception raised by plugin code."""
    message = " ".join(str(exc).split())  # one line, whatever the plugin raised
    text = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    frames = traceback.extract_tb(exc.__traceback__)
    # Point at the plugin's code, not at the import machinery or pluggy's validation.
    if frames and not frames[-1].filename.startswith(("<", _PLUGGY_DIR)):
        text += f" (at {frames[-1].filename}:{frames[-1].lineno})"
    return text


def _distribution_of(obj: Any) -> tuple[str, str]:
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


class PluginRegistry:
    """The plugins of one process, by kind and name.

    ``PluginRegistry()`` is empty; :meth:`discover` (used by :func:`get_registry`) loads the
    installed entry points. :meth:`register` adds a module or object in code, for example in a
    vendor's tests::

        registry = PluginRegistry()
        registry.register(my_vendor_plugin_module)
        encoder = registry.get("encoder", "my-encoder")
    """

    def __init__(self) -> None:
        self.plugin_manager = pluggy.PluginManager(hookspecs.PROJECT)
        self.plugin_manager.add_hookspecs(hookspecs)
        self._by_kind: dict[str, dict[str, PluginInfo]] = {kind: {} for kind in KINDS}
        self._commands: dict[str, CommandPlugin] = {}
        self._broken: list[BrokenPlugin] = []
        self._registered: list[_Registered] = []
        """Registered plugins, sorted by :attr:`_Registered.order`."""
        self._pending: list[_Pending] = []
        """Remembered entry points not imported yet, in discovery order."""
        self._orders = itertools.count()
        self._collected: set[str] = set()
        """Hooks every registered plugin has answered (the rest are called when first asked)."""
        self._collecting = threading.RLock()
        """Held while hooks are called: a thread asking for a kind waits for all its plugins."""

    @property
    def broken(self) -> list[BrokenPlugin]:
        """Every problem of the registered plugins, in the order found (calls the hooks not
        called yet)."""
        self.collect()
        return self._broken

    # ----------------------------------------------------------------------------- discovery

    @classmethod
    def discover(cls, group: str = hookspecs.ENTRY_POINT_GROUP) -> PluginRegistry:
        """A registry of every plugin installed in the entry-point ``group``; never raises."""
        registry = cls()
        registry.load_entry_points(group)
        return registry

    def load_entry_points(self, group: str = hookspecs.ENTRY_POINT_GROUP) -> None:
        """Load and register every entry point of ``group`` (its hooks are called when their
        kind is first asked for).

        Entry points of the ``hcard`` distribution come first, then the others sorted by
        distribution and entry-point name, so the outcome does not depend on ``sys.path`` order.
        Problems are warned (:class:`HcardPluginWarning`) and recorded in :attr:`broken`.

        When an earlier run's discovery of ``group`` is remembered and still valid
        (:func:`hcard.plugins.command_cache.load_entry_points`), the entry points are taken
        from it and each plugin module is imported when a hook it implements is first called.
        Otherwise they are listed and imported now, and remembered when none had a problem.
        """
        remembered = command_cache.load_entry_points(group)
        if remembered is not None:
            with self._collecting:
                self._pending += [_Pending(group, entry, next(self._orders))
                                  for entry in remembered]
                if self._collected:  # hooks already called are called on these plugins now
                    self._load_pending(None)
            return
        from importlib import metadata

        try:
            found = list(metadata.entry_points(group=group))
        except Exception as exc:  # a malformed entry_points.txt somewhere on sys.path
            self._problem("entry points", f"cannot list entry points of '{group}': {exc}")
            return
        problems = len(self._broken)
        discovered: list[CachedEntryPoint] = []
        modules: list[str] = []
        for entry_point in sorted(found, key=_entry_point_order):
            cached = self._load_entry_point(entry_point)
            path = getattr(sys.modules.get(entry_point.module), "__file__", None)
            if cached is not None and isinstance(path, str):
                discovered.append(cached)
                modules.append(path)
        # A problem, or a module without a file (that cannot be checked): nothing remembered.
        if len(self._broken) == problems and len(discovered) == len(found):
            command_cache.store_entry_points(group, discovered, modules)

    def _load_entry_point(self, entry_point: metadata.EntryPoint) -> CachedEntryPoint | None:
        """Import and register ``entry_point``'s plugin; what to remember of it (None when it
        cannot be imported)."""
        dist = entry_point.dist
        source = _Source(
            entry_point=entry_point.name,
            package=dist.name if dist is not None else "unknown",
            version=dist.version if dist is not None else "",
        )
        try:
            plugin = entry_point.load()
        except (Exception, SystemExit) as exc:
            self._problem(
                source.entry_point,
                f"{source.label()} failed to import '{entry_point.value}': {_describe(exc)}",
            )
            return None
        self._add(plugin, source, strict=False, order=next(self._orders))
        hooks = self.plugin_manager.get_hookcallers(plugin) or []
        return CachedEntryPoint(source.entry_point, entry_point.value, source.package,
                                source.version, tuple(sorted(c.name for c in hooks)))

    def _load_pending(self, hook_name: str | None) -> None:
        """Import and register the remembered entry points whose plugins implement
        ``hook_name`` (all of them when None), in discovery order. Call with
        :attr:`_collecting` held."""
        due = [p for p in self._pending if hook_name is None or hook_name in p.entry_point.hooks]
        if not due:
            return
        self._pending = [p for p in self._pending if p not in due]
        for pending in due:
            entry = pending.entry_point
            source = _Source(entry.name, entry.package, entry.version)
            try:
                plugin = _import_target(entry.value)
            except (Exception, SystemExit) as exc:
                # Remembered but no longer importable (a dependency changed): discover again.
                command_cache.forget(command_cache.entry_point_cache_name(pending.group))
                self._problem(
                    source.entry_point,
                    f"{source.label()} failed to import '{entry.value}': {_describe(exc)}",
                )
                continue
            self._add(plugin, source, strict=False, order=pending.order)

    # ---------------------------------------------------------------------- registration

    def register(
        self,
        plugin: Any,
        *,
        name: str | None = None,
        package: str | None = None,
        version: str | None = None,
    ) -> list[PluginInfo]:
        """Register a module or object implementing hcard hooks, and collect its plugins.

        ``name`` defaults to the module name, ``package`` and ``version`` to the distribution
        that installed the module (when there is one). Unlike discovery this is strict: any
        problem raises :class:`PluginError` and leaves the registry unchanged.

        Returns:
            The :class:`PluginInfo` of every object the plugin provided.
        """
        default_package, default_version = _distribution_of(plugin)
        label = name or getattr(plugin, "__name__", None) or type(plugin).__name__
        source = _Source(
            entry_point=label,
            package=package or default_package,
            version=default_version if version is None else version,
        )
        return self._add(plugin, source, strict=True)

    def _add(self, plugin: Any, source: _Source, *, strict: bool,
             order: int | None = None) -> list[PluginInfo]:
        with self._collecting:
            if order is None:
                order = next(self._orders)
            return self._add_unlocked(plugin, source, strict=strict, order=order)

    def _add_unlocked(
        self, plugin: Any, source: _Source, *, strict: bool, order: int
    ) -> list[PluginInfo]:
        """Register ``plugin`` with pluggy; collect its objects now (strict) or when first asked.

        Not strict (discovery): problems are warned and the usable objects kept; each hook is
        called when its kind is first queried (:meth:`_ensure`), so looking up an encoder does
        not import every predictor, effect and check. Strict: every hook is called now, all
        problems are raised in one :class:`PluginError` and nothing is kept.
        """
        pm = self.plugin_manager
        if pm.is_registered(plugin):
            if strict:
                raise PluginError(f"{source.label()} is already registered")
            # The same module named by two entry points: its hooks are collected once.
            return []
        if strict:
            self.collect()  # a name clash with a plugin not collected yet must be seen now
        problems: list[str] = []
        try:
            registered = pm.register(plugin, name=f"{source.package}:{source.entry_point}")
        except Exception as exc:
            registered = None
            problems.append(f"{source.label()} could not be registered: {_describe(exc)}")
        if registered is not None:
            self._check_hooks(plugin, source, problems)
        entry = _Registered(plugin, source, order)
        infos: list[PluginInfo] = []
        commands: dict[str, CommandPlugin] = {}
        if registered is not None:
            for hook_name in ALL_HOOKS:
                if strict or hook_name in self._collected:
                    answered, contributed = self._answer(entry, hook_name, problems)
                    infos += answered
                    commands.update(contributed)
        if strict and problems:
            if registered is not None:
                pm.unregister(plugin)
            raise PluginError("; ".join(problems))
        for reason in problems:
            self._problem(source.entry_point, reason)
        self._keep(infos, commands)
        if registered is not None:
            bisect.insort(self._registered, entry, key=lambda known: known.order)
        return infos

    def _keep(self, infos: list[PluginInfo], commands: dict[str, CommandPlugin]) -> None:
        for info in infos:
            self._by_kind[info.kind][info.name] = info
        self._commands.update(commands)

    def _answer(self, entry: _Registered, hook_name: str, problems: list[str]
                ) -> tuple[list[PluginInfo], dict[str, CommandPlugin]]:
        """Call ``hook_name`` of ``entry``'s plugin (marked answered): the plugins it gives, or
        the commands for :data:`COMMAND_HOOK`; problems appended to ``problems``."""
        entry.collected.add(hook_name)
        if hook_name == COMMAND_HOOK:
            return [], self._collect_commands(entry.plugin, entry.source, problems)
        return self._collect(entry.plugin, entry.source, hook_name, problems), {}

    def _ensure(self, hook_name: str) -> None:
        """Call ``hook_name`` of every registered plugin that has not answered it yet, in
        registration order (so the first plugin keeps a name), warning about problems."""
        if hook_name in self._collected:
            return
        with self._collecting:
            self._load_pending(hook_name)
            for entry in self._registered:
                if hook_name in entry.collected:
                    continue
                problems: list[str] = []
                infos, commands = self._answer(entry, hook_name, problems)
                for reason in problems:
                    self._problem(entry.source.entry_point, reason)
                self._keep(infos, commands)
            self._collected.add(hook_name)

    def collect(self) -> None:
        """Call every hook not called yet (warning about problems): after it, :attr:`broken`
        holds every problem of the registered plugins."""
        with self._collecting:
            self._load_pending(None)
        for hook_name in ALL_HOOKS:
            self._ensure(hook_name)

    def _check_hooks(self, plugin: Any, source: _Source, problems: list[str]) -> None:
        """Problems of ``plugin``'s hook implementations found without calling them."""
        pm = self.plugin_manager
        callers = pm.get_hookcallers(plugin) or []
        unknown = sorted(c.name for c in callers if not c.has_spec())
        if unknown:
            problems.append(
                f"{source.label()} implements unknown hook(s) {', '.join(unknown)} "
                f"(known: {', '.join(ALL_HOOKS)}); they are ignored"
            )
        if not callers:
            problems.append(
                f"{source.label()} defines no hcard hook implementations "
                "(are its hooks decorated with hcard.plugins.hookimpl?)"
            )

    def _results(
        self, plugin: Any, source: _Source, hook_name: str, problems: list[str]
    ) -> Iterable[Any]:
        """What each implementation of ``hook_name`` by ``plugin`` returns, called on its own."""
        for impl in getattr(self.plugin_manager.hook, hook_name).get_hookimpls():
            if impl.plugin is not plugin:
                continue
            if impl.hookwrapper or impl.wrapper:
                problems.append(f"{source.label()}: {hook_name} must not be a hook wrapper")
                continue
            try:
                result = impl.function()
            except (Exception, SystemExit) as exc:
                problems.append(f"{source.label()}: {hook_name}() raised {_describe(exc)}")
                continue
            yield from self._objects_of(result, hook_name, source, problems)

    def _collect(
        self, plugin: Any, source: _Source, hook_name: str, problems: list[str]
    ) -> list[PluginInfo]:
        """The valid plugin objects ``plugin``'s ``hook_name`` returns."""
        kind = HOOK_KINDS[hook_name]
        infos: list[PluginInfo] = []
        staged: dict[tuple[str, str], PluginInfo] = {}
        for obj in self._results(plugin, source, hook_name, problems):
            info = self._check(obj, kind, hook_name, source, staged, problems)
            if info is not None:
                staged[(kind, info.name)] = info
                infos.append(info)
        return infos

    def _collect_commands(
        self, plugin: Any, source: _Source, problems: list[str]
    ) -> dict[str, CommandPlugin]:
        """The subcommands ``plugin`` contributes through :data:`COMMAND_HOOK`, by name."""
        found: dict[str, CommandPlugin] = {}
        where = f"{source.label()}: {COMMAND_HOOK}() returned"
        for command in self._results(plugin, source, COMMAND_HOOK, problems):
            name = getattr(command, "name", None)
            if not isinstance(command, CommandPlugin) or not isinstance(name, str) or not (
                name.strip() and isinstance(command.summary, str)
            ):
                problems.append(
                    f"{where} an object of type '{type(command).__name__}' that is not a "
                    "command (a string 'name' and 'summary', and load())"
                )
                continue
            if name in found or name in self._commands:
                problems.append(f"{where} command '{name}', a name already taken; it is ignored")
                continue
            found[name] = command
        return found

    @staticmethod
    def _objects_of(
        result: Any, hook_name: str, source: _Source, problems: list[str]
    ) -> Iterable[Any]:
        if isinstance(result, list | tuple):
            return result
        problems.append(
            f"{source.label()}: {hook_name}() returned {type(result).__name__}, "
            "expected a list of plugin objects"
        )
        return ()

    def _check(
        self,
        obj: Any,
        kind: str,
        hook_name: str,
        source: _Source,
        staged: dict[tuple[str, str], PluginInfo],
        problems: list[str],
    ) -> PluginInfo | None:
        """A :class:`PluginInfo` for ``obj`` when it is a valid ``kind`` plugin, else None."""
        where = f"{source.label()}: {hook_name}() returned"
        name = getattr(obj, "name", None)
        if not isinstance(name, str) or not name.strip():
            problems.append(
                f"{where} an object of type '{type(obj).__name__}' without a string 'name'"
            )
            return None
        description = getattr(obj, "description", "")
        if not isinstance(description, str):
            problems.append(f"{where} '{name}' whose 'description' is not a string")
            return None
        declared = getattr(obj, "kind", kind)
        if declared != kind:
            problems.append(f"{where} '{name}' of kind '{declared}', expected '{kind}'")
            return None
        other = staged.get((kind, name)) or self._by_kind[kind].get(name)
        if other is not None:
            problems.append(
                f"{where} {kind} '{name}', a name already taken by plugin "
                f"'{other.entry_point}' from package '{other.package}'; it is ignored"
            )
            return None
        return PluginInfo(
            name=name,
            kind=kind,
            version=source.version,
            package=source.package,
            entry_point=source.entry_point,
            obj=obj,
        )

    def _problem(self, entry_point: str, reason: str) -> None:
        self._broken.append(BrokenPlugin(entry_point, reason))
        warnings.warn(reason, HcardPluginWarning, stacklevel=3)

    # ---------------------------------------------------------------------------- queries

    def of_kind(self, kind: str) -> dict[str, Any]:
        """Plugin objects of ``kind`` by name (a copy)."""
        return {name: info.obj for name, info in self._infos_of(kind).items()}

    def _infos_of(self, kind: str) -> dict[str, PluginInfo]:
        if kind not in self._by_kind:
            raise PluginError(f"unknown plugin kind '{kind}'; kinds are: {', '.join(KINDS)}")
        self._ensure(_HOOK_OF_KIND[kind])
        return self._by_kind[kind]

    @property
    def encoders(self) -> dict[str, Any]:
        """Encoders by name."""
        return self.of_kind("encoder")

    @property
    def predictors(self) -> dict[str, Any]:
        """Physics predictors by name."""
        return self.of_kind("predictor")

    @property
    def drivers(self) -> dict[str, Any]:
        """Device drivers by name."""
        return self.of_kind("driver")

    @property
    def calibration_effects(self) -> dict[str, Any]:
        """Calibration effects by name."""
        return self.of_kind("calibration-effect")

    @property
    def conformance_checks(self) -> dict[str, Any]:
        """Conformance checks by name."""
        return self.of_kind("conformance-check")

    @property
    def commands(self) -> dict[str, CommandPlugin]:
        """Subcommands contributed through the ``hcard_commands`` hook, by name (a copy)."""
        self._ensure(COMMAND_HOOK)
        return dict(self._commands)

    def infos(self, kind: str) -> list[PluginInfo]:
        """The :class:`PluginInfo` of every plugin of ``kind``, sorted by name."""
        return [info for _, info in sorted(self._infos_of(kind).items())]

    def all(self) -> list[PluginInfo]:
        """Every plugin, sorted by kind (in :data:`KINDS` order), then name."""
        self.collect()
        return [info for kind in KINDS for _, info in sorted(self._by_kind[kind].items())]

    def info(self, kind: str, name: str) -> PluginInfo:
        """The :class:`PluginInfo` of plugin ``name`` of ``kind``.

        Raises:
            PluginError: no such kind or plugin; the message lists the available names.
        """
        infos = self._infos_of(kind)
        try:
            return infos[name]
        except KeyError:
            available = ", ".join(sorted(infos)) or "none installed"
            raise PluginError(f"no {kind} plugin named '{name}'; available: {available}") from None

    def get(self, kind: str, name: str) -> Any:
        """The plugin object ``name`` of ``kind`` (raises :class:`PluginError` listing names)."""
        return self.info(kind, name).obj


def _import_target(value: str) -> Any:
    """The object an entry point's ``value`` names (``module`` or ``module:attribute``,
    optionally followed by ``[extras]``), importing its module."""
    import pkgutil

    return pkgutil.resolve_name(value.partition("[")[0].strip())


def _entry_point_order(entry_point: metadata.EntryPoint) -> tuple[bool, str, str]:
    dist = entry_point.dist
    package = dist.name if dist is not None else ""
    return (package != CORE_DISTRIBUTION, package.lower(), entry_point.name)


_default: PluginRegistry | None = None
_default_lock = threading.Lock()


def get_registry(*, refresh: bool = False) -> PluginRegistry:
    """The process-wide registry of installed plugins, discovered on first use.

    ``refresh=True`` discovers again (after installing a package, or in tests that change
    ``sys.path``); warnings of broken plugins are issued by each discovery.
    """
    global _default
    with _default_lock:
        if _default is None or refresh:
            _default = PluginRegistry.discover()
        return _default


_commands: PluginRegistry | None = None


def command_registry_discovered() -> bool:
    """Whether this process has discovered (or been given) the registry of commands."""
    return _commands is not None


def get_command_registry(*, refresh: bool = False) -> PluginRegistry:
    """The registry of the entry-point group ``hcard.commands``: the light modules whose
    ``hcard_commands`` hook contributes subcommands. ``hcard --help`` loads only these, not
    the plugins of :func:`get_registry` (which import models, checks and effects)."""
    global _commands
    with _default_lock:
        if _commands is None or refresh:
            _commands = PluginRegistry.discover(hookspecs.COMMAND_ENTRY_POINT_GROUP)
        return _commands
