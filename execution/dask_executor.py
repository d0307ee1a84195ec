"""The Dask executor: forward runs on a Dask cluster, from a laptop to SLURM or PBS.

>>> import fbia
>>> # a LocalCluster of 4 worker processes, started for the study and stopped with it:
>>> # with fbia.make_evaluator("dask", workers=4, timeout=3600.0) as ev:
>>> #     records = ev.evaluate(problem, points)
>>> # an existing scheduler:   make_evaluator("dask", address="tls://10.0.0.5:8786")
>>> # a SLURM allocation:      make_evaluator("dask", cluster="slurm", workers=20,
>>> #     cluster_options={"cores": 8, "memory": "16GB", "walltime": "04:00:00"})

Three ways to get workers, chosen by the options (the study file's ``[executor]`` section):

* ``address``: connect to a running scheduler (``dask scheduler`` + ``dask worker`` started by
  hand or by a batch script).  The working folders must lie on a file system the workers share.
  Its security is the user's: fbia connects with the security of Dask's configuration
  (``distributed.comm.tls.ca-file``, ``.client.cert``, ``.client.key`` in ``~/.config/dask/``),
  so a ``tls://`` scheduler started with the user's certificates is reached with them.  A
  ``tcp://`` scheduler is unauthenticated: whoever reaches its port can run code on its
  workers, so start it on a trusted network or with TLS.
* ``cluster = "local"`` (default): a ``distributed.LocalCluster`` of ``workers`` processes with
  one thread each, started for the study and closed with it.  It speaks TLS with certificates
  made for it (``distributed.Security.temporary()``, in this process's memory and handed to
  the worker processes by their nannies): a client of another process, of this user or
  another, cannot connect to it, so cannot run code on its workers (short of reading this
  process's memory).  It serves no HTTP (Dask starts its HTTP servers all the same: they get
  no pages and are closed once the cluster is up) unless ``cluster_options = { dashboard =
  true }``, which serves Dask's dashboard on a free loopback port, readable by every user of
  the machine.
* ``cluster = "slurm" | "pbs" | "sge" | "lsf" | "htcondor" | "moab" | "oar"``: a
  ``dask-jobqueue`` cluster (``pip install dask-jobqueue``) built from ``cluster_options``
  (``cores``, ``memory``, ``walltime``, ``queue``, ``account``, ``job_extra_directives``,
  ...), scaled to ``workers`` workers.

``cluster_options`` are checked against an allow-list (:mod:`fbia.execution.cluster_options`): the
options that run code (``preload``, ``job_script_prologue``, ``python``, ...) or bind network
interfaces (``host``, ``interface``, ...) are refused, and so are values the job script would
run: a ``job_extra_directives`` entry is a flag of the batch system's allow-list
(``--partition=short``), never ``--export=ALL,LD_PRELOAD=...``.

On the local cluster each run of a batch goes to the worker its place in the batch fixes
(:func:`~fbia.execution.local_executors.workers_of_runs`, as in the process pool; workers in
the order of their names), each worker getting its next run when its last is done (before
the client records the last one), so in the batch's order: a warm-starting model's last
digits depend on the runs its process made before, so a study gives the same bits on the same
number of single-threaded workers.  A run goes to another worker only if its own has left the
cluster, and the local cluster runs without Dask's work stealing.  On a scheduler at an
``address`` or a batch-system cluster, whose workers come and go, every run of a batch is
submitted at once for any free worker: there the numbers agree to the model's tolerance, not
bit for bit.

Every run is a task that evaluates in a child process of the worker
(:mod:`fbia.execution.isolation`, ``isolate = True`` by default here): a time-out kills that
child, not the worker, and a run that crashes its process costs the child only, instead of
the worker and every other task on it (Dask would also retry a task whose worker died, three
times by default).  The problem is
scattered to the workers once, as the bytes of its pickle and their digest
(:class:`~fbia.execution.isolation.PackedProblem`: the digest, not the object a worker holds,
tells a worker's runner that a task's problem is the one its helper has loaded); each task
sends back only the record.
"""

from __future__ import annotations

import gc
import logging
import os
import shutil
import time
import uuid
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError
from ..core.extras import require
from ..core.problem import Evaluable, Evaluation
from .cluster_options import check_cluster_options
from .evaluator import BatchEvaluator, Job
from .isolation import PackedProblem, RunOutcome, isolation_mode, run_isolated_or_here
from .local_executors import workers_ignore_sigint, workers_of_runs
from .resources import check_workers

__all__ = ["CLUSTERS", "JOBQUEUE_CLUSTERS", "DaskEvaluator", "DaskExecutor"]

Finish = Callable[[RunOutcome], Evaluation]

#: ``cluster`` names of dask-jobqueue and their classes
JOBQUEUE_CLUSTERS = {
    "slurm": "SLURMCluster",
    "pbs": "PBSCluster",
    "sge": "SGECluster",
    "lsf": "LSFCluster",
    "htcondor": "HTCondorCluster",
    "moab": "MoabCluster",
    "oar": "OARCluster",
}
CLUSTERS = ("local", *JOBQUEUE_CLUSTERS)


def _task(
    problem: PackedProblem,
    x: dict[str, float],
    workdir: str,
    index: int,
    timeout: float | None,
    isolate: bool,
) -> RunOutcome:
    """One forward run on a Dask worker (in the worker's child process when ``isolate``)."""
    from distributed import get_worker

    outcome = run_isolated_or_here(problem, x, workdir, index, timeout, isolate)
    try:
        outcome.worker = str(get_worker().address)
    except ValueError:  # not on a worker (a synchronous scheduler): keep host:pid
        pass
    return outcome


class DaskExecutor:
    """Runs each batch as Dask tasks, one task per forward run (a back end of
    :class:`~fbia.execution.evaluator.BatchEvaluator`).

    Parameters
    ----------
    address
        Scheduler address of a running cluster, e.g. ``"tcp://10.0.0.5:8786"``.
    workers
        Worker processes of the cluster started here (default: the number of cores for
        ``"local"``, 1 for a jobqueue cluster); not allowed with ``address``.
    cluster
        ``"local"`` or a dask-jobqueue kind (see :data:`JOBQUEUE_CLUSTERS`).
    cluster_options
        Keyword arguments of the cluster class (for ``"local"``: those of
        ``distributed.LocalCluster``, e.g. ``memory_limit``, and ``dashboard``: true serves
        Dask's dashboard), from an allow-list (:mod:`fbia.execution.cluster_options`).
    connect_timeout
        Seconds to wait for the scheduler at ``address``.
    timeout, isolate
        See :mod:`fbia.execution.evaluator`; ``isolate`` defaults to True here.
    """

    def __init__(
        self,
        address: str | None = None,
        workers: int | None = None,
        cluster: str = "local",
        cluster_options: Mapping[str, Any] | None = None,
        connect_timeout: float = 30.0,
        timeout: float | None = None,
        isolate: bool | None = None,
    ) -> None:
        require(("distributed",), "the dask executor")
        import distributed

        if cluster not in CLUSTERS:
            raise ConfigError(f"unknown cluster {cluster!r}; valid: {', '.join(CLUSTERS)}")
        if workers is not None and workers < 1:
            raise ConfigError(f"workers must be at least 1, got {workers}")
        self.isolate = isolation_mode(timeout, isolate, default=True)
        self.timeout = timeout
        cluster_options = dict(cluster_options or {})
        try:
            check_cluster_options(cluster, cluster_options)
        except ConfigError as exc:
            raise ConfigError(f"cluster_options: {exc.reason}") from None
        self.address = address
        self.cluster_kind = "scheduler" if address else cluster
        self._cluster: Any = None
        self._token = uuid.uuid4().hex[:8]
        self._scattered: tuple[Evaluable, Any] | None = None
        self.client: Any = None
        #: the TLS credentials of a local cluster (``distributed.Security``), held by this
        #: process only; None for a cluster fbia did not start here
        self.security: Any = None
        t0 = time.perf_counter()
        try:
            self._connect(distributed, address, workers, cluster, cluster_options, connect_timeout)
        except BaseException:
            self.close()  # a half-started cluster
            raise
        #: seconds taken to start (or reach) the cluster
        self.startup_time = time.perf_counter() - t0

    def _connect(
        self,
        distributed: Any,
        address: str | None,
        workers: int | None,
        cluster: str,
        cluster_options: dict[str, Any],
        connect_timeout: float,
    ) -> None:
        if address:
            if workers is not None or cluster != "local" or cluster_options:
                raise ConfigError(
                    "with an address the cluster exists already: workers, cluster and "
                    "cluster_options do not apply"
                )
            failure = None
            try:  # with the security of Dask's configuration (distributed.comm.tls.*)
                self.client = distributed.Client(address, timeout=connect_timeout)
            except (OSError, TypeError) as exc:  # TypeError: tls:// without a certificate
                failure = str(exc)
            if failure is not None:
                # The Client that failed to start is closed by its __del__, which deadlocks if
                # the garbage collector runs it while another Client starts (both take
                # distributed's LoopRunner lock): run it now, its traceback gone.
                gc.collect()
                hint = (
                    " (a tls:// scheduler needs this user's certificate in Dask's configuration: "
                    "distributed.comm.tls.ca-file, .client.cert, .client.key)"
                    if address.startswith("tls://")
                    else ""
                )
                raise ConfigError(f"cannot reach the Dask scheduler at {address}: {failure}{hint}")
        elif cluster == "local":
            self._cluster = _local_cluster(distributed, workers, cluster_options)
            self.security = self._cluster.security
            self.client = distributed.Client(self._cluster)
            if not cluster_options.get("dashboard", False):
                _close_http_servers(self._cluster, self.client)
        else:
            self._cluster = _jobqueue_cluster(cluster, cluster_options)
            self._cluster.scale(n=workers or 1)
            self.client = distributed.Client(self._cluster)

    @property
    def slots(self) -> int:
        try:
            return max(1, sum(self.client.nthreads().values()))
        except (OSError, TimeoutError):  # the scheduler is gone: the batch will tell
            return 1

    def _problem_on_cluster(self, problem: Evaluable) -> Any:
        if self._scattered is None or self._scattered[0] is not problem:
            # as bytes: a worker may rebuild its copy between tasks, and the bytes (with
            # their digest) stay the problem's identity there (PackedProblem)
            packed = PackedProblem.pack(problem)
            data = self.client.scatter(packed, broadcast=True, hash=False)
            self._scattered = (problem, data)
        return self._scattered[1]

    def run(self, problem: Evaluable, jobs: Sequence[Job], finish: Finish) -> dict[int, Evaluation]:
        """Run ``jobs``: on the local cluster each worker its own runs (:meth:`_lanes`), one
        at a time in the batch's order; on other clusters every run at once, for any free
        worker (module docstring)."""
        from distributed import KilledWorker, as_completed

        data = self._problem_on_cluster(problem)
        lanes = self._lanes()
        # one queue per worker, or a single one that every free worker takes from
        queues: list[deque[Job]] = [deque() for _ in range(max(len(lanes), 1))]
        for k, job in zip(workers_of_runs(len(jobs), len(queues)), jobs, strict=True):
            queues[k].append(job)
        futures: dict[Any, tuple[Job, int]] = {}

        def submit(w: int) -> Any:
            job = queues[w].popleft()
            i, wd, x = job
            fut = self.client.submit(
                _task,
                data,
                x,
                str(wd),
                i,
                self.timeout,
                self.isolate,
                pure=False,
                key=f"fbia-eval-{self._token}-{i}",
                # another worker only if this one has left the cluster
                **({"workers": [lanes[w]], "allow_other_workers": True} if lanes else {}),
            )
            futures[fut] = (job, w)
            return fut

        # a worker's next run is submitted when its last one is done: a Dask worker starts
        # the first task that reaches it, and the scheduler may pass on two submissions in
        # either order
        if lanes:
            first = [submit(w) for w in range(len(lanes)) if queues[w]]
        else:
            first = [submit(0) for _ in range(len(jobs))]
        done: dict[int, Evaluation] = {}
        try:
            running = as_completed(first)
            for fut in running:
                (i, wd, x), w = futures.pop(fut)
                try:
                    outcome = fut.result()
                except KilledWorker:
                    outcome = RunOutcome.unfinished(
                        i,
                        x,
                        str(wd),
                        "the Dask worker process died during this run, on every worker that "
                        "tried it (killed, crashed or exited)",
                    )
                except Exception as exc:  # raised outside problem.evaluate's guard
                    message = f"{type(exc).__name__}: {exc}"
                    outcome = RunOutcome.unfinished(i, x, str(wd), message, "error")
                fut.release()
                # the worker's next run first: recording this one (the store, the listener)
                # would otherwise keep the worker idle
                if lanes and queues[w]:
                    running.add(submit(w))
                done[i] = finish(outcome)
        except BaseException:  # Ctrl-C or a bug: stop the tasks instead of waiting for them
            self.client.cancel(list(futures), force=True)
            raise
        return done

    def _lanes(self) -> list[str]:
        """On the local cluster fbia started, the workers' addresses in the order of their
        names (0, 1, ..., which the nanny keeps for a worker it restarts): worker ``w`` of
        :func:`~fbia.execution.local_executors.workers_of_runs` is ``lanes[w]``.  Empty for a
        scheduler at an address or a batch-system cluster, whose workers come and go (a
        SLURM job starts when the queue lets it): there any free worker takes the next run."""
        if self.cluster_kind != "local":
            return []
        try:
            workers = self.client.scheduler_info(n_workers=-1)["workers"]
        except (OSError, TimeoutError):  # the scheduler is gone: the batch will tell
            return []
        return sorted(workers, key=lambda a: (str(workers[a].get("name", "")), a))

    def describe(self) -> dict[str, Any]:
        import dask
        import distributed

        return {
            "kind": "dask",
            "workers": self.slots,
            "timeout": self.timeout,
            "isolate": self.isolate,
            "cluster": self.cluster_kind,
            "scheduler": self.client.scheduler.address if self.client.scheduler else None,
            "dask": dask.__version__,
            "distributed": distributed.__version__,
            "startup_seconds": round(self.startup_time, 3),
        }

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


class DaskEvaluator(BatchEvaluator):
    """A :class:`~fbia.execution.evaluator.BatchEvaluator` with a :class:`DaskExecutor`.

    Parameters
    ----------
    address, workers, cluster, cluster_options, connect_timeout, timeout, isolate
        The executor's (:class:`DaskExecutor`).
    workdir, keep_workdirs, on_record, store, retry_failed, listener
        The front part's (:class:`~fbia.execution.evaluator.BatchEvaluator`); ``workdir`` must be
        visible to the workers.
    """

    def __init__(
        self,
        address: str | None = None,
        workers: int | None = None,
        cluster: str = "local",
        cluster_options: Mapping[str, Any] | None = None,
        workdir: str | Path | None = None,
        keep_workdirs: bool | None = None,
        on_record: Callable[[Evaluation], None] | None = None,
        connect_timeout: float = 30.0,
        *,
        timeout: float | None = None,
        isolate: bool | None = None,
        **front: Any,
    ) -> None:
        executor = DaskExecutor(
            address, workers, cluster, cluster_options, connect_timeout, timeout, isolate
        )
        try:
            super().__init__(executor, workdir, keep_workdirs, on_record, **front)
        except BaseException:
            executor.close()
            raise
        self.dask = executor

    @property
    def client(self) -> Any:
        """The Dask client."""
        return self.dask.client

    @property
    def startup_time(self) -> float:
        """Seconds taken to start (or reach) the cluster."""
        return self.dask.startup_time


def _jobqueue_cluster(kind: str, options: Mapping[str, Any]) -> Any:
    try:
        import dask_jobqueue
    except ImportError:
        raise ConfigError(
            f"cluster {kind!r} needs the package 'dask-jobqueue' (pip install dask-jobqueue, "
            "or pip install 'fbia[cluster]')"
        ) from None
    factory = getattr(dask_jobqueue, JOBQUEUE_CLUSTERS[kind])
    # dask-jobqueue only logs a failed job submission and the study would wait for workers
    # that never come: without the batch system's submit command, say so now
    submit = str(factory.job_cls.submit_command).split()[0]
    if shutil.which(submit) is None:
        raise ConfigError(
            f"cluster {kind!r} submits jobs with {submit!r}, which is not on this machine's PATH "
            "(run the study on the cluster's login node)"
        )
    try:
        return factory(**options)
    except TypeError as exc:
        raise ConfigError(f"bad cluster_options for {JOBQUEUE_CLUSTERS[kind]}: {exc}") from None


def _local_cluster(distributed: Any, workers: int | None, options: Mapping[str, Any]) -> Any:
    """A ``distributed.LocalCluster`` that only this process can use: its scheduler, nannies
    and workers speak TLS with certificates made for it (``Security.temporary()``, kept in
    memory and handed to the worker processes by the nannies), so a client of another process
    cannot connect, whichever user runs it; and it serves no HTTP unless ``dashboard``."""
    import dask

    n_workers = workers or os.cpu_count() or 1
    check_workers(n_workers, "dask executor (local cluster)")
    options = dict(options)
    dashboard = options.pop("dashboard", False)
    try:
        security = distributed.Security.temporary()
    except ImportError:
        raise ConfigError(
            "needs cryptography (the TLS certificates of the local cluster), which is not "
            "installed: pip install 'fbia[dask]'",
            "the dask executor",
        ) from None
    settings: dict[str, Any] = {
        "n_workers": n_workers,
        "threads_per_worker": 1,
        "processes": True,
        "security": security,
        "protocol": "tls://",
        "dashboard_address": None,
        # the scheduler's HTTP server starts even without a dashboard (on port 8787 by
        # default, where a second cluster warned "port 8787 in use"): any free loopback port
        "scheduler_kwargs": {"dashboard_address": "127.0.0.1:0"},
        "silence_logs": logging.ERROR,  # no warnings about tasks cancelled by Ctrl-C
        **options,
    }
    # Without a dashboard the HTTP servers (which Dask starts all the same) get no pages to
    # serve while they run, and _close_http_servers closes them once the cluster is up.
    # Dask reads these routes from its configuration only; the nannies pass it on to the
    # worker processes.
    config: dict[str, Any] = {}
    if not dashboard:
        config = {f"distributed.{role}.http.routes": [] for role in ("scheduler", "worker")}
    # No work stealing: each run stays on the worker DaskExecutor.run gives it (its scheduler
    # runs in this process and reads this when it starts)
    config["distributed.scheduler.work-stealing"] = False
    try:
        with dask.config.set(config), workers_ignore_sigint():  # Ctrl-C reaches the study,
            return distributed.LocalCluster(**settings)  # which stops them
    except TypeError as exc:
        raise ConfigError(f"bad cluster_options for the local cluster: {exc}") from None


def _close_http_servers(cluster: Any, client: Any) -> None:
    """Stop the HTTP servers of ``cluster``'s scheduler and workers, which Dask starts even
    without a dashboard (dask/distributed#7207)."""
    client.run_on_scheduler(_close_scheduler_http)
    client.run(_close_worker_http)
    cluster.scheduler_info.get("services", {}).pop("dashboard", None)  # no dashboard_link


def _close_http(server: Any) -> None:
    server.http_server.stop()
    server.services.pop("dashboard", None)


def _close_scheduler_http(dask_scheduler: Any) -> None:
    _close_http(dask_scheduler)


def _close_worker_http(dask_worker: Any) -> None:
    _close_http(dask_worker)
