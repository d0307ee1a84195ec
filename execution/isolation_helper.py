"""The helper process of :class:`~fbia.execution.isolation.IsolatedRunner`: the side that runs.

The helper (``python -c "...; helper_main()"``, a session of its own) loads the problem
once, calls the model's optional ``prepare()`` (``ale_fsi`` meshes there), and forks a
**run process** in a process group of its own that serves the runs one after another, as the
study's own process would: it keeps the model's state between runs (``ale_fsi``'s warm starts
and its last factorisation), so an isolated run costs what a run in the worker costs.  The
caller still sees one process group per run (``("started", pid)``): a run past its time limit
is stopped by killing that group, and a run that kills its process (``os._exit``, a segfault,
the out-of-memory killer) ends that process; either way the helper reports how it died and
forks a fresh run process for the next run, which starts from the helper's model: meshed, and
warm from the states the earlier runs sent back (their ``warm_state()``, taken by the helper's
model with ``adopt_warm_state()``).  A helper whose caller dies kills the run under way and
exits; a run process whose helper dies gets SIGKILL (Linux).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pickle
import select
import signal
import sys
from typing import Any

from ..core.problem import Evaluable
from .isolation import evaluate_here
from .isolation_wire import HEADER, exit_text, recv, send

__all__ = ["helper_main"]


def helper_main() -> None:  # pragma: no cover - runs in the helper process
    jobs, answers = int(sys.argv[1]), int(sys.argv[2])
    running: list[int] = []  # the run process, if one is alive
    try:
        _serve(jobs, answers, running)
    except (BrokenPipeError, ConnectionResetError):  # the caller is gone (killed, e.g. during
        pass  # start-up): no traceback
    for pid in running:  # stop the run process with the helper
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(pid, signal.SIGKILL)
    os._exit(0)  # nothing left to flush to a caller that may be gone


class _RunProcess:
    """The forked process that serves the runs (see the module docstring)."""

    def __init__(self, problem: Evaluable, keep: tuple[int, ...]) -> None:
        req_r, self.requests = os.pipe()
        self.results, res_w = os.pipe()
        pid = os.fork()
        if pid == 0:
            for fd in (*keep, self.requests, self.results):
                os.close(fd)
            _run_process(problem, req_r, res_w)
        os.close(req_r)
        os.close(res_w)
        with contextlib.suppress(OSError):  # also done by the child: no race with a kill
            os.setpgid(pid, pid)
        self.pid = pid

    def close(self) -> str:
        """Close the pipes and reap the process; how it ended."""
        for fd in (self.requests, self.results):
            with contextlib.suppress(OSError):
                os.close(fd)
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.pid, signal.SIGKILL)
        _, status = os.waitpid(self.pid, 0)
        return exit_text(status)


def _serve(jobs: int, answers: int, running: list[int]) -> None:  # pragma: no cover - helper
    problem: Evaluable | None = None
    proc: _RunProcess | None = None
    while True:
        message = recv(jobs)
        if message is None:  # the caller closed the pipe or died
            return
        kind = message[0]
        if kind == "init":
            sys.path[:] = message[1]
        elif kind == "problem":
            if proc is not None:  # a run process of another problem
                proc.close()
                proc = None
                running.clear()
            try:
                problem = pickle.loads(message[1])
            except Exception as exc:  # e.g. a model class this process cannot import
                send(answers, ("problem", f"the problem could not be loaded: {exc!r}"))
                return  # the caller starts a new helper for the next problem
            _prepare(problem)
            send(answers, ("problem", None))
        elif kind == "run":
            assert problem is not None
            if proc is None:
                proc = _RunProcess(problem, (jobs, answers))
                running[:] = [proc.pid]
            try:
                send(proc.requests, message[1:])
            except BrokenPipeError:
                pass  # it died between runs: its silence below says so
            send(answers, ("started", proc.pid))
            data = _collect(jobs, proc.results, proc.pid)
            if data is None:
                send(answers, ("died", proc.close()))
                proc = None
                running.clear()
                continue
            data, warm = pickle.loads(data)
            _adopt(problem, warm)
            send(answers, ("done", data))


def _collect(jobs: int, pipe: int, pid: int) -> bytes | None:
    """One answer of the run process (a length-prefixed blob); None if it died.  If the
    caller goes away meanwhile, kill the run process and exit."""
    buffer = b""
    while True:
        want = HEADER.size if len(buffer) < HEADER.size else None
        if want is None:
            total = HEADER.size + HEADER.unpack(buffer[: HEADER.size])[0]
            if len(buffer) >= total:
                return buffer[HEADER.size : total]
        ready, _, _ = select.select([pipe, jobs], [], [])
        if jobs in ready:  # the caller closed its end (or died): nothing waits for this run
            with contextlib.suppress(ProcessLookupError):
                os.killpg(pid, signal.SIGKILL)
            os._exit(0)
        chunk = os.read(pipe, 1 << 20)
        if not chunk:
            return None
        buffer += chunk


# -- the run process ------------------------------------------------------------------------------
def _die_with_parent() -> None:
    """Linux: this process gets SIGKILL when its parent ends (a run whose helper was killed)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG


def _run_process(problem: Evaluable, requests: int, results: int) -> None:
    """Serve runs until the helper closes the pipe: each outcome and the model's warm state
    go back as one blob.  Exits without cleanup of the helper's state."""
    code = 1
    try:
        os.setpgid(0, 0)
        _die_with_parent()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        while True:
            request = recv(requests)
            if request is None:
                code = 0
                break
            x, workdir, index = request
            outcome = evaluate_here(problem, x, workdir, index)
            try:
                data = pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)
            except (pickle.PicklingError, TypeError, AttributeError) as exc:
                ev = outcome.record
                ev.status, ev.message = "error", f"the record could not be sent back: {exc}"
                ev.diagnostics = {}
                data = pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)
            send(results, (data, _warm_state(problem)))
    finally:
        os._exit(code)


# -- warm runs: the model meshed once in the helper, each run's end state adopted by it ---------
def _model(problem: Evaluable | None) -> Any:
    """The problem's forward model, or None: ``fbia.least_squares``' residual function is a
    problem without one."""
    return getattr(problem, "model", None)


def _prepare(problem: Evaluable) -> None:
    """The model's ``prepare()`` in the helper, before the run process is forked, so that it
    inherits what it built (a mesh).  A failure is left to the runs to report: each one
    meets it again and records it."""
    model = _model(problem)
    if model is not None:
        with contextlib.suppress(Exception):
            model.prepare()


def _warm_state(problem: Evaluable) -> Any:
    """In the run process, after a run: the model's ``warm_state()`` (None without a model)."""
    model = _model(problem)
    try:
        return None if model is None else model.warm_state()
    except Exception:  # a warm start is an optimisation: never a reason to lose a record
        return None


def _adopt(problem: Evaluable | None, warm: Any) -> None:
    """In the helper: the model takes a finished run's warm state (``adopt_warm_state``), so a
    run process forked later starts from it."""
    model = _model(problem)
    if warm is not None and model is not None:
        with contextlib.suppress(Exception):
            model.adopt_warm_state(warm)
