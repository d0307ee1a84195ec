"""Option schemas: every plugin class carries an ``Options`` model that rejects unknown keys.

>>> from pydantic import Field
>>> class Options(PluginOptions):
...     mesh_size: float = Field(0.02, gt=0, description="element size at the interface [mm]")
>>> Options.parse({"mesh_size": 0.01}, where="model.options").mesh_size
0.01
>>> Options.parse({"mesh_sise": 0.01}, where="model.options")
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: model.options: unknown option 'mesh_sise'; valid options: mesh_size
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from typing import Any, Self, TypeVar

import pydantic
from pydantic import BaseModel, ConfigDict

from .errors import ConfigError
from .extras import require

#: a unit in brackets inside an option's description: short, no comma, no nested brackets
_UNIT = re.compile(r"\[([^\[\],]{1,24})\]")


class PluginOptions(BaseModel):
    """Base class of option schemas: strict about keys, validated on assignment, immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)

    @classmethod
    def parse(cls, values: Mapping[str, Any] | None = None, where: str = "options") -> Self:
        """Validate ``values``; any problem becomes one :class:`ConfigError` line."""
        values = dict(values or {})
        valid = sorted(cls.model_fields)
        unknown = [k for k in values if k not in cls.model_fields]
        if unknown:
            plural = "s" if len(unknown) > 1 else ""
            raise ConfigError(
                f"unknown option{plural} {', '.join(repr(k) for k in unknown)}; "
                f"valid options: {', '.join(valid) or '(none)'}",
                where,
            )
        try:
            return cls(**values)
        except pydantic.ValidationError as exc:
            err = exc.errors()[0]
            if not err["loc"]:  # a check of several options (a model validator): its message
                message = str(err["msg"]).removeprefix("Value error, ")
                raise ConfigError(message, where) from None
            loc = ".".join(str(p) for p in err["loc"])
            raise ConfigError(
                f"option {loc!r}: {err['msg']} (got {err.get('input')!r})", where
            ) from None

    @classmethod
    def describe(cls) -> dict[str, dict[str, Any]]:
        """Name -> {default, unit, description} of every option, for ``fbia plugins
        --options``: the unit is the description's closing ``[...]`` (``[-]``:
        dimensionless), the default ``"(required)"`` for an option without one."""
        out: dict[str, dict[str, Any]] = {}
        for name, f in cls.model_fields.items():
            text = (f.description or "").strip()
            unit = ""
            if text.endswith("]") and "[" in text:
                head, _, tail = text.rpartition("[")
                text, unit = head.rstrip(), tail[:-1]
            else:  # a unit inside the text: "width of the kernel [mm]; Paper B: ..."
                found = _UNIT.search(text)
                unit = found.group(1) if found else ""
            default: Any = (
                "(required)" if f.is_required() else f.get_default(call_default_factory=True)
            )
            if isinstance(default, BaseModel):
                default = default.model_dump(mode="json")
            out[name] = {"default": default, "unit": unit, "description": text}
        return out


class Configurable:
    """What every plugin class is built on (through its kind's base,
    :class:`fbia.ForwardModelBase`, :class:`fbia.MeasureBase` or :class:`fbia.IteratorBase`):
    ``Cls(**options)`` or ``Cls(Cls.Options(...))``, and the members every kind shares.

    The registry builds a plugin as ``factory(parsed_options)``; a user may also write
    ``AnalyticMound2DForwardModel(height=0.4)``.  Either way ``self.options`` holds the
    validated, immutable options.
    """

    Options: type[PluginOptions] = PluginOptions
    """Its options, a subclass of :class:`fbia.PluginOptions` (every option with its unit;
    unknown keys are rejected)."""

    requires: tuple[str, ...] = ()
    """Modules the plugin needs beyond fbia's core, checked before it is built
    (:mod:`fbia.core.extras`), e.g. ``("ngsolve", "netgen")``."""

    pickle_options_only: bool = False
    """True: pickling (process pools, Dask workers) ships the options only, and the copy is
    built anew from them (caches, meshes and solver state stay behind, as they should for a
    model whose state is a cache of what its options determine)."""

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """The options of a cheap instance for the conformance kit (a coarse mesh, a few
        particles).  The base: ``{}``, the defaults."""
        return {}

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: Any) -> None:
        require(type(self).requires, type(self).__name__)
        if options is None:
            options = self.Options.parse(kwargs, where=type(self).__name__)
        elif kwargs:
            raise TypeError("pass either an Options instance or keyword options, not both")
        elif not isinstance(options, self.Options):
            raise TypeError(f"expected {self.Options.__qualname__}, got {type(options).__name__}")
        self.options = options

    def __getstate__(self) -> Any:
        if type(self).pickle_options_only:
            return {"options": self.options}
        return super().__getstate__()

    def __setstate__(self, state: dict[str, Any]) -> None:
        if type(self).pickle_options_only:
            self.__init__(state["options"])  # type: ignore[misc]
        else:
            self.__dict__.update(state)

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.model_dump().items())
        return f"{type(self).__name__}({opts})"


def plugin_options(obj: Any, *, exclude_defaults: bool = False) -> dict[str, Any]:
    """A plugin object's options as JSON-ready values (paths as strings, tuples as lists);
    ``{}`` for an object without an ``Options`` model.  The one dump every report,
    provenance record and store fingerprint uses."""
    opts = getattr(obj, "options", None)
    if not isinstance(opts, BaseModel):
        return {}
    return dict(opts.model_dump(mode="json", exclude_defaults=exclude_defaults))


S = TypeVar("S")


def settings_from(
    options: BaseModel, settings: type[S], renamed: Mapping[str, str] | None = None, **values: Any
) -> S:
    """The ``*Settings`` dataclass a solver takes, derived from a plugin's options in one
    place: each field takes ``values[field]``, else the option ``renamed[field]``, else the
    option of its own name, else keeps its default.  A name in ``renamed`` or ``values`` that
    is not a field (or an option) is a TypeError: the mapping cannot go stale silently."""
    renamed = dict(renamed or {})
    names = {f.name for f in dataclasses.fields(settings)}  # type: ignore[arg-type]
    options_of = type(options).model_fields
    stale = sorted(set(renamed) - names) + sorted(set(values) - names)
    stale += sorted(v for v in renamed.values() if v not in options_of)
    if stale:
        raise TypeError(f"{settings.__name__}: no such field or option: {', '.join(stale)}")
    kwargs = {
        name: values[name] if name in values else getattr(options, renamed.get(name, name))
        for name in names
        if name in values or renamed.get(name, name) in options_of
    }
    return settings(**kwargs)
