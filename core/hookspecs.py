"""Hook specifications: one ``register_<kind>(register)`` hook per extension point.

A plugin module (named by an entry point in the ``fbia`` group) implements any of them::

    import fbia

    @fbia.hookimpl
    def register_forward_models(register):
        register("my_solver", MySolverForwardModel)

``register(name, cls)`` validates ``cls`` (it needs an ``Options`` schema and the methods of
its protocol) and rejects a name that another plugin already registered.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pluggy

PROJECT = "fbia"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)

Register = Callable[[str, Any], None]


@hookspec
def register_forward_models(register: Register) -> None:
    """Register forward model classes (protocol :class:`fbia.core.protocols.ForwardModel`)."""


@hookspec
def register_measures(register: Register) -> None:
    """Register measure classes (protocol :class:`fbia.core.protocols.Discrepancy`)."""


@hookspec
def register_iterators(register: Register) -> None:
    """Register iterator classes (protocol :class:`fbia.core.protocols.InverseIterator`)."""
