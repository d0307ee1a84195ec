"""fbia.plugins: the built-in forward models (one sub-package each).

``fbia.plugins`` is this package *and*, called, the registry listing of ARCHITECTURE.md:
``fbia.plugins()`` / ``fbia.plugins("measure")`` return the installed plugin entries.
"""

from __future__ import annotations

import sys
import types
from typing import Any


class _PluginsPackage(types.ModuleType):
    """A package module that is also callable, so ``fbia.plugins`` can be both."""

    def __call__(self, kind: str | None = None) -> Any:
        from fbia.core.registry import plugins

        return plugins(kind)


sys.modules[__name__].__class__ = _PluginsPackage
