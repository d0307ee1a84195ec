"""The error a conformance check raises."""

from __future__ import annotations

from typing import Any


class ConformanceError(AssertionError):
    """A plugin breaks a rule of its protocol; the message names the plugin and the rule."""


def _fail(obj: Any, rule: str) -> ConformanceError:
    cls = obj if isinstance(obj, type) else type(obj)
    return ConformanceError(f"{cls.__module__}.{cls.__qualname__}: {rule}")
