"""The registry of hcard plugins: the plugin objects of one process by kind and name, and the
queries on them.

Plugins are found through the entry-point group ``hcard.plugins``, the built-ins included
(``hcard_builtins``; :mod:`hcard.plugins.discovery`), and registered with a
``pluggy.PluginManager("hcard")``. Discovery never raises because of a third-party package: a
plugin that fails to import, to register, whose hook raises, or whose hook returns unusable
objects (:mod:`hcard.plugins.validation`) is skipped with an :class:`HcardPluginWarning` naming
the entry point, its distribution and the reason, and is listed in :attr:`PluginRegistry.broken`.
Every hook implementation is called on its own, so one broken plugin never hides the others,
and only when its kind is first asked for: looking up the image encoder imports no predictor,
effect or conformance check. The kinds, their hooks and the registry's property for each come
from :data:`hcard.plugins.kinds.KIND_TABLE`.

>>> from hcard.plugins import get_registry
>>> encoder = get_registry().get("encoder", "image")      # doctest: +SKIP
"""

from __future__ import annotations

import bisect
import itertools
import threading
import warnings
from typing import Any, overload

import pluggy

from hcard.errors import PluginError
from hcard.plugins import discovery, hookspecs, validation
from hcard.plugins.hookspecs import ALL_HOOKS, COMMAND_HOOK
from hcard.plugins.kinds import KIND_NAMED, KIND_OF_HOOK, KINDS, CommandPlugin
from hcard.plugins.records import (
    BrokenPlugin,
    HcardPluginWarning,
    PluginInfo,
    PluginSource,
    describe_exception,
)


class _Registered:
    """A registered plugin and the hooks it has answered.

    ``order`` is its position in registration order: discovered entry points in discovery
    order, even when imported late (:meth:`~hcard.plugins.discovery.EntryPoints.load_pending`),
    then plugins registered in code.
    """

    __slots__ = ("collected", "order", "plugin", "source")

    def __init__(self, plugin: Any, source: PluginSource, order: int) -> None:
        self.plugin = plugin
        self.source = source
        self.order = order
        self.collected: set[str] = set()


class _PluginsOfKind:
    """A :class:`PluginRegistry` property: the plugin objects, by name, of the kind whose row
    of :data:`~hcard.plugins.kinds.KIND_TABLE` names this property (its ``attribute``)."""

    def __set_name__(self, owner: type, name: str) -> None:
        rows = [kind for kind in KIND_NAMED.values() if kind.attribute == name]
        if not rows:
            raise TypeError(f"{owner.__name__}.{name}: no plugin kind has this attribute")
        self.kind = rows[0].name
        self.__doc__ = f"Plugins of kind ``{self.kind}`` by name (a copy): {rows[0].description}."

    @overload
    def __get__(self, registry: None, owner: type) -> _PluginsOfKind: ...

    @overload
    def __get__(self, registry: PluginRegistry, owner: type) -> dict[str, Any]: ...

    def __get__(self, registry: PluginRegistry | None,
                owner: type) -> _PluginsOfKind | dict[str, Any]:
        if registry is None:
            return self
        return registry.of_kind(self.kind)


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
        self._orders = itertools.count()
        self._entry_points = discovery.EntryPoints(self._register_discovered, self._problem,
                                                   self._orders)
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
        distribution and entry-point name (:mod:`hcard.plugins.discovery`). Problems are warned
        (:class:`HcardPluginWarning`) and recorded in :attr:`broken`.

        When an earlier run's discovery of ``group`` is remembered and still valid
        (:func:`hcard.plugins.command_cache.load_entry_points`), the entry points are taken
        from it and each plugin module is imported when a hook it implements is first called.
        Otherwise they are listed and imported now, and remembered when none had a problem.
        """
        remembered = discovery.remembered_entry_points(group)
        if remembered is None:
            self._entry_points.load_listed(group)
            return
        with self._collecting:
            self._entry_points.add_pending(group, remembered)
            if self._collected:  # hooks already called are called on these plugins now
                self._entry_points.load_pending(None)

    def _register_discovered(self, plugin: Any, source: PluginSource,
                             order: int) -> tuple[str, ...] | None:
        """Register a plugin discovery imported: the hooks it implements, or None when it had
        a problem (warned)."""
        problems = len(self._broken)
        self._add(plugin, source, strict=False, order=order)
        if len(self._broken) != problems:
            return None
        return tuple(c.name for c in self.plugin_manager.get_hookcallers(plugin) or [])

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
        default_package, default_version = discovery.distribution_of(plugin)
        label = name or getattr(plugin, "__name__", None) or type(plugin).__name__
        source = PluginSource(
            entry_point=label,
            package=package or default_package,
            version=default_version if version is None else version,
        )
        return self._add(plugin, source, strict=True)

    def _add(self, plugin: Any, source: PluginSource, *, strict: bool,
             order: int | None = None) -> list[PluginInfo]:
        with self._collecting:
            if order is None:
                order = next(self._orders)
            return self._add_unlocked(plugin, source, strict=strict, order=order)

    def _add_unlocked(
        self, plugin: Any, source: PluginSource, *, strict: bool, order: int
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
            problems.append(f"{source.label()} could not be registered: "
                            f"{describe_exception(exc)}")
        if registered is not None:
            problems += validation.hook_problems(pm, plugin, source)
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
        the commands for :data:`~hcard.plugins.hookspecs.COMMAND_HOOK`; problems appended to
        ``problems``."""
        entry.collected.add(hook_name)
        pm = self.plugin_manager
        if hook_name == COMMAND_HOOK:
            return [], validation.commands_of(pm, entry.plugin, entry.source, self._commands,
                                              problems)
        kind = KIND_OF_HOOK[hook_name].name
        return validation.plugins_of(pm, entry.plugin, entry.source, hook_name,
                                     self._by_kind[kind], problems), {}

    def _ensure(self, hook_name: str) -> None:
        """Call ``hook_name`` of every registered plugin that has not answered it yet, in
        registration order (so the first plugin keeps a name), warning about problems."""
        if hook_name in self._collected:
            return
        with self._collecting:
            self._entry_points.load_pending(hook_name)
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
            self._entry_points.load_pending(None)
        for hook_name in ALL_HOOKS:
            self._ensure(hook_name)

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
        self._ensure(KIND_NAMED[kind].hook)
        return self._by_kind[kind]

    encoders = _PluginsOfKind()
    predictors = _PluginsOfKind()
    drivers = _PluginsOfKind()
    device_profiles = _PluginsOfKind()
    calibration_effects = _PluginsOfKind()
    conformance_checks = _PluginsOfKind()
    importers = _PluginsOfKind()
    exporters = _PluginsOfKind()

    @property
    def commands(self) -> dict[str, CommandPlugin]:
        """Subcommands contributed through the ``hcard_commands`` hook, by name (a copy)."""
        self._ensure(COMMAND_HOOK)
        return dict(self._commands)

    def infos(self, kind: str) -> list[PluginInfo]:
        """The :class:`PluginInfo` of every plugin of ``kind``, sorted by name."""
        return [info for _, info in sorted(self._infos_of(kind).items())]

    def all(self) -> list[PluginInfo]:
        """Every plugin, sorted by kind (in :data:`~hcard.plugins.kinds.KINDS` order), then
        name."""
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
