"""Fixtures shared by the test modules (helpers without pytest live in _models.py and
_studies.py), and the thread share of a pytest-xdist worker."""

from __future__ import annotations

import os
import signal

import pytest
from _studies import write_study


def _share_the_cores_among_xdist_workers() -> None:
    """Under ``pytest -n N`` each worker gets ``cpu_count // N`` BLAS, OpenMP and numba
    threads, as the study's own pool workers do (``fbia.execution.local_executors.
    limit_threads``, issue 30 item 7): with two workers on two cores, each one's GNU OpenMP
    threads (numba's threading layer here) spin between the many short parallel calls of an
    SMC run and take the other worker's core.  numba's pool keeps its size (only the count
    in use is lowered), so a test may still compare one thread with two; processes a test
    starts inherit the BLAS and OpenMP counts.  ``OMP_NUM_THREADS`` set by the user wins."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or 1)
    if workers < 2:
        return
    given = os.environ.get("OMP_NUM_THREADS", "")
    share = max(1, (os.cpu_count() or 1) // workers)
    n = int(given) if given.isdigit() and int(given) > 0 else share
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)
    try:
        import numba
    except ImportError:  # the bayes extra is not installed
        return
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


_share_the_cores_among_xdist_workers()


def _ctrl_c_raises() -> None:
    """Ctrl-C raises KeyboardInterrupt in the test processes, as at a terminal.  A shell that
    starts a job in the background (``make test &``, ``nohup``) without job control sets
    SIGINT to "ignore", which the test processes inherit: the tests of Ctrl-C handling then
    failed (measured 2026-11-28: four of them, a fresh clone's .ci/run started with &)."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


_ctrl_c_raises()


@pytest.fixture
def study_file(tmp_path, monkeypatch):
    """The small valid study of _studies.py in a fresh working folder (the current one)."""
    monkeypatch.chdir(tmp_path)
    return write_study(tmp_path)
