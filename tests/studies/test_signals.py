"""Issue 14, defect 15: SIGTERM (what a batch system sends at its wall-time limit) stops a
study like Ctrl-C: one line, exit status 143, the finished runs and a result saved."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from _models import write_driver


@pytest.mark.parametrize("executor", ["serial", "processes"])
def test_sigterm_to_the_job_saves_the_finished_runs_and_exits_143(tmp_path, executor):
    write_driver(tmp_path)
    workers = "\nworkers = 2" if executor == "processes" else ""
    (tmp_path / "toy.toml").write_text(
        '[model]\nname = "toy_mound"\noptions = { slow_above = 500.0 }\n'
        '[[parameters]]\nname = "E"\nbounds = [100.0, 800.0]\n'
        '[[parameters]]\nname = "nu"\nbounds = [-0.8, 0.5]\n'
        "[synthetic]\ntruth = { E = 400.0, nu = 0.3 }\ncoordinates = [{ inflow_rate = 100.0 }]\n"
        '[measure]\nname = "vertical"\n[iterator]\nname = "grid"\n'
        f'[executor]\nkind = "{executor}"{workers}\n'
    )
    log = tmp_path / "output" / "evaluations.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "drive.py", "run", "toy.toml"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120.0
        while not (log.is_file() and len(log.read_text().splitlines()) >= 6):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        time.sleep(0.5)  # now in the 30 s runs of the grid's last row (E = 800 Pa)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGTERM)  # as a batch system signals the whole job
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert time.monotonic() - t0 < 15.0
    assert proc.returncode == 143, err
    assert err == "fbia: terminated (SIGTERM); what was computed is saved\n"
    assert len(log.read_text().splitlines()) >= 6
    result = json.loads((tmp_path / "output" / "result.json").read_text())
    assert result["status"] == "interrupted" and "SIGTERM" in result["message"]
