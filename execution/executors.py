"""Executors by name: the ``[executor]`` of a study as a value (:class:`ExecutorSpec`) and the
factories that build an evaluator from it (:func:`evaluator_for`) or from a name
(:func:`make_evaluator`).

It sits above the evaluators it chooses from: evaluator (the front part) <- local_executors,
dask_executor (front + executor) <- executors, with no arrow back.  The study application
holds the value and asks this module for the evaluator; the value builds nothing itself.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

from ..core.errors import ConfigError
from ..core.iteration import Evaluator
from ..core.problem import Evaluation
from .evaluator import BatchEvaluator
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


_SCHEDULER = re.compile(r"((tcp|tls|ucx|ws|wss)://)?(\[[0-9a-fA-F:.]+\]|[A-Za-z0-9_.-]+):\d{1,5}/?")


def check_scheduler_address(address: str, where: str) -> str:
    """A Dask scheduler address (``tcp://HOST:PORT``; also ``tls://``, ``ucx://``, ``ws://``,
    ``wss://``, or ``HOST:PORT``), else a one-line ConfigError at ``where``."""
    if not _SCHEDULER.fullmatch(address.strip()):
        raise ConfigError(
            f"{address!r} is not a Dask scheduler address: expected tcp://HOST:PORT "
            "(or tls://HOST:PORT with TLS set up)",
            where,
        )
    return address.strip()


@dataclass(frozen=True)
class ExecutorSpec:
    """How forward runs are executed (the ``[executor]`` section).

    ``kind`` is ``serial``, ``processes`` (a local pool of ``workers``) or ``dask`` (a running
    scheduler at ``address``, else a cluster started for the study: ``cluster = "local"`` or a
    dask-jobqueue kind with ``cluster_options``).  ``timeout`` is the wall-time limit of one run
    in seconds; ``isolate`` runs each run in a child process of its own.
    """

    kind: str = "processes"
    workers: int | None = None
    keep_runs: bool = False
    timeout: float | None = None
    isolate: bool | None = None
    address: str | None = None
    cluster: str = "local"
    cluster_options: Mapping[str, Any] = field(default_factory=dict)

    def with_workers(self, workers: int | None) -> ExecutorSpec:
        """The command line's ``--workers N``: 1 runs serially, more on a process pool; for
        ``dask``, the number of workers of the cluster started for the study."""
        if workers is None:
            return self
        if workers < 1:
            raise ConfigError(f"--workers must be at least 1, got {workers}")
        if self.kind == "dask":
            if self.address:
                raise ConfigError("--workers does not apply to a running Dask scheduler (address)")
            return replace(self, workers=workers)
        return replace(self, kind="serial" if workers == 1 else "processes", workers=workers)

    def with_address(self, address: str | None) -> ExecutorSpec:
        """The command line's ``--address``: the runs go to that Dask scheduler."""
        if not address:
            return self
        check_scheduler_address(address, "--address")
        return replace(
            self, kind="dask", address=address, workers=None, cluster="local", cluster_options={}
        )

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "kind": self.kind,
            "workers": self.workers,
            "keep_runs": self.keep_runs,
        }
        if self.timeout is not None:
            out["timeout"] = self.timeout
        if self.isolate is not None:
            out["isolate"] = self.isolate
        if self.kind == "dask":
            out.update(
                address=self.address,
                cluster=self.cluster,
                cluster_options=dict(self.cluster_options),
            )
        return out

    def label(self) -> str:
        """E.g. ``processes, 2 workers, time-out 600 s``."""
        parts = [self.kind]
        if self.kind == "dask":
            parts.append(f"scheduler {self.address}" if self.address else f"{self.cluster} cluster")
        if self.workers and self.kind != "serial":
            parts.append(f"{self.workers} workers")
        if self.timeout is not None:
            parts.append(f"time-out {self.timeout:g} s")
        return ", ".join(parts)


def evaluator_for(
    spec: ExecutorSpec,
    output: Path,
    on_record: Callable[[Evaluation], None] | None = None,
    **options: Any,
) -> BatchEvaluator:
    """The evaluator ``spec`` describes (a front part with the executor it names); run
    folders go to ``<output>/runs`` (successful runs' folders are removed unless
    ``keep_runs``).  ``options`` (store, listener, retry_failed) are passed on."""
    settings: dict[str, Any] = {
        "workdir": output / "runs",
        "keep_workdirs": spec.keep_runs,
        "on_record": on_record,
        "timeout": spec.timeout,
        "isolate": spec.isolate,
        **options,
    }
    if spec.kind == "processes":
        settings["workers"] = spec.workers
    elif spec.kind == "dask":
        settings.update(
            address=spec.address,
            workers=spec.workers,
            cluster=spec.cluster,
            cluster_options=dict(spec.cluster_options),
        )
    return cast(BatchEvaluator, make_evaluator(spec.kind, **settings))
