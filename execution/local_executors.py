"""Executors on this machine: one run after another, or a local pool of worker processes.

:class:`SerialExecutor` and :class:`PoolExecutor` are back ends of
:class:`~fbia.execution.evaluator.BatchEvaluator` (see :mod:`fbia.execution.evaluator`);
:class:`SerialEvaluator` and :class:`ProcessPoolEvaluator` are the evaluators built from
them, with the front part's options (``workdir``, ``store``, ``listener``, ...).

>>> import fbia
>>> with fbia.SerialEvaluator() as ev:
...     ev.describe()["kind"]
'serial'
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import ConfigError
from ..core.problem import Evaluable, Evaluation
from .evaluator import BatchEvaluator, Job
from .isolation import (
    IsolatedRunner,
    RunOutcome,
    evaluate_here,
    isolation_mode,
    run_isolated_or_here,
    run_view,
)
from .resources import check_workers

__all__ = [
    "PoolExecutor",
    "ProcessPoolEvaluator",
    "SerialEvaluator",
    "SerialExecutor",
    "limit_threads",
    "workers_ignore_sigint",
    "workers_of_runs",
]

Finish = Callable[[RunOutcome], Evaluation]


class SerialExecutor:
    """Runs the jobs one after another in this process (or, with ``isolate`` or ``timeout``,
    in one child process that is replaced after a time-out or a crash)."""

    def __init__(self, timeout: float | None = None, isolate: bool | None = None) -> None:
        self.isolate = isolation_mode(timeout, isolate, default=False)
        self.timeout = timeout
        self._runner: IsolatedRunner | None = None

    slots = 1

    def run(self, problem: Evaluable, jobs: Sequence[Job], finish: Finish) -> dict[int, Evaluation]:
        out: dict[int, Evaluation] = {}
        for i, wd, x in jobs:
            if self.isolate:
                if self._runner is None:
                    self._runner = IsolatedRunner()
                outcome = self._runner.run(problem, x, str(wd), i, self.timeout)
            else:
                outcome = evaluate_here(problem, x, str(wd), i)
            out[i] = finish(outcome)
        return out

    def describe(self) -> dict[str, Any]:
        return {"kind": "serial", "workers": 1, "timeout": self.timeout, "isolate": self.isolate}

    def close(self) -> None:
        if self._runner is not None:
            self._runner.stop()
            self._runner = None


# -- the process pool ----------------------------------------------------------------------------
_WORKER_PROBLEM: Evaluable | None = None


_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def limit_threads(workers: int) -> int:
    """Share this machine's cores among ``workers`` processes: in the calling process, BLAS and
    OpenMP (through threadpoolctl, also in libraries loaded already) and numba get
    ``cpu_count // workers`` threads (at least 1), and so do the processes it starts (the
    environment variables).  ``OMP_NUM_THREADS`` set by the user wins.  Returns the count."""
    given = os.environ.get("OMP_NUM_THREADS", "")
    n = (
        int(given)
        if given.isdigit() and int(given) > 0
        else max(1, (os.cpu_count() or 1) // workers)
    )
    for name in (*_THREAD_VARIABLES, "NUMBA_NUM_THREADS"):
        os.environ[name] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)  # kept for the process's life (not used as a context)
    numba = sys.modules.get("numba")
    if numba is not None:  # imported already (unpickling the problem): its pool is sized
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    return n


def _init_worker(problem: Evaluable, parent: int, direct: bool, workers: int = 1) -> None:
    """Set up a pool worker.  ``parent`` is the study's process id, read by the study itself:
    a worker that read it with ``os.getppid()`` after its study was killed during the pool's
    start-up would watch the wrong process and never end.  ``direct``: the study is the
    worker's parent (``spawn``, ``fork``), not the ``forkserver`` process.  The pool's
    ``workers`` share the cores (:func:`limit_threads`): two workers of a GP or an FEM solve
    with every core's threads each would oversubscribe the machine."""
    global _WORKER_PROBLEM
    if not _parent_alive(parent, direct):  # the study is gone already: end now
        os._exit(1)
    limit_threads(workers)
    _WORKER_PROBLEM = problem

    def watch() -> None:  # a worker whose study was killed (SIGKILL) ends itself
        while _parent_alive(parent, direct):
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _parent_alive(parent: int, direct: bool) -> bool:
    if direct:  # race-free: an orphan's parent is init or a subreaper, never the study again
        return os.getppid() == parent
    try:
        os.kill(parent, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - a process of another user took the pid
        return False
    return True


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


class PoolExecutor:
    """Runs the jobs concurrently on a local pool of worker processes.

    Each run of a batch goes to the worker :func:`workers_of_runs` fixes by its place in the
    batch, each worker taking its runs in the batch's order: what a worker has run before (a
    model's warm starts from its own earlier states) is then the same in every run of a
    study, and so are the results, bit for bit.  Any free worker taking the next run
    (``concurrent.futures``' pool) balanced the load as it went but made the results depend
    on which run finished first: two fresh runs of Paper B's 1000-run design on 2 workers
    differed by up to 1e-8 in their residuals and by Monte Carlo amounts in the posterior
    (CHANGELOG, issue 48).

    A run that kills its worker process (``os._exit``, a segfault, the OOM killer) becomes a
    failed record; it costs the runs of no other worker, the dead worker's runs that had not
    started are run on a new one, and the executor stays usable.  With ``isolate`` (or a
    ``timeout``) every worker runs its runs in a child process of its own, so a crash or a
    time-out costs that child only and the worker is never lost.

    Parameters
    ----------
    workers
        Number of worker processes (default: the number of cores).
    start_method
        ``"spawn"`` (default: safe with threaded solvers), ``"forkserver"`` or ``"fork"``.
    timeout, isolate
        See :mod:`fbia.execution.evaluator`; ``timeout`` is in seconds of wall time per run.
    """

    def __init__(
        self,
        workers: int | None = None,
        start_method: str = "spawn",
        timeout: float | None = None,
        isolate: bool | None = None,
    ) -> None:
        self.isolate = isolation_mode(timeout, isolate, default=False)
        self.timeout = timeout
        n = workers if workers is not None else (os.cpu_count() or 1)
        if n < 1:
            raise ConfigError(f"workers must be at least 1, got {workers}")
        check_workers(n, "processes executor")
        if start_method not in multiprocessing.get_all_start_methods():
            raise ConfigError(
                f"unknown start method {start_method!r}; valid: "
                f"{', '.join(multiprocessing.get_all_start_methods())}"
            )
        self.workers = n
        self.start_method = start_method
        #: one single-process pool per worker (None: not started, or lost with its process)
        self._lanes: list[ProcessPoolExecutor | None] = [None] * n
        self._pool_problem: Evaluable | None = None

    @property
    def slots(self) -> int:
        return self.workers

    def _lanes_for(self, problem: Evaluable) -> list[ProcessPoolExecutor]:
        """The workers for ``problem``: all new for another problem; a lost one replaced."""
        if self._pool_problem is not problem:
            self._shutdown()
            self._pool_problem = problem
        for k, lane in enumerate(self._lanes):
            if lane is None:
                self._lanes[k] = ProcessPoolExecutor(
                    max_workers=1,
                    mp_context=multiprocessing.get_context(self.start_method),
                    initializer=_init_worker,
                    initargs=(
                        run_view(problem),
                        os.getpid(),
                        self.start_method != "forkserver",
                        self.workers,
                    ),
                )
        return [lane for lane in self._lanes if lane is not None]

    def worker_processes(self) -> list[multiprocessing.process.BaseProcess]:
        """The worker processes running now (one per worker that has started)."""
        return [
            proc
            for lane in self._lanes
            if lane is not None
            for proc in list((getattr(lane, "_processes", None) or {}).values())
        ]

    def run(self, problem: Evaluable, jobs: Sequence[Job], finish: Finish) -> dict[int, Evaluation]:
        done: dict[int, Evaluation] = {}
        try:
            todo = list(jobs)
            while todo:
                lost = self._round(problem, todo, done, finish)
                # A worker died.  A worker runs one run at a time, so the run it had started is
                # the one that killed it; its runs that had not started go to a new worker in
                # the next round.  If none had started, the worker could not start (or died
                # between runs): its runs fail rather than kill worker after worker.
                started = [j for j in lost if (j[1] / _STARTED).exists()]
                for job in started:
                    done[job[0]] = _died(job, _DIED, finish)
                if lost and not started:
                    for job in lost:
                        done[job[0]] = _died(
                            job, "the worker process died before this run started", finish
                        )
                    break
                todo = [j for j in lost if j not in started]
        except BaseException:  # Ctrl-C or a bug: stop the workers instead of waiting for them
            self._shutdown(kill=True)
            raise
        return done

    def _round(
        self, problem: Evaluable, jobs: Sequence[Job], done: dict[int, Evaluation], finish: Finish
    ) -> list[Job]:
        """Submit ``jobs`` (to the workers :func:`workers_of_runs` gives); record each as it
        finishes; return those lost with a worker that died, whose process is then let go."""
        lanes = self._lanes_for(problem)
        worker = workers_of_runs(len(jobs), len(lanes))
        futures: dict[Future[RunOutcome], Job] = {}
        lost: list[Job] = []
        with workers_ignore_sigint():  # a pool starts its process on the first submit
            for k, job in enumerate(jobs):
                i, wd, x = job
                try:
                    fut = lanes[worker[k]].submit(
                        _run_in_worker, x, str(wd), i, self.timeout, self.isolate
                    )
                except BrokenProcessPool:  # this worker died while the batch was submitted:
                    lost.append(job)  # the run did not start; the next round runs it
                    continue
                futures[fut] = job
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
            done[i] = finish(outcome)
        for k, lane in enumerate(self._lanes):
            if lane is not None and getattr(lane, "_broken", False):
                _stop(lane, kill=True)
                self._lanes[k] = None
        return sorted(lost)

    def _shutdown(self, kill: bool = False) -> None:
        for k, lane in enumerate(self._lanes):
            if lane is not None:
                _stop(lane, kill)
                self._lanes[k] = None
        self._pool_problem = None

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "processes",
            "workers": self.workers,
            "timeout": self.timeout,
            "isolate": self.isolate,
            "start_method": self.start_method,
        }

    def close(self) -> None:
        self._shutdown()


def workers_of_runs(n: int, workers: int) -> list[int]:
    """The worker of each of a batch's ``n`` runs: as many runs each (give or take one), by a
    permutation of the batch seeded by ``n`` alone, so that it follows no pattern of the
    batch.  Run k on worker k mod ``workers`` did: a Sobol design's consecutive points lie in
    opposite halves of its first input, so on 2 workers one worker got nearly every soft,
    slow run (study_cpp's 1000-run design: 29 of the 35 failed runs, 151 s of runs against
    69 s; the batch took 153 s instead of the 109-119 s of any free worker taking the next)."""
    order = np.random.default_rng(n).permutation(n)
    return [int(p) % workers for p in order]


def _stop(pool: ProcessPoolExecutor, kill: bool) -> None:
    """Shut a worker's pool down; with ``kill`` (or broken) its process is terminated first."""
    if kill or getattr(pool, "_broken", False):
        # The standard library has no public way to stop running workers before Python 3.14
        # (ProcessPoolExecutor.terminate_workers).  A broken pool's worker is stopped too:
        # CPython 3.11 can start a worker while it marks the pool broken (a submit racing the
        # worker's death), terminates only the workers it knew of, then waits for the new one
        # forever in shutdown().
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _died(job: Job, message: str, finish: Finish) -> Evaluation:
    i, wd, x = job
    ev = Evaluation(index=i, x=dict(x), status="failed", workdir=str(wd), message=message)
    return finish(RunOutcome(ev))


# -- the evaluators ------------------------------------------------------------------------------
class SerialEvaluator(BatchEvaluator):
    """A :class:`~fbia.execution.evaluator.BatchEvaluator` with a :class:`SerialExecutor`.

    Parameters
    ----------
    workdir, keep_workdirs, on_record
        The front part's (:class:`~fbia.execution.evaluator.BatchEvaluator`).
    timeout, isolate
        The executor's; ``timeout`` is in seconds of wall time per run.
    **front
        The front part's other options: ``store``, ``retry_failed``, ``listener``.
    """

    def __init__(
        self,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        on_record: Callable[[Evaluation], None] | None = None,
        *,
        timeout: float | None = None,
        isolate: bool | None = None,
        **front: Any,
    ) -> None:
        super().__init__(
            SerialExecutor(timeout, isolate), workdir, keep_workdirs, on_record, **front
        )


class ProcessPoolEvaluator(BatchEvaluator):
    """A :class:`~fbia.execution.evaluator.BatchEvaluator` with a :class:`PoolExecutor`.

    Parameters
    ----------
    workers, start_method, timeout, isolate
        The executor's (:class:`PoolExecutor`).
    workdir, keep_workdirs, on_record
        The front part's (:class:`~fbia.execution.evaluator.BatchEvaluator`).
    **front
        The front part's other options: ``store``, ``retry_failed``, ``listener``.
    """

    def __init__(
        self,
        workers: int | None = None,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        start_method: str = "spawn",
        on_record: Callable[[Evaluation], None] | None = None,
        *,
        timeout: float | None = None,
        isolate: bool | None = None,
        **front: Any,
    ) -> None:
        executor = PoolExecutor(workers, start_method, timeout, isolate)
        super().__init__(executor, workdir, keep_workdirs, on_record, **front)

    @property
    def workers(self) -> int:
        return self.executor.slots
