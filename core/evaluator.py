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

import contextlib
import multiprocessing
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
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

    def __init__(
        self,
        workdir: str | Path | None = None,
        keep_workdirs: bool = False,
        on_record: Callable[[Evaluation], None] | None = None,
    ) -> None:
        self.on_record = on_record
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
        if self.on_record is not None:
            self.on_record(ev)  # e.g. the study's log: every record is stored as it finishes
        return ev

    def close(self) -> None:
        if self._own_root and not self.keep_workdirs:
            shutil.rmtree(self.root, ignore_errors=True)

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialEvaluator(_EvaluatorBase):
    """Runs the batch one after another in this process.

    Parameters
    ----------
    workdir
        Root of the per-evaluation working folders (default: a temporary folder).
    keep_workdirs
        Keep every run's folder (default: only when ``workdir`` is given).
    on_record
        Called with every finished record, at once (e.g. to store it).
    """

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


#: Written in a run's folder when a worker starts it and removed when it ends: after a worker
#: dies, the runs that have it are the suspects, the others never started.
_STARTED = ".fbia-started"


def _run_in_worker(x: Mapping[str, float], workdir: str, index: int) -> Evaluation:
    assert _WORKER_PROBLEM is not None
    marker = Path(workdir) / _STARTED
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.write_text(str(os.getpid()))
    # The solution object (interfaces, fields) stays in the worker: only the record travels.
    ev = _WORKER_PROBLEM.evaluate(x, workdir=workdir, index=index, keep_solution=False)
    marker.unlink(missing_ok=True)
    return ev


@contextlib.contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """Processes started inside ignore SIGINT (the disposition survives exec): Ctrl-C then
    reaches only this process, which stops the workers, instead of every worker printing
    a traceback."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


_Job = tuple[int, Path, dict[str, float]]
_DIED = (
    "the worker process died during this run (killed, crashed or exited: e.g. os._exit, "
    "a segfault, the out-of-memory killer)"
)


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
    on_record
        Called in this process with every finished record, at once (e.g. to store it).

    A run that kills its worker process (``os._exit``, a segfault, the OOM killer) becomes a
    failed record; the rest of the batch is completed and the evaluator stays usable.
    """

    def __init__(
        self,
        workers: int | None = None,
        workdir: str | Path | None = None,
        keep_workdirs: bool = False,
        start_method: str = "spawn",
        on_record: Callable[[Evaluation], None] | None = None,
    ) -> None:
        super().__init__(workdir, keep_workdirs, on_record)
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
        jobs: list[_Job] = [
            (i, wd, dict(x))
            for (i, wd), x in zip(self._next_dirs(len(points)), points, strict=True)
        ]
        done: dict[int, Evaluation] = {}
        try:
            todo = jobs
            while todo:
                lost = self._round(problem, todo, done)
                if not lost:
                    break
                # A worker died and took the pool down with every run under way.  Runs that
                # had not started are submitted again.  If one run had started, it is the one
                # that died; if several had, each is repeated alone to tell the run that kills
                # its process from those that were only in the same pool.
                self._shutdown()
                suspects = [j for j in lost if (j[1] / _STARTED).exists()]
                if not suspects:
                    for job in lost:
                        done[job[0]] = self._finish(
                            self._died(job, "the worker pool broke before this run started")
                        )
                    break
                if len(suspects) == 1:
                    done[suspects[0][0]] = self._finish(self._died(suspects[0], _DIED))
                else:
                    for job in suspects:
                        if self._round(problem, [job], done):
                            self._shutdown()
                            done[job[0]] = self._finish(
                                self._died(job, f"{_DIED}; it died again when repeated alone")
                            )
                todo = [j for j in lost if j not in suspects]
        except BaseException:  # Ctrl-C or a bug: stop the workers instead of waiting for them
            self._shutdown(kill=True)
            raise
        return [done[i] for i, _, _ in jobs]

    def _round(
        self, problem: InverseProblem, jobs: Sequence[_Job], done: dict[int, Evaluation]
    ) -> list[_Job]:
        """Submit ``jobs``; record each as it finishes; return those lost to a dead worker."""
        pool = self._pool_for(problem)
        with _workers_ignore_sigint():  # the pool starts its processes on submit
            futures: dict[Future[Evaluation], _Job] = {
                pool.submit(_run_in_worker, x, str(wd), i): (i, wd, x) for i, wd, x in jobs
            }
        lost: list[_Job] = []
        for fut in as_completed(futures):
            i, wd, x = job = futures[fut]
            try:
                ev = fut.result()
            except BrokenProcessPool:
                lost.append(job)
                continue
            except (Exception, SystemExit) as exc:  # raised outside problem.evaluate's guard
                ev = Evaluation(
                    index=i,
                    x=dict(x),
                    status="error",
                    workdir=str(wd),
                    message=f"{type(exc).__name__}: {exc}",
                )
            done[i] = self._finish(ev)
        return sorted(lost)

    @staticmethod
    def _died(job: _Job, message: str) -> Evaluation:
        i, wd, x = job
        return Evaluation(index=i, x=dict(x), status="failed", workdir=str(wd), message=message)

    def _shutdown(self, kill: bool = False) -> None:
        if self._pool is not None:
            if kill:
                # The standard library has no public way to stop running workers before
                # Python 3.14 (ProcessPoolExecutor.terminate_workers).
                for proc in list(getattr(self._pool, "_processes", {}).values()):
                    proc.terminate()
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
