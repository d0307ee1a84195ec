"""Conformance of a plugin class's ``Options`` schema."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from ..core.errors import ConfigError
from ..core.options import Configurable, PluginOptions
from .errors import fail


def check_options(cls: type) -> list[str]:
    """Prove that ``cls`` has an ``Options`` schema a study file can be checked against.

    Checks that ``cls.Options`` is a :class:`fbia.PluginOptions`; that every option has a
    description (which states its unit); that an unknown key is rejected with a one-line
    :class:`fbia.ConfigError` naming the key and all valid keys, by ``Options.parse`` and,
    for a :class:`fbia.Configurable`, by the constructor ``cls(**options)``.

    Returns the option names.
    """

    # a probe, not a contract call: a candidate class without a schema is what this reports
    options = getattr(cls, "Options", None)
    if not (isinstance(options, type) and issubclass(options, PluginOptions)):
        raise fail(cls, "has no Options schema (a subclass of fbia.PluginOptions)")
    names = sorted(options.model_fields)
    undocumented = [n for n, f in options.model_fields.items() if not (f.description or "").strip()]
    if undocumented:
        raise fail(
            cls,
            f"option(s) {', '.join(undocumented)} have no description; document each option "
            "and its unit with pydantic.Field(description=...)",
        )
    bad_key = "no_such_option_xyz"
    attempts: list[tuple[str, Callable[[], Any]]] = [
        ("Options.parse", lambda: options.parse({bad_key: 1.0}, where="conformance")),
    ]
    if issubclass(cls, Configurable):  # the Configurable convention: Cls(**options)
        attempts.append((f"{cls.__name__}(**options)", lambda: cls(**{bad_key: 1.0})))
    for label, attempt in attempts:
        try:
            attempt()
        except ConfigError as exc:
            message = str(exc)
            if "\n" in message:
                raise fail(
                    cls, f"{label}: the error for an unknown key spans lines: {message!r}"
                ) from None
            missing = [n for n in [bad_key, *names] if n not in message]
            if missing:
                raise fail(
                    cls,
                    f"{label}: the error for an unknown key does not name "
                    f"{', '.join(missing)}: {message!r}",
                ) from None
        except Exception as exc:
            raise fail(
                cls,
                f"{label}: an unknown key raised {type(exc).__name__}: {exc} "
                "instead of fbia.ConfigError",
            ) from exc
        else:
            raise fail(cls, f"{label} accepts the unknown key {bad_key!r}")
    return names


def example_options(cls: type[Configurable]) -> dict[str, Any]:
    """The options of a cheap instance of ``cls``: ``cls.example_options()`` (the base's:
    ``{}``)."""
    opts = cls.example_options()
    if not isinstance(opts, Mapping):
        raise fail(cls, f"example_options() must return a dict, got {type(opts).__name__}")
    return dict(opts)
