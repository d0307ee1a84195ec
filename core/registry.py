"""The plugin registry: pluggy + entry points, the same path for built-ins and third parties.

>>> import fbia
>>> sorted(e.name for e in fbia.list_plugins() if e.kind == "measure")
['cpp', 'ray', 'rkhs']
>>> fbia.measure("rkhs", sigma_w=0.05)                          # doctest: +ELLIPSIS
RkhsMeasure(sigma_w=0.05, ...)
"""

from __future__ import annotations

import difflib
import functools
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import pluggy

from . import hookspecs
from .errors import PluginError
from .extras import missing, require
from .options import Configurable, PluginOptions
from .problem import IteratorMembers
from .protocols import ForwardModelBase, MeasureBase, missing_methods

KINDS: dict[str, str] = {
    "forward_model": "register_forward_models",
    "measure": "register_measures",
    "iterator": "register_iterators",
}
ENTRY_POINT_GROUP = "fbia"
#: The class every plugin of a kind derives from, and the base its author is told to use: an
#: iterator derives from fbia.IteratorBase, whose members below ``run`` (IteratorMembers) are
#: what the registry can see, as ``IteratorBase.run`` names its result through the registry.
BASES: dict[str, tuple[type[Configurable], str]] = {
    "forward_model": (ForwardModelBase, "fbia.ForwardModelBase"),
    "measure": (MeasureBase, "fbia.MeasureBase"),
    "iterator": (IteratorMembers, "fbia.IteratorBase"),
}


@dataclass(frozen=True)
class PluginEntry:
    """One registered class: what it is called, what kind it is and who provided it."""

    name: str
    kind: str
    factory: Any
    plugin: str
    distribution: str
    version: str

    def describe(self) -> dict[str, str]:
        return {
            "name": self.name,
            "kind": self.kind,
            "class": f"{self.factory.__module__}.{self.factory.__qualname__}",
            "plugin": self.plugin,
            "distribution": self.distribution,
            "version": self.version,
            "missing": ", ".join(missing(self.factory.requires)),
        }


class Registry:
    """Name -> class tables for forward models, measures and iterators.

    Use :meth:`load` (entry points of the ``fbia`` group, plus optional extra plugin modules);
    :func:`default_registry` holds the process-wide one.
    """

    def __init__(self) -> None:
        self._entries: dict[str, dict[str, PluginEntry]] = {kind: {} for kind in KINDS}
        self.plugin_manager = pluggy.PluginManager(hookspecs.PROJECT)
        self.plugin_manager.add_hookspecs(hookspecs)

    @classmethod
    def load(cls, entry_points: bool = True, extra: Iterable[ModuleType | object] = ()) -> Registry:
        """Load the plugins declared under the ``fbia`` entry-point group, then ``extra`` ones."""
        reg = cls()
        pm = reg.plugin_manager
        if entry_points:
            try:
                pm.load_setuptools_entrypoints(ENTRY_POINT_GROUP)
            except Exception as exc:  # an entry point that does not import
                raise PluginError(
                    f"a plugin of group {ENTRY_POINT_GROUP!r} failed to load: {exc}"
                ) from exc
        for plugin in extra:
            pm.register(plugin)
        try:
            pm.check_pending()  # a misspelled hook fails loudly (tox does the same)
        except pluggy.PluginValidationError as exc:
            raise PluginError(str(exc)) from None
        dists = {id(p): d for p, d in pm.list_plugin_distinfo()}
        for kind, hook_name in KINDS.items():
            for impl in getattr(pm.hook, hook_name).get_hookimpls():
                dist = dists.get(id(impl.plugin))
                provider = (
                    (getattr(dist, "project_name", None) or dist.metadata["Name"], dist.version)
                    if dist is not None
                    else (getattr(impl.plugin, "__name__", impl.plugin_name), "unversioned")
                )
                impl.function(
                    register=functools.partial(reg._register, kind, impl.plugin_name, provider)
                )
        return reg

    def _register(
        self, kind: str, plugin: str, provider: tuple[str, str], name: str, factory: Any
    ) -> None:
        where = f"plugin {plugin!r}"
        if not isinstance(name, str) or not name.replace("_", "a").replace(".", "a").isalnum():
            raise PluginError(f"registers an invalid {kind} name {name!r}", where)
        if not isinstance(factory, type):
            raise PluginError(
                f"{kind} {name!r} must be a class, got an instance of {type(factory).__name__}",
                where,
            )
        base, shown = BASES[kind]
        if not issubclass(factory, base):  # the framework calls the base's members directly
            raise PluginError(
                f"{kind} {name!r}: class {factory.__qualname__} does not derive from {shown}",
                where,
            )
        options = factory.Options  # Configurable's, or the plugin's own
        if not (isinstance(options, type) and issubclass(options, PluginOptions)):
            raise PluginError(
                f"{kind} {name!r} has no Options schema (a subclass of fbia.PluginOptions)", where
            )
        missing = missing_methods(kind, factory)
        if missing:
            raise PluginError(f"{kind} {name!r} lacks method(s) {', '.join(missing)}", where)
        table = self._entries[kind]
        if name in table:
            other = table[name]
            raise PluginError(
                f"{kind} name {name!r} is registered twice: by plugin {other.plugin!r} "
                f"({other.distribution}) and by plugin {plugin!r} ({provider[0]})"
            )
        table[name] = PluginEntry(name, kind, factory, plugin, provider[0], provider[1])

    # -- lookup ------------------------------------------------------------------------------
    def names(self, kind: str) -> list[str]:
        return sorted(self._entries[kind])

    def entries(self, kind: str | None = None) -> list[PluginEntry]:
        kinds = [kind] if kind else list(KINDS)
        return [self._entries[k][n] for k in kinds for n in sorted(self._entries[k])]

    def get(self, kind: str, name: str, where: str | None = None) -> PluginEntry:
        if kind not in KINDS:
            raise PluginError(f"unknown plugin kind {kind!r}; valid: {', '.join(KINDS)}", where)
        try:
            return self._entries[kind][name]
        except (KeyError, TypeError):
            valid = ", ".join(self.names(kind)) or "(none installed)"
            label = kind.replace("_", " ")
            close = close_name(str(name), self.names(kind))
            hint = f" (did you mean {close!r}?)" if close else ""
            raise PluginError(f"unknown {label} {name!r}{hint}; valid: {valid}", where) from None

    def create(
        self,
        kind: str,
        name: str,
        options: Mapping[str, Any] | None = None,
        where: str | None = None,
    ) -> Any:
        """Look ``name`` up and build it from ``options`` (validated by its ``Options`` schema)."""
        entry = self.get(kind, name, where)
        require(entry.factory.requires, f"{where or kind} {name!r}")
        parsed = entry.factory.Options.parse(options or {}, where=where or f"{kind} {name!r}")
        return entry.factory(parsed)

    def entry_for(self, obj: Any) -> PluginEntry | None:
        """The entry whose class built ``obj`` (for provenance), if any."""
        for table in self._entries.values():
            for entry in table.values():
                if type(obj) is entry.factory:
                    return entry
        return None


@functools.lru_cache(maxsize=1)
def default_registry() -> Registry:
    """The process-wide registry, loaded from entry points on first use."""
    return Registry.load()


def forward_model(name: str, **options: Any) -> Any:
    """A forward model by registry name, e.g. ``fbia.forward_model("analytic_mound_2d")``."""
    return default_registry().create("forward_model", name, options)


def measure(name: str, **options: Any) -> Any:
    """A measure by registry name: ``"ray"``, ``"cpp"`` or ``"rkhs"`` (or a plugin's)."""
    return default_registry().create("measure", name, options)


def iterator(name: str, **options: Any) -> Any:
    """An iterator by registry name, e.g. ``fbia.iterator("levenberg_marquardt", x0=...)``."""
    return default_registry().create("iterator", name, options)


def close_name(name: str, names: Iterable[str]) -> str | None:
    """The installed name closest to a mistyped ``name`` (difflib's ratio >= 0.6), or None:
    what "did you mean" suggests."""
    close = difflib.get_close_matches(name, list(names), n=1)
    return close[0] if close else None


def list_plugins(kind: str | None = None) -> list[PluginEntry]:
    """What is installed: name, kind, class, providing plugin, distribution and version."""
    return default_registry().entries(kind)


def plugin_versions(*objects: Any) -> dict[str, dict[str, str]]:
    """Provenance of the plugin objects used by a study (for result files)."""
    reg = default_registry()
    out: dict[str, dict[str, str]] = {}
    for obj in objects:
        entry = reg.entry_for(obj)
        if entry is not None:
            out[f"{entry.kind}:{entry.name}"] = entry.describe()
        elif obj is not None:
            cls = type(obj)
            mod = sys.modules.get(cls.__module__)
            out[f"unregistered:{cls.__qualname__}"] = {
                "class": f"{cls.__module__}.{cls.__qualname__}",
                "version": str(getattr(mod, "__version__", "unversioned")),
            }
    return out
