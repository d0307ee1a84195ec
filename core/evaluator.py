"""Evaluators run batches of forward evaluations: serially or on a local process pool.

>>> import fbia
>>> # problem = fbia.InverseProblem(...)
>>> # with fbia.ProcessPoolEvaluator(workers=2) as ev:
>>> #     records = ev.evaluate(problem, [{"E": 300.0, "nu": 0.2}, {"E": 500.0, "nu": 0.1}])

Every run gets its own working folder ``<workdir>/eval_<index>``; a run that fails is recorded
as a failed :class:`~fbia.core.problem.Evaluation` with its message and never stops the batch.
The batch interface is what the Dask executor and the persistent store of later versions plug
into: ``evaluate(problem, points) -> list[Evaluation]`` in the order of ``points``.
"""

from __future__ import annotations

import multiprocessing
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from fbia.core.errors import ConfigError
from fbia.core.problem import Evaluation, InverseProblem


@runtime_checkable
class Evaluator(Protocol):
    """Evaluates batches of parameter points; results come back in the order of ``points``."""

    def evaluate(
        self, problem: InverseProblem, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]: ...


class _EvaluatorBase:
    """Working folders and evaluation numbering shared by the evaluators."""

    def __init__(self, workdir: str | Path | None = None, keep_workdirs: bool = False) -> None:
        self._own_root = workdir is None
        self.root = (
            Path(tempfile.mkdtemp(prefix="fbia-runs-")) if workdir is None else Path(workdir)
        )
        self.root.mkdir(parents=True, exist_ok=True)
        self.keep_workdirs = keep_workdirs or not self._own_root
        self.count = 0
        self.history: list[Evaluation] = []

    def _next_dirs(self, n: int) -> list[tuple[int, Path]]:
        out = [(self.count + i, self.root / f"eval_{self.count + i:06d}") for i in range(n)]
        self.count += n
        return out

    def _finish(self, ev: Evaluation) -> Evaluation:
        if not self.keep_workdirs and ev.workdir:
            shutil.rmtree(ev.workdir, ignore_errors=True)
            ev.workdir = None
        self.history.append(ev)
        return ev

    def close(self) -> None:
        if self._own_root and not self.keep_workdirs:
            shutil.rmtree(self.root, ignore_errors=True)

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialEvaluator(_EvaluatorBase):
    """Runs the batch one after another in this process."""

    def evaluate(
        self, problem: InverseProblem, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        return [
            self._finish(problem.evaluate(x, workdir=wd, index=i))
            for (i, wd), x in zip(self._next_dirs(len(points)), points, strict=True)
        ]


_WORKER_PROBLEM: InverseProblem | None = None


def _init_worker(problem: InverseProblem) -> None:
    global _WORKER_PROBLEM
    _WORKER_PROBLEM = problem


def _run_in_worker(x: Mapping[str, float], workdir: str, index: int) -> Evaluation:
    assert _WORKER_PROBLEM is not None
    # The solution object (interfaces, fields) stays in the worker: only the record travels.
    ev = _WORKER_PROBLEM.evaluate(x, workdir=workdir, index=index, keep_solution=False)
    return ev


class ProcessPoolEvaluator(_EvaluatorBase):
    """Runs the batch concurrently on a local pool of worker processes.

    Parameters
    ----------
    workers
        Number of worker processes (default: the number of cores).
    workdir
        Root of the per-evaluation working folders (default: a temporary folder).
    keep_workdirs
        Keep every run's folder (default: only when ``workdir`` is given).
    start_method
        ``"spawn"`` (default: safe with threaded solvers), ``"forkserver"`` or ``"fork"``.
    """

    def __init__(
        self,
        workers: int | None = None,
        workdir: str | Path | None = None,
        keep_workdirs: bool = False,
        start_method: str = "spawn",
    ) -> None:
        super().__init__(workdir, keep_workdirs)
        n = workers if workers is not None else (os.cpu_count() or 1)
        if n < 1:
            raise ConfigError(f"workers must be at least 1, got {workers}")
        if start_method not in multiprocessing.get_all_start_methods():
            raise ConfigError(
                f"unknown start method {start_method!r}; valid: "
                f"{', '.join(multiprocessing.get_all_start_methods())}"
            )
        self.workers = n
        self.start_method = start_method
        self._pool: ProcessPoolExecutor | None = None
        self._pool_problem: int | None = None

    def _pool_for(self, problem: InverseProblem) -> ProcessPoolExecutor:
        if self._pool is None or self._pool_problem != id(problem):
            self._shutdown()
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=multiprocessing.get_context(self.start_method),
                initializer=_init_worker,
                initargs=(problem,),
            )
            self._pool_problem = id(problem)
        return self._pool

    def evaluate(
        self, problem: InverseProblem, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        pool = self._pool_for(problem)
        jobs: list[tuple[int, Path, Mapping[str, float], Future[Evaluation]]] = []
        for (i, wd), x in zip(self._next_dirs(len(points)), points, strict=True):
            jobs.append((i, wd, x, pool.submit(_run_in_worker, dict(x), str(wd), i)))
        out: list[Evaluation] = []
        broken = False
        for i, wd, x, fut in jobs:
            try:
                ev = fut.result()
            except BrokenProcessPool:
                broken = True
                ev = Evaluation(
                    index=i,
                    x=dict(x),
                    status="failed",
                    workdir=str(wd),
                    message="the worker process died (killed or crashed) during the run",
                )
            out.append(self._finish(ev))
        if broken:
            self._shutdown()
        return out

    def _shutdown(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            self._pool_problem = None

    def close(self) -> None:
        self._shutdown()
        super().close()


def make_evaluator(
    kind: str = "processes", **options: Any
) -> SerialEvaluator | ProcessPoolEvaluator:
    """An evaluator by name: ``"serial"`` or ``"processes"`` (``"dask"`` arrives with the store)."""
    kinds: dict[str, type[SerialEvaluator] | type[ProcessPoolEvaluator]] = {
        "serial": SerialEvaluator,
        "processes": ProcessPoolEvaluator,
    }
    if kind not in kinds:
        raise ConfigError(f"unknown executor {kind!r}; valid: {', '.join(kinds)}")
    try:
        return kinds[kind](**options)
    except TypeError as exc:
        raise ConfigError(f"bad option for executor {kind!r}: {exc}") from None
