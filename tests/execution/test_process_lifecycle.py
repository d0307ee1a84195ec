"""A study killed at a bad moment leaves no process behind and prints nothing (issue 14).

* Defect 6: ``kill -9`` of a study while its process pool starts: every worker ends by itself
  within seconds (a worker used to read its parent's pid after the parent was gone, and
  watched the wrong process for ever).
* Defect 15: the helper process of isolated runs, whose caller is gone before it answers,
  exits at once and silently (it used to print a ``BrokenPipeError`` traceback).
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _models import _alive, toy_problem
from _paths import TESTS

from fbia.execution.isolation_wire import recv, send

_POOL_DRIVER = """
import sys
sys.path.insert(0, {tests!r})
from _models import toy_problem
import fbia
if __name__ == "__main__":
    with fbia.ProcessPoolEvaluator(workers=2, start_method={method!r}) as ev:
        ev.evaluate(toy_problem(delay=30.0), [{{"E": 400.0, "nu": 0.3}}, {{"E": 500.0, "nu": 0.3}}])
"""


def _children(pid: int) -> set[int]:
    """Process ids whose parent is ``pid`` (read from /proc)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("method", ["spawn", "forkserver"])
def test_kill_9_while_the_pool_starts_leaves_no_worker(tmp_path, method):
    (tmp_path / "drive.py").write_text(_POOL_DRIVER.format(tests=str(TESTS), method=method))
    proc = subprocess.Popen(
        [sys.executable, "drive.py"],
        cwd=tmp_path,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    seen: set[int] = set()
    try:
        deadline = time.monotonic() + 60.0
        # kill -9 as soon as the pool's processes exist: they are still starting (importing)
        while len(seen) < 2 and time.monotonic() < deadline and proc.poll() is None:
            kids = _children(proc.pid)
            for kid in kids:  # the forkserver's children are the workers
                seen |= _children(kid)
            seen |= kids if method == "spawn" else set()
            time.sleep(0.005)
        assert seen, "the pool never started"
        seen |= _children(proc.pid)
        proc.kill()
        proc.wait()
        for kid in list(seen):
            seen |= _children(kid)
        deadline = time.monotonic() + 10.0
        while any(_alive(p) for p in seen) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert [p for p in seen if _alive(p)] == []
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in seen:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def _helper(tmp_path: Path) -> tuple[subprocess.Popen[bytes], int, int, Path]:
    """A helper process as IsolatedRunner starts it, its stderr in a file."""
    job_r, job_w = os.pipe()
    res_r, res_w = os.pipe()
    err = tmp_path / "helper.err"
    with err.open("wb") as sink:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from fbia.execution.isolation_helper import helper_main; helper_main()",
                str(job_r),
                str(res_w),
            ],
            pass_fds=(job_r, res_w),
            stdin=subprocess.DEVNULL,
            stderr=sink,
            start_new_session=True,
        )
    os.close(job_r)
    os.close(res_w)
    return proc, job_w, res_r, err


@pytest.mark.parametrize("gone", ["loading the problem", "starting a run"])
def test_the_isolation_helper_exits_silently_when_its_caller_is_gone(tmp_path, gone):
    proc, jobs, answers, err = _helper(tmp_path)
    try:
        send(jobs, ("init", list(sys.path)))
        problem = pickle.dumps(toy_problem(delay=30.0))
        if gone == "starting a run":
            send(jobs, ("problem", problem))
            assert recv(answers, time.monotonic() + 60.0) == ("problem", None)
            os.close(answers)  # the caller dies: its answers pipe has no reader
            send(jobs, ("run", {"E": 400.0, "nu": 0.3}, str(tmp_path / "run"), 0))
        else:
            os.close(answers)
            send(jobs, ("problem", problem))
        assert proc.wait(timeout=20.0) == 0
    finally:
        os.close(jobs)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert err.read_text() == ""
