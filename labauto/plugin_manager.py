"""Loading plugins and collecting what they register.

Built-in plugins are registered by module path; third-party plugins come from the entry-point
group ``labauto``. Each is loaded on its own: one that fails to import or register is reported
(name and error) and skipped, so a broken plugin never takes labauto down. ``enabled`` is an
allow-list (``None`` allows all) and ``disabled`` a block-list; both name plugins as
``labauto plugins`` lists them (built-ins by their short module name, e.g. ``vision``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

import pluggy

from labauto import __version__, hookspecs
from labauto.errors import PluginError

BUILTIN_PLUGINS: tuple[str, ...] = (
    "labauto.plugins.vision",
    "labauto.plugins.plate",
    "labauto.plugins.devices",
)


@dataclass(frozen=True)
class PluginInfo:
    """What ``labauto plugins`` shows for one loaded plugin."""

    name: str
    version: str
    source: str
    hooks: tuple[str, ...]


@dataclass(frozen=True)
class PluginFailure:
    """A plugin that could not be loaded, with the reason."""

    name: str
    source: str
    error: str


@dataclass
class Registry:
    """Everything the loaded plugins registered, by family and name."""

    segmenters: dict[str, Callable[..., Any]] = field(default_factory=dict)
    classifiers: dict[str, Callable[..., Any]] = field(default_factory=dict)
    applications: dict[str, Callable[..., Any]] = field(default_factory=dict)
    drivers: dict[tuple[str, str], Callable[..., Any]] = field(default_factory=dict)

    def merge(self, other: Registry) -> None:
        """Add everything ``other`` registered; a later plugin overrides an earlier name."""
        self.segmenters.update(other.segmenters)
        self.classifiers.update(other.classifiers)
        self.applications.update(other.applications)
        self.drivers.update(other.drivers)

    def get(self, family: str, name: str) -> Callable[..., Any]:
        """Return the component ``name`` of a family (``"segmenters"``, ...) or raise."""
        return _lookup(getattr(self, family), name, family[:-1])

    def driver(self, kind: str, name: str) -> Callable[..., Any]:
        """Return the factory of the ``kind`` driver ``name`` or raise a ``PluginError``."""
        names = {n: f for (k, n), f in self.drivers.items() if k == kind}
        return _lookup(names, name, f"{kind} driver")


def _lookup(table: dict[str, Callable[..., Any]], name: str, what: str) -> Callable[..., Any]:
    try:
        return table[name]
    except KeyError:
        known = ", ".join(sorted(table)) or "none"
        raise PluginError(f"no {what} named {name!r} (loaded: {known})") from None


@dataclass
class Plugins:
    """The plugin manager with its load report and registry."""

    manager: pluggy.PluginManager
    loaded: list[PluginInfo]
    failed: list[PluginFailure]
    registry: Registry

    @property
    def hook(self) -> Any:
        """The pluggy hook relay, for calling event hooks with keyword arguments."""
        return self.manager.hook


def _allowed(name: str, enabled: Iterable[str] | None, disabled: Iterable[str]) -> bool:
    return (enabled is None or name in enabled) and name not in disabled


def _hook_names(pm: pluggy.PluginManager, plugin: object) -> tuple[str, ...]:
    return tuple(sorted(caller.name for caller in pm.get_hookcallers(plugin) or ()))


def load_plugins(
    enabled: Iterable[str] | None = None,
    disabled: Iterable[str] = (),
    *,
    builtins: Iterable[str] = BUILTIN_PLUGINS,
    use_entry_points: bool = True,
) -> Plugins:
    """Load the built-in and installed plugins and collect their registrations.

    Parameters
    ----------
    enabled : iterable of str or None
        Allow-list of plugin names; ``None`` allows every plugin.
    disabled : iterable of str
        Block-list of plugin names, applied after the allow-list.
    builtins : iterable of str
        Module paths of the built-in plugins.
    use_entry_points : bool
        Whether to load third-party plugins from the ``labauto`` entry-point group.

    Returns
    -------
    Plugins
        The manager, the loaded plugins, the failures (name and error) and the registry.
    """
    enabled = None if enabled is None else set(enabled)
    disabled = set(disabled)
    pm = pluggy.PluginManager(hookspecs.PROJECT_NAME)
    pm.add_hookspecs(hookspecs)
    loaded: list[PluginInfo] = []
    failed: list[PluginFailure] = []

    candidates: list[tuple[str, str, str, Callable[[], object]]] = [
        (path.rsplit(".", 1)[-1], __version__, "builtin", lambda p=path: importlib.import_module(p))
        for path in builtins
    ]
    if use_entry_points:
        for ep in entry_points(group=hookspecs.ENTRY_POINT_GROUP):
            dist = ep.dist
            version = dist.version if dist is not None else "unknown"
            source = f"entry point {ep.value}" + (f" ({dist.name})" if dist is not None else "")
            candidates.append((ep.name, version, source, ep.load))

    for name, version, source, load in candidates:
        if not _allowed(name, enabled, disabled):
            continue
        try:
            module = load()
            pm.register(module, name=name)
        except Exception as exc:  # a broken plugin is reported and skipped, never fatal
            failed.append(PluginFailure(name, source, f"{type(exc).__name__}: {exc}"))
            continue
        loaded.append(PluginInfo(name, version, source, _hook_names(pm, module)))

    registry = Registry()
    for plugin_name, plugin in list(pm.list_name_plugin()):
        try:
            registry.merge(_registrations(plugin, plugin_name))
        except Exception as exc:  # registration failed: drop the plugin whole
            failed.append(PluginFailure(plugin_name, "register", f"{type(exc).__name__}: {exc}"))
            pm.unregister(plugin)
            loaded = [info for info in loaded if info.name != plugin_name]
    return Plugins(pm, loaded, failed, registry)


_FAMILY_HOOKS = {
    "labauto_register_segmenters": "segmenters",
    "labauto_register_classifiers": "classifiers",
    "labauto_register_applications": "applications",
}
DRIVER_KINDS = ("robot", "analyzer", "camera")


def _registrations(plugin: object, plugin_name: str) -> Registry:
    """Call one plugin's registration hooks and return what it registered."""
    own = Registry()

    def checked(name: str, component: object) -> None:
        if not callable(component):
            raise PluginError(f"{plugin_name} registered {name!r}, which is not callable")

    for hook_name, family in _FAMILY_HOOKS.items():
        impl = getattr(plugin, hook_name, None)
        if impl is None:
            continue
        table = getattr(own, family)

        def register(name: str, component: Callable[..., Any], table: dict = table) -> None:
            checked(name, component)
            table[name] = component

        impl(register=register)

    impl = getattr(plugin, "labauto_register_drivers", None)
    if impl is not None:

        def register_driver(kind: str, name: str, factory: Callable[..., Any]) -> None:
            if kind not in DRIVER_KINDS:
                raise PluginError(
                    f"{plugin_name} registered driver {name!r} of unknown kind {kind!r} "
                    f"(expected one of {', '.join(DRIVER_KINDS)})"
                )
            checked(name, factory)
            own.drivers[(kind, name)] = factory

        impl(register=register_driver)
    return own
