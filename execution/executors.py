"""Executors by name: the factory behind ``[executor] kind = ...`` in a study file.

It sits above the evaluators it chooses from: evaluator (the front part) <- local_executors,
dask_executor (front + executor) <- executors, with no arrow back.
"""

from __future__ import annotations

from typing import Any

from ..core.errors import ConfigError
from ..core.iteration import Evaluator
from .local_executors import ProcessPoolEvaluator, SerialEvaluator

#: The executors :func:`make_evaluator` knows.
EXECUTOR_KINDS = ("serial", "processes", "dask")


def make_evaluator(kind: str = "processes", **options: Any) -> Evaluator:
    """An evaluator by name: ``"serial"``, ``"processes"`` or ``"dask"`` (see
    :class:`~fbia.execution.dask_executor.DaskEvaluator`), with its keyword options."""
    if kind not in EXECUTOR_KINDS:
        raise ConfigError(f"unknown executor {kind!r}; valid: {', '.join(EXECUTOR_KINDS)}")
    factory: Any
    if kind == "serial":
        factory = SerialEvaluator
    elif kind == "processes":
        factory = ProcessPoolEvaluator
    else:
        from .dask_executor import DaskEvaluator  # imports dask, which takes a second

        factory = DaskEvaluator
    try:
        evaluator: Evaluator = factory(**options)
    except TypeError as exc:
        raise ConfigError(f"bad option for executor {kind!r}: {exc}") from None
    return evaluator
