"""Evaluators run batches of forward evaluations: serially, on a local process pool, or on Dask.

>>> import fbia
>>> # problem = fbia.InverseProblem(...)
>>> # with fbia.ProcessPoolEvaluator(workers=2, timeout=600.0) as ev:
>>> #     records = ev.evaluate(problem, [{"E": 300.0, "nu": 0.2}, {"E": 500.0, "nu": 0.1}])

``evaluate(problem, points) -> list[Evaluation]`` returns one record per point, in the order of
``points``, numbered by request (the n-th point ever asked for has ``index`` n).  What every
evaluator does the same way, whichever runs the forward models:

* **Working folders**: each run in ``<workdir>/eval_<index>``; a failed run's folder is kept,
  a successful one's is removed unless ``keep_workdirs`` (default: keep all when ``workdir`` is
  given, none in a temporary folder).
* **Failures are records**: a run that raises, hangs past ``timeout`` or kills its process
  becomes a record with status ``failed``/``error`` and its message; the batch goes on.
* **Time-outs** (``timeout`` seconds of wall time per run) and **isolation** (``isolate``):
  each run in a child process of its own (:mod:`fbia.core.isolation`) that is killed, with
  everything it started, when the time is up.  A time-out implies isolation.
* **The store** (``store``, a :class:`~fbia.core.store.StudyStore`, used through
  :class:`~fbia.core.cache.RunCache`): a point whose run is
  already stored is not run again, its stored record is returned (a failed run is a finished
  run too; ``retry_failed`` runs stored failures once more); every new record is written to the
  store the moment its run finishes.  A point asked for twice in one batch runs once.
* **Listeners**: ``on_record(record)`` and a ``listener`` (progress bar, log file) see every
  record as it finishes; the listener also hears of batches and of records taken from the store.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from .cache import Plan, RunCache
from .errors import ConfigError
from .isolation import (
    IsolatedRunner,
    RunOutcome,
    evaluate_here,
    run_isolated_or_here,
    run_view,
)
from .problem import Evaluable, Evaluation, InverseProblem

if TYPE_CHECKING:
    from .store import StudyStore

__all__ = [
    "Evaluator",
    "EvaluatorBase",
    "Job",
    "ProcessPoolEvaluator",
    "RunListener",
    "SerialEvaluator",
]


@runtime_checkable
class Evaluator(Protocol):
    """Evaluates batches of parameter points; results come back in the order of ``points``."""

    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]: ...


class RunListener(Protocol):
    """What a progress display or log hears from an evaluator (all calls in the caller's
    process and thread)."""

    def batch_started(self, total: int, reused: int, to_run: int, slots: int) -> None:
        """A batch of ``total`` points: ``reused`` from the store, ``to_run`` to run on
        ``slots`` parallel workers."""

    def record(self, record: Evaluation, reused: bool, worker: str | None) -> None:
        """A record: from the store (``reused``) or just finished on ``worker``."""

    def batch_finished(self) -> None:
        """The batch is complete."""


#: (index, working folder, input values) of one run to make
Job = tuple[int, Path, dict[str, float]]


class EvaluatorBase:
    """The base of every executor: numbering, working folders, the run cache
    (:class:`~fbia.core.cache.RunCache`, with ``store``), time-outs and listeners; a subclass
    (serial, process pool, :class:`~fbia.core.dask_executor.DaskEvaluator`) implements
    :meth:`_run`: run the jobs it is given and hand each outcome to :meth:`_finish` as it
    arrives."""

    #: whether runs go to child processes when neither ``isolate`` nor ``timeout`` is given
    isolate_by_default = False

    def __init__(
        self,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        on_record: Callable[[Evaluation], None] | None = None,
        *,
        store: StudyStore | None = None,
        retry_failed: bool = False,
        timeout: float | None = None,
        isolate: bool | None = None,
        listener: RunListener | None = None,
    ) -> None:
        if timeout is not None and not timeout > 0:
            raise ConfigError(f"timeout must be a positive number of seconds, got {timeout}")
        if timeout is not None and isolate is False:
            raise ConfigError(
                "a time-out needs isolated runs (isolate = true): only a run in its own "
                "process can be stopped"
            )
        self.on_record = on_record
        self.listener = listener
        #: store lookup, de-duplication and retry (fbia.core.cache), None without a store
        self.cache = None if store is None else RunCache(store, retry_failed)
        self.timeout = timeout
        self.isolate = (
            bool(isolate)
            if isolate is not None
            else (timeout is not None or self.isolate_by_default)
        )
        self._own_root = workdir is None
        self.root = (
            Path(tempfile.mkdtemp(prefix="fbia-runs-")) if workdir is None else Path(workdir)
        ).absolute()
        self.root.mkdir(parents=True, exist_ok=True)
        self.keep_workdirs = keep_workdirs
        self.count = 0
        self.history: list[Evaluation] = []
        #: request indices whose records came from the store
        self.reused: set[int] = set()

    #: number of runs under way at once (for progress displays)
    @property
    def slots(self) -> int:
        return 1

    # -- the batch ---------------------------------------------------------------------------
    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        requests = [
            (self.count + k, {str(n): float(v) for n, v in x.items()}) for k, x in enumerate(points)
        ]
        self.count += len(requests)
        if self.cache is None:
            plan = Plan(to_run=requests)
        elif isinstance(problem, InverseProblem):
            plan = self.cache.plan(problem, requests)
        else:  # a store keys runs by an inverse problem's model
            raise ConfigError(
                f"a study store needs an InverseProblem, not a {type(problem).__name__}",
                "evaluator",
            )
        done: dict[int, Evaluation] = dict(plan.reused)
        reused = list(plan.reused.values())
        self.reused.update(plan.reused)
        todo: list[Job] = [(i, self._workdir(i), x) for i, x in plan.to_run]
        copies = plan.copies
        if self.listener is not None:
            self.listener.batch_started(len(requests), len(reused), len(todo), self.slots)
        for ev in reused:
            self.history.append(ev)
            if self.listener is not None:
                self.listener.record(ev, True, None)
            if self.on_record is not None:
                self.on_record(ev)
        if todo:
            done.update(self._run(problem, todo))
        for i, j in copies:
            ev = dataclasses.replace(done[j], index=i)
            done[i] = ev
            self.reused.add(i)
            self.history.append(ev)
            if self.listener is not None:
                self.listener.record(ev, True, None)
            if self.on_record is not None:
                self.on_record(ev)
        if self.listener is not None:
            self.listener.batch_finished()
        return [done[i] for i, _ in requests]

    def _run(self, problem: Evaluable, jobs: Sequence[Job]) -> dict[int, Evaluation]:
        raise NotImplementedError

    # -- folders and records -----------------------------------------------------------------
    def _workdir(self, index: int) -> Path:
        """``eval_<index>``; with a store, a folder that a stored run owns is never reused
        (``eval_<index>-2``, ...) and one that no stored run owns (left by a run that was under
        way when the study stopped) is emptied."""
        wd = self.root / f"eval_{index:06d}"
        if self.cache is None:
            return wd
        n = 1
        while wd.exists() and self.cache.workdir_taken(wd):
            n += 1
            wd = self.root / f"eval_{index:06d}-{n}"
        if wd.exists():
            shutil.rmtree(wd, ignore_errors=True)
        return wd

    def _keep(self, ev: Evaluation) -> bool:
        if self.keep_workdirs is None:
            return not self._own_root
        return self.keep_workdirs or (not ev.ok and not self._own_root)

    def _finish(self, outcome: RunOutcome) -> Evaluation:
        """A run has finished: clean its folder, store it, tell the listeners."""
        ev = outcome.record
        if ev.workdir and not self._keep(ev):
            shutil.rmtree(ev.workdir, ignore_errors=True)
            ev.workdir = None
        if self.cache is not None:
            self.cache.record(outcome)
        self.history.append(ev)
        if self.listener is not None:
            self.listener.record(ev, False, outcome.worker)
        if self.on_record is not None:
            self.on_record(ev)  # e.g. the study's log: every record is kept as it finishes
        return ev

    def describe(self) -> dict[str, Any]:
        """For provenance: the kind of executor and its settings."""
        return {
            "kind": type(self).__name__,
            "workers": self.slots,
            "timeout": self.timeout,
            "isolate": self.isolate,
            "workdir": str(self.root),
        }

    def close(self) -> None:
        if self._own_root and not self.keep_workdirs:
            shutil.rmtree(self.root, ignore_errors=True)

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialEvaluator(EvaluatorBase):
    """Runs the batch one after another in this process (or, with ``isolate`` or ``timeout``,
    in one child process that is replaced after a time-out or a crash).

    Parameters
    ----------
    workdir
        Root of the per-evaluation working folders (default: a temporary folder).
    keep_workdirs
        Keep every run's folder (True), only failed runs' (False), or all when ``workdir`` is
        given (None, default).
    on_record
        Called with every record, at once (e.g. to log it).
    store, retry_failed, timeout, isolate, listener
        See the module docstring; ``timeout`` is in seconds of wall time per run.
    """

    def __init__(
        self,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        on_record: Callable[[Evaluation], None] | None = None,
        **options: Any,
    ) -> None:
        super().__init__(workdir, keep_workdirs, on_record, **options)
        self._runner: IsolatedRunner | None = None

    def _run(self, problem: Evaluable, jobs: Sequence[Job]) -> dict[int, Evaluation]:
        out: dict[int, Evaluation] = {}
        for i, wd, x in jobs:
            if self.isolate:
                if self._runner is None:
                    self._runner = IsolatedRunner()
                outcome = self._runner.run(problem, x, str(wd), i, self.timeout)
            else:
                outcome = evaluate_here(problem, x, str(wd), i)
            out[i] = self._finish(outcome)
        return out

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": "serial"}

    def close(self) -> None:
        if self._runner is not None:
            self._runner.stop()
            self._runner = None
        super().close()


# -- the process pool ----------------------------------------------------------------------------
_WORKER_PROBLEM: Evaluable | None = None


def _init_worker(problem: Evaluable) -> None:
    global _WORKER_PROBLEM
    _WORKER_PROBLEM = problem
    parent = os.getppid()

    def watch() -> None:  # a worker whose study was killed (SIGKILL) ends itself
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


#: Written in a run's folder when a worker starts it and removed when it ends: after a worker
#: dies, the runs that have it are the suspects, the others never started.
_STARTED = ".fbia-started"


def _run_in_worker(
    x: dict[str, float], workdir: str, index: int, timeout: float | None, isolate: bool
) -> RunOutcome:
    assert _WORKER_PROBLEM is not None
    marker = Path(workdir) / _STARTED
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.write_text(str(os.getpid()))
    outcome = run_isolated_or_here(_WORKER_PROBLEM, x, workdir, index, timeout, isolate)
    marker.unlink(missing_ok=True)
    return outcome


@contextlib.contextmanager
def workers_ignore_sigint() -> Iterator[None]:
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


_DIED = (
    "the worker process died during this run (killed, crashed or exited: e.g. os._exit, "
    "a segfault, the out-of-memory killer)"
)


class ProcessPoolEvaluator(EvaluatorBase):
    """Runs the batch concurrently on a local pool of worker processes.

    Parameters
    ----------
    workers
        Number of worker processes (default: the number of cores).
    workdir
        Root of the per-evaluation working folders (default: a temporary folder).
    keep_workdirs
        Keep every run's folder (True), only failed runs' (False), or all when ``workdir`` is
        given (None, default).
    start_method
        ``"spawn"`` (default: safe with threaded solvers), ``"forkserver"`` or ``"fork"``.
    on_record
        Called in this process with every record, at once (e.g. to log it).
    store, retry_failed, timeout, isolate, listener
        See the module docstring; ``timeout`` is in seconds of wall time per run.

    A run that kills its worker process (``os._exit``, a segfault, the OOM killer) becomes a
    failed record; the rest of the batch is completed and the evaluator stays usable.  With
    ``isolate`` (or a ``timeout``) every worker runs its runs in a child process of its own,
    so a crash or a time-out costs that child only and the pool is never broken.
    """

    def __init__(
        self,
        workers: int | None = None,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        start_method: str = "spawn",
        on_record: Callable[[Evaluation], None] | None = None,
        **options: Any,
    ) -> None:
        super().__init__(workdir, keep_workdirs, on_record, **options)
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
        self._pool_problem: Evaluable | None = None

    @property
    def slots(self) -> int:
        return self.workers

    def _pool_for(self, problem: Evaluable) -> ProcessPoolExecutor:
        if self._pool is None or self._pool_problem is not problem:
            self._shutdown()
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=multiprocessing.get_context(self.start_method),
                initializer=_init_worker,
                initargs=(run_view(problem),),
            )
            self._pool_problem = problem
        return self._pool

    def _run(self, problem: Evaluable, jobs: Sequence[Job]) -> dict[int, Evaluation]:
        done: dict[int, Evaluation] = {}
        try:
            todo = list(jobs)
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
                        done[job[0]] = self._died(
                            job, "the worker pool broke before this run started"
                        )
                    break
                if len(suspects) == 1:
                    done[suspects[0][0]] = self._died(suspects[0], _DIED)
                else:
                    for job in suspects:
                        if self._round(problem, [job], done):
                            self._shutdown()
                            done[job[0]] = self._died(
                                job, f"{_DIED}; it died again when repeated alone"
                            )
                todo = [j for j in lost if j not in suspects]
        except BaseException:  # Ctrl-C or a bug: stop the workers instead of waiting for them
            self._shutdown(kill=True)
            raise
        return done

    def _round(
        self, problem: Evaluable, jobs: Sequence[Job], done: dict[int, Evaluation]
    ) -> list[Job]:
        """Submit ``jobs``; record each as it finishes; return those lost to a dead worker."""
        pool = self._pool_for(problem)
        futures: dict[Future[RunOutcome], Job] = {}
        lost: list[Job] = []
        with workers_ignore_sigint():  # the pool starts its processes on submit
            for k, (i, wd, x) in enumerate(jobs):
                try:
                    fut = pool.submit(_run_in_worker, x, str(wd), i, self.timeout, self.isolate)
                except BrokenProcessPool:  # a worker died while the batch was being submitted:
                    lost = list(jobs[k:])  # these never started and run in the next round
                    break
                futures[fut] = (i, wd, x)
        for fut in as_completed(futures):
            i, wd, x = job = futures[fut]
            try:
                outcome = fut.result()
            except BrokenProcessPool:
                lost.append(job)
                continue
            except (Exception, SystemExit) as exc:  # raised outside problem.evaluate's guard
                message = f"{type(exc).__name__}: {exc}"
                outcome = RunOutcome.unfinished(i, x, str(wd), message, "error")
            done[i] = self._finish(outcome)
        return sorted(lost)

    def _died(self, job: Job, message: str) -> Evaluation:
        i, wd, x = job
        ev = Evaluation(index=i, x=dict(x), status="failed", workdir=str(wd), message=message)
        return self._finish(RunOutcome(ev))

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

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": "processes", "start_method": self.start_method}

    def close(self) -> None:
        self._shutdown()
        super().close()
