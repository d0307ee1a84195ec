"""Evaluators run batches of forward evaluations: a front part in front of an executor.

>>> import fbia
>>> # problem = fbia.InverseProblem(...)
>>> # with fbia.ProcessPoolEvaluator(workers=2, timeout=600.0) as ev:
>>> #     records = ev.evaluate(problem, [{"E": 300.0, "nu": 0.2}, {"E": 500.0, "nu": 0.1}])

``evaluate(problem, points) -> list[Evaluation]`` returns one record per point, in the order of
``points``, numbered by request (the n-th point ever asked for has ``index`` n).  The data goes
one way::

    runner -> BatchEvaluator (numbering, run cache, folders, listeners)
           -> Executor (serial, process pool, Dask: where runs happen)
           -> isolation (a child process per run, time-outs) -> forward model

:class:`BatchEvaluator` is the front part, the same for every executor:

* **Working folders**: each run in ``<workdir>/eval_<index>``; a failed run's folder is kept,
  a successful one's is removed unless ``keep_workdirs`` (default: keep all when ``workdir`` is
  given, none in a temporary folder).
* **The store** (``store``, a :class:`~fbia.storage.store.StudyStore`, used through
  :class:`~fbia.execution.cache.RunCache`): a point whose run is
  already stored is not run again, its stored record is returned (a failed run is a finished
  run too; ``retry_failed`` runs stored failures once more); every new record is written to the
  store the moment its run finishes.  A point asked for twice in one batch runs once.
* **Listeners**: ``on_record(record)`` and a ``listener`` (progress bar, log file) see every
  record as it finishes; the listener also hears of batches and of records taken from the store.

An :class:`Executor` is the back end: it runs the jobs it is given and hands each outcome to
the front as it arrives.  Every executor turns failures into records (a run that raises, hangs
past ``timeout`` or kills its process becomes a record with status ``failed``/``error`` and its
message; the batch goes on) and honours **time-outs** (``timeout`` seconds of wall time per
run) and **isolation** (``isolate``: each run in a child process of its own,
:mod:`fbia.execution.isolation`, killed with everything it started when the time is up; a time-out
implies isolation).  The executors: :class:`~fbia.execution.local_executors.SerialExecutor`,
:class:`~fbia.execution.local_executors.PoolExecutor`,
:class:`~fbia.execution.dask_executor.DaskExecutor`;
the evaluators :class:`~fbia.SerialEvaluator`, :class:`~fbia.ProcessPoolEvaluator` and
:class:`~fbia.execution.dask_executor.DaskEvaluator` are a front with one of them.
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..core.errors import ConfigError
from ..core.problem import Evaluable, Evaluation, InverseProblem
from .cache import Plan, RunCache
from .isolation import RunOutcome

logger = logging.getLogger(__name__)

if TYPE_CHECKING:
    from ..storage.store import StudyStore

__all__ = [
    "BatchEvaluator",
    "Executor",
    "Job",
    "RunListener",
]


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


class Executor(Protocol):
    """Where forward runs happen: the back end of a :class:`BatchEvaluator`."""

    #: seconds of wall time per run (None: no limit)
    timeout: float | None
    #: whether each run goes to a child process of its own
    isolate: bool

    @property
    def slots(self) -> int:
        """Runs under way at once (for progress displays)."""

    def run(
        self,
        problem: Evaluable,
        jobs: Sequence[Job],
        finish: Callable[[RunOutcome], Evaluation],
    ) -> dict[int, Evaluation]:
        """Run ``jobs``; hand each outcome to ``finish`` the moment it arrives and return
        the records ``finish`` gave back, by index.  Failures are records, not exceptions."""

    def describe(self) -> dict[str, Any]:
        """For provenance: the kind of executor and its settings."""

    def close(self) -> None:
        """Stop the workers."""


class BatchEvaluator:
    """The front part of every evaluator: numbering, the run cache
    (:class:`~fbia.execution.cache.RunCache`, with ``store``), working folders and listeners, in
    front of an :class:`Executor` (see the module docstring).

    Parameters
    ----------
    executor
        Where the runs happen; closed with the evaluator.
    workdir
        Root of the per-evaluation working folders (default: a temporary folder).
    keep_workdirs
        Keep every run's folder (True), only failed runs' (False), or all when ``workdir`` is
        given (None, default).
    on_record
        Called with every record, at once (e.g. to log it).
    store, retry_failed, listener
        See the module docstring.
    """

    def __init__(
        self,
        executor: Executor,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        on_record: Callable[[Evaluation], None] | None = None,
        *,
        store: StudyStore | None = None,
        retry_failed: bool = False,
        listener: RunListener | None = None,
    ) -> None:
        self.executor = executor
        self.on_record = on_record
        self.listener = listener
        #: store lookup, de-duplication and retry (fbia.execution.cache), None without a store
        self.cache = None if store is None else RunCache(store, retry_failed)
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

    # the executor's settings, for callers that read them off the evaluator
    @property
    def slots(self) -> int:
        return self.executor.slots

    @property
    def timeout(self) -> float | None:
        return self.executor.timeout

    @property
    def isolate(self) -> bool:
        return self.executor.isolate

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
        done: dict[int, Evaluation] = {}
        todo: list[Job] = [(i, self._workdir(i), x) for i, x in plan.to_run]
        logger.info(
            "batch: %d points, %d from the store, %d to run on %d slot(s)",
            len(requests),
            len(plan.reused) + len(plan.copies),
            len(todo),
            self.slots,
        )
        for i, wd, x in todo:
            logger.debug("eval %d starts at %s in %s", i, _point(x), wd)
        if self.listener is not None:
            self.listener.batch_started(len(requests), len(plan.reused), len(todo), self.slots)
        for i, ev in plan.reused.items():
            done[i] = self._reuse(ev)
        if todo:
            done.update(self.executor.run(problem, todo, self._finish))
        for i, j in plan.copies:
            done[i] = self._reuse(dataclasses.replace(done[j], index=i))
        if self.listener is not None:
            self.listener.batch_finished()
        return [done[i] for i, _ in requests]

    def run_aside(
        self, problem: Evaluable, x: Mapping[str, float], workdir: str | Path
    ) -> RunOutcome:
        """One run at ``x`` on the executor, outside the books: not numbered, stored, logged
        or told to the listeners, its folder ``workdir`` kept.  For what a study writes beside
        its result (the interfaces at a result's ``x`` that no run was made at, e.g. a
        posterior mean): on a worker that has run the study's batches, the model is warm,
        where a run in the study's process would be its first (a 3-D ``ale_fsi`` run: ~20 s
        cold against a few seconds warm).  Pass the problem the batches were run with: an
        executor's workers are made for one problem."""
        got: list[RunOutcome] = []

        def keep(outcome: RunOutcome) -> Evaluation:
            got.append(outcome)
            return outcome.record

        job = (self.count, Path(workdir), {str(n): float(v) for n, v in x.items()})
        self.executor.run(problem, [job], keep)
        return got[0]

    def _reuse(self, ev: Evaluation) -> Evaluation:
        """A record that did not run now (stored, or a copy of one earlier in the batch)."""
        self.reused.add(ev.index)
        logger.debug("eval %d %s (from the store)%s", ev.index, ev.status, _brief(ev))
        self.history.append(ev)
        if self.listener is not None:
            self.listener.record(ev, True, None)
        if self.on_record is not None:
            self.on_record(ev)
        return ev

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
        logger.info(
            "eval %d %s in %.3g s on %s%s",
            ev.index,
            ev.status,
            ev.time,
            outcome.worker or "?",
            _brief(ev),
        )
        self.history.append(ev)
        if self.listener is not None:
            self.listener.record(ev, False, outcome.worker)
        if self.on_record is not None:
            self.on_record(ev)  # e.g. the study's log: every record is kept as it finishes
        return ev

    def describe(self) -> dict[str, Any]:
        """For provenance: the kind of executor, its settings and the working folder."""
        return {**self.executor.describe(), "workdir": str(self.root)}

    def close(self) -> None:
        self.executor.close()
        if self._own_root and not self.keep_workdirs:
            shutil.rmtree(self.root, ignore_errors=True)

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _point(x: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {v:.6g}" for k, v in x.items())


def _brief(ev: Evaluation) -> str:
    """D of a run that went through, the reason of one that failed."""
    if ev.ok:
        return f", D = {ev.distance:.6g}"
    return f": {ev.message}" if ev.message else ""
