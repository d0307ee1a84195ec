"""Forward runs in a process of their own: a wall-time limit that really stops a hung run.

>>> import fbia
>>> from fbia.execution.isolation import IsolatedRunner
>>> # problem = fbia.InverseProblem(...)
>>> # with IsolatedRunner() as runner:
>>> #     outcome = runner.run(problem, {"E": 300.0, "nu": 0.2}, "runs/eval_000000", 0, timeout=600)

An :class:`IsolatedRunner` starts one helper Python process (in a session of its own) that
imports fbia and loads the problem once, then *forks* a run process
(:mod:`fbia.execution.isolation_helper`) in a process group of its own, which runs the
forward model and sends each record back; the helper passes it on.  So:

* a run that passes its time limit is stopped for good: its whole process group (the run
  process and any solver it started) is killed with SIGKILL and the run becomes a failed
  record ``"time-out after N s ..."``;
* a run that kills its process (``os._exit``, a segfault, the out-of-memory killer) becomes a
  failed record that says how it died;
* neither costs more than that run: the helper, with everything imported, forks a new run
  process for the next run at once (a fork takes milliseconds);
* runs are as warm as in the worker itself: the run process serves one run after another and
  keeps the model's state between them (``ale_fsi``: warm starts and its last factorisation);
  a run process forked after a failure starts from the helper's model, which the model's
  optional ``prepare()`` built once (``ale_fsi`` meshes there) and which took the
  ``warm_state()`` of every finished run (``adopt_warm_state``);
* a helper whose caller dies (the study was killed) kills the run under way and exits.

Every executor uses it the same way: the serial evaluator in the study's process, the process
pool in each worker, the Dask executor inside each worker's task (a Dask worker is a daemon
process, which may not have ``multiprocessing`` children: the helper is a plain subprocess).
POSIX only (fork, process groups, pipes passed by descriptor).
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import logging
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from ..core.errors import ConfigError, Terminated
from ..core.interface import Interface
from ..core.observation import CoordinateKey
from ..core.parameters import Parameter
from ..core.problem import Evaluable, Evaluation
from .isolation_wire import recv, send

__all__ = [
    "IsolatedRunner",
    "PackedProblem",
    "isolation_mode",
    "RunOutcome",
    "evaluate_here",
    "run_isolated_or_here",
    "run_view",
    "worker_label",
]

logger = logging.getLogger(__name__)

_KILL_WAIT = 10.0  # s to wait for the helper to confirm a killed run before replacing it


@dataclass
class RunOutcome:
    """One finished run: its record, who ran it, and the files it made (name -> path)."""

    record: Evaluation
    worker: str = ""
    artifacts: dict[str, str] = field(default_factory=dict)
    #: the interfaces the forward model gave (for the store), None if it gave none
    interfaces: dict[CoordinateKey, Interface] | None = None

    @classmethod
    def unfinished(
        cls,
        index: int,
        x: dict[str, float],
        workdir: str,
        message: str,
        status: str = "failed",
        seconds: float = 0.0,
        worker: str = "",
    ) -> RunOutcome:
        """A run that gave no record of its own (its process died, timed out, raised outside
        ``problem.evaluate``'s guard): a record with ``status`` and ``message``."""
        record = Evaluation(
            index=index, x=dict(x), status=status, message=message, workdir=workdir, time=seconds
        )
        return cls(record, worker)


def worker_label() -> str:
    """``host:pid`` of this process (the executors' default worker name)."""
    return f"{socket.gethostname()}:{os.getpid()}"


def evaluate_here(problem: Evaluable, x: dict[str, float], workdir: str, index: int) -> RunOutcome:
    """Evaluate in this process; the solution object is dropped, its interfaces travel with
    the record (for the store) and its field files are kept as artifacts.

    A model that raises SystemExit (``sys.exit``) or KeyboardInterrupt itself gives a failed
    record, the same under every executor; a real Ctrl-C (SIGINT to this process while the
    run is under way) still raises KeyboardInterrupt and stops the study.
    """
    t0 = time.perf_counter()
    with _sigint_watch() as signalled:
        try:
            ev = problem.evaluate(x, workdir=workdir, index=index, keep_solution=True)
        except Terminated:  # SIGTERM to the study (fbia.studies.cli): always real
            raise
        except (SystemExit, KeyboardInterrupt) as exc:
            if signalled:
                raise
            seconds = time.perf_counter() - t0
            return RunOutcome.unfinished(
                index, x, workdir, escaped_message(exc), seconds=seconds, worker=worker_label()
            )
    if signalled:  # a Ctrl-C that the model caught and turned into a record
        raise KeyboardInterrupt
    artifacts: dict[str, str] = {}
    interfaces = None
    if ev.solution is not None:
        artifacts = {str(k): str(v) for k, v in ev.solution.fields.items()}
        interfaces = dict(ev.solution.interfaces)
        ev.solution = None
    return RunOutcome(ev, worker_label(), artifacts, interfaces)


def escaped_message(exc: BaseException) -> str:
    """The message of a failed record whose model raised SystemExit or KeyboardInterrupt."""
    if isinstance(exc, SystemExit):
        what = f"SystemExit({exc.code!r}) (sys.exit or exit() in the model or a library it calls)"
    else:
        what = "KeyboardInterrupt, with no Ctrl-C to the study"
    return (
        f"the forward model raised {what}: a run may not end its process; a failed run "
        "raises fbia.ForwardModelError"
    )


@contextlib.contextmanager
def _sigint_watch() -> Iterator[list[int]]:
    """A list that gets an entry when SIGINT arrives during the block: what tells a real
    Ctrl-C from a KeyboardInterrupt the model raised.  Only where SIGINT raises
    KeyboardInterrupt at all (the main thread, with a Python handler): elsewhere (a pool
    worker ignores SIGINT, an isolated run's child dies of it, a Dask task runs in a thread)
    every KeyboardInterrupt comes from the model."""
    seen: list[int] = []
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield seen
        return

    def handler(signum: int, frame: Any) -> Any:
        seen.append(signum)
        return previous(signum, frame)

    signal.signal(signal.SIGINT, handler)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, previous)


def run_view(problem: Evaluable) -> Evaluable:
    """The problem as a worker needs it to evaluate runs, to be sent to other processes.

    A run needs the model, the measure, the observations and the fixed inputs, not the
    priors: the copy keeps the parameters' names and units only, so that loading it in a
    worker does not import ``scipy.stats`` (about 2 s per worker process).  Its ``evaluate``
    gives exactly the records of the original.
    """
    if all(p.prior is None for p in [*problem.parameters, *problem.uncertain]):
        return problem
    view = copy.copy(problem)
    view.parameters = [Parameter(p.name, unit=p.unit) for p in problem.parameters]
    view.uncertain = [Parameter(p.name, unit=p.unit) for p in problem.uncertain]
    return view


@dataclass(frozen=True)
class PackedProblem:
    """A problem as its workers receive it: :func:`run_view` pickled once, by the caller, and
    the SHA-256 digest of those bytes, which is the problem's identity on the workers.

    A Dask worker may hand a task a rebuilt copy of the scattered problem, and a rebuilt copy
    need not pickle to the same bytes as the first (a debug loop caught one; why it differed
    was not found): the runner then took it for another problem and reloaded its helper, and
    the next run started cold -- one run from rest among warm ones (a 2-worker batch of 3-D
    runs, benchmarks/bench_dask_3d.py).  Bytes travel unchanged, so a worker compares digests,
    never objects or its own pickles.
    """

    blob: bytes
    digest: bytes

    @classmethod
    def pack(cls, problem: Evaluable) -> PackedProblem:
        blob = pickle.dumps(run_view(problem), protocol=pickle.HIGHEST_PROTOCOL)
        return cls(blob, hashlib.sha256(blob).digest())

    def unpack(self) -> Evaluable:
        """The problem, loaded once per process and digest: the runs of a worker that are
        not isolated share one model (its warm starts), whichever copy of the bytes came."""
        cached = _UNPACKED.get(self.digest)
        if cached is None:
            _UNPACKED.clear()  # one problem at a time: a study's next one replaces it
            cached = _UNPACKED[self.digest] = pickle.loads(self.blob)
        return cached


#: the problem :meth:`PackedProblem.unpack` loaded in this process, by digest
_UNPACKED: dict[bytes, Evaluable] = {}


# -- the caller's side ---------------------------------------------------------------------------
class IsolatedRunner:
    """Runs evaluations one at a time, each in a forked child of a helper process, and kills
    a run that passes its time limit.

    Not thread-safe: a thread that runs evaluations keeps a runner of its own.
    """

    def __init__(self) -> None:
        if os.name != "posix":
            raise ConfigError("isolated runs (and time-outs) need a POSIX system")
        self._proc: subprocess.Popen[bytes] | None = None
        self._jobs: int | None = None
        self._answers: int | None = None
        self._problem: Evaluable | PackedProblem | None = None
        self._digest: bytes | None = None  # of the problem the helper holds

    @property
    def pid(self) -> int | None:
        """The helper's process id (None when none runs)."""
        return None if self._proc is None else self._proc.pid

    def _start(self) -> None:
        job_r, job_w = os.pipe()
        res_r, res_w = os.pipe()
        code = "from fbia.execution.isolation_helper import helper_main; helper_main()"
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-c", code, str(job_r), str(res_w)],
                pass_fds=(job_r, res_w),
                stdin=subprocess.DEVNULL,
                start_new_session=True,  # no terminal Ctrl-C: the caller decides what stops
            )
        finally:
            os.close(job_r)
            os.close(res_w)
        self._jobs, self._answers = job_w, res_r
        self._problem, self._digest = None, None
        send(job_w, ("init", list(sys.path)))

    def _load(self, problem: Evaluable | PackedProblem) -> str | None:
        """Start the helper if none runs and give it ``problem`` unless it has it; returns the
        helper's message if it cannot load the problem (e.g. cannot import the model)."""
        if self._proc is not None and self._problem is problem:
            return None
        packed = problem if isinstance(problem, PackedProblem) else PackedProblem.pack(problem)
        blob, digest = packed.blob, packed.digest
        if self._proc is not None and digest == self._digest:
            # the same problem in another object: the helper keeps its model, with the warm
            # states and the run process's factorisation (a reload there made a cold run of
            # 17-25 s among warm ones of 1-5 s: 3-D dome, benchmarks/bench_dask_3d.py)
            self._problem = problem
            return None
        if self._proc is not None:
            logger.info("the isolated runs' helper loads another problem: its warm states go")
        for _attempt in (1, 2):  # a helper that died between runs is replaced once
            if self._proc is None:
                self._start()
            assert self._jobs is not None and self._answers is not None
            try:
                send(self._jobs, ("problem", blob))
                answer = recv(self._answers)
            except BrokenPipeError:
                answer = None
            if answer is not None:
                break
            self.stop()
        else:
            return "the helper process for isolated runs ended as it started"
        if answer[1] is not None:
            self.stop()
            return str(answer[1])
        self._problem, self._digest = problem, digest
        return None

    def run(
        self,
        problem: Evaluable | PackedProblem,
        x: dict[str, float],
        workdir: str,
        index: int,
        timeout: float | None = None,
    ) -> RunOutcome:
        """Evaluate ``x`` in a child process; a time-out or a dead child gives a failed record.

        The time limit counts from the start of the child: starting the helper and loading the
        problem (imports of the model's libraries) are not part of the run.
        """
        try:
            return self._run(problem, dict(x), workdir, index, timeout)
        except BaseException:  # Ctrl-C or a broken helper: no run goes on alone
            self.stop()
            raise

    def _run(
        self,
        problem: Evaluable | PackedProblem,
        x: dict[str, float],
        workdir: str,
        index: int,
        timeout: float | None,
    ) -> RunOutcome:
        error = self._load(problem)
        if error is not None:
            return RunOutcome.unfinished(index, x, workdir, error, "error", worker=worker_label())
        assert self._jobs is not None and self._answers is not None
        t0 = time.perf_counter()
        with contextlib.suppress(BrokenPipeError):  # a dead helper: its silence says so below
            send(self._jobs, ("run", x, workdir, index))
        started = recv(self._answers)
        if started is None or started[0] != "started":
            return self._lost(x, workdir, index, t0, "the helper process for isolated runs died")
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            answer = recv(self._answers, deadline)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(started[1], signal.SIGKILL)
            try:  # the helper reaps the child and says so; a silent helper is replaced
                recv(self._answers, time.monotonic() + _KILL_WAIT)
            except TimeoutError:
                self.stop()
            message = (
                f"time-out after {timeout:g} s: the run was stopped (its process group was killed)"
            )
            return RunOutcome.unfinished(
                index, x, workdir, message, seconds=time.perf_counter() - t0, worker=worker_label()
            )
        if answer is None:
            return self._lost(x, workdir, index, t0, "the helper process for isolated runs died")
        if answer[0] == "died":
            message = (
                f"the process running this evaluation died ({answer[1]}: e.g. os._exit, a "
                "segfault, the out-of-memory killer)"
            )
            return RunOutcome.unfinished(
                index, x, workdir, message, seconds=time.perf_counter() - t0, worker=worker_label()
            )
        outcome: RunOutcome = pickle.loads(answer[1])
        outcome.worker = worker_label()
        return outcome

    def _lost(
        self, x: dict[str, float], workdir: str, index: int, t0: float, why: str
    ) -> RunOutcome:
        status = self._reap()
        return RunOutcome.unfinished(
            index,
            x,
            workdir,
            f"{why} ({status})",
            seconds=time.perf_counter() - t0,
            worker=worker_label(),
        )

    def _reap(self) -> str:
        proc = self._proc
        code = None
        if proc is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                code = proc.wait(timeout=5.0)
        self.stop()
        if code is None:
            return "no exit status"
        return f"killed by signal {-code}" if code < 0 else f"exit status {code}"

    def stop(self) -> None:
        """Kill the helper (and the run under way) and forget it."""
        proc, self._proc = self._proc, None
        for fd in (self._jobs, self._answers):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._jobs = self._answers = None
        self._problem, self._digest = None, None
        if proc is not None:
            # closing its job pipe makes the helper kill its child and exit; SIGKILL to its
            # process group covers a helper that does not answer
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=2.0)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=10.0)

    def __enter__(self) -> IsolatedRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


_LOCAL = threading.local()


#: why a time-out cannot go with ``isolate = false`` (the one place this rule is written)
TIMEOUT_NEEDS_ISOLATION = (
    "a time-out needs isolated runs (only a run in its own process can be stopped): "
    "drop isolate = false or the timeout"
)


def isolation_mode(timeout: float | None, isolate: bool | None, default: bool) -> bool:
    """Whether runs go to child processes: ``isolate`` if given, else whenever there is a
    ``timeout``, else ``default``; a ConfigError for a time-out that is not positive or a
    time-out with ``isolate = False``."""
    if timeout is not None and not timeout > 0:
        raise ConfigError(f"timeout must be a positive number of seconds, got {timeout}")
    if timeout is not None and isolate is False:
        raise ConfigError(TIMEOUT_NEEDS_ISOLATION)
    return bool(isolate) if isolate is not None else (timeout is not None or default)


def thread_runner() -> IsolatedRunner:
    """The runner of the calling thread (pool and Dask workers keep one per thread)."""
    runner = getattr(_LOCAL, "runner", None)
    if runner is None:
        runner = _LOCAL.runner = IsolatedRunner()
    return runner


def run_isolated_or_here(
    problem: Evaluable | PackedProblem,
    x: dict[str, float],
    workdir: str,
    index: int,
    timeout: float | None,
    isolate: bool,
) -> RunOutcome:
    """What a worker does with one run: in a child of its thread's helper, or in itself."""
    if isolate:
        return thread_runner().run(problem, x, workdir, index, timeout)
    if isinstance(problem, PackedProblem):
        problem = problem.unpack()
    return evaluate_here(problem, x, workdir, index)
