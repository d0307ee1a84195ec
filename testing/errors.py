"""The error a conformance check raises."""

from __future__ import annotations

from typing import Any


class ConformanceError(AssertionError):
    """A plugin breaks a rule of its protocol; the message names the plugin and the rule."""


def fail(obj: Any, rule: str) -> ConformanceError:
    """The error for ``obj`` (a plugin or its class) breaking ``rule``, naming both."""
    cls = obj if isinstance(obj, type) else type(obj)
    return ConformanceError(f"{cls.__module__}.{cls.__qualname__}: {rule}")
