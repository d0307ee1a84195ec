"""Resume: a study killed with SIGKILL and run again ends with the uninterrupted result, and no
finished run is repeated; a changed study file is detected; --fresh starts over.

The study is Levenberg-Marquardt (two starts) on the toy model of tests/_models.py, whose
runs take 0.05 s each here (``delay``), so a kill lands in the middle of the study.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _models import PLUGIN, write_driver

import fbia
from fbia.core.registry import Registry
from fbia.storage.store import StudyStore
from fbia.studies import study_file as study_module
from fbia.studies.cli import main
from fbia.studies.study_file import load_study

STUDY = """\
[study]
seed = 2

[model]
name = "toy_mound"
options = {{ delay = {delay} }}

[[parameters]]
name = "E"
bounds = [100.0, 800.0]

[[parameters]]
name = "nu"
bounds = [-0.8, 0.5]

[synthetic]
truth = {{ E = 450.0, nu = 0.15 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]
noise_std = 0.001

[measure]
name = "vertical"

[likelihood]
noise_std = 0.001

[iterator]
name = "levenberg_marquardt"
options = {{ x0 = [ {{ E = 200.0, nu = 0.4 }}, {{ E = 700.0, nu = -0.5 }} ]{extra} }}

[executor]
kind = "{kind}"
workers = 2
"""


@pytest.fixture
def folder(tmp_path, monkeypatch):
    registry = Registry.load(extra=[PLUGIN])
    monkeypatch.setattr(study_module, "default_registry", lambda: registry)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _write(folder: Path, delay: float = 0.1, kind: str = "processes", extra: str = "") -> Path:
    path = folder / "toy.toml"
    path.write_text(STUDY.format(delay=delay, kind=kind, extra=extra))
    return path


def _rows(store: Path) -> list[tuple]:
    db = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        return db.execute(
            "SELECT key, session, attempt, finished, worker FROM runs ORDER BY id"
        ).fetchall()
    finally:
        db.close()


def _count(store: Path) -> int:
    """Rows in a store that another process may be creating right now."""
    try:
        return len(_rows(store)) if store.is_file() else 0
    except sqlite3.OperationalError:  # the file exists, its tables not yet
        return 0


def _workers(store: Path) -> int:
    """Distinct workers that recorded a run so far (0 while the store is being created)."""
    try:
        return len({r[4] for r in _rows(store)}) if store.is_file() else 0
    except sqlite3.OperationalError:
        return 0


def _essence(result: dict) -> dict:
    """A result as JSON without what differs between two runs of one study: provenance, what
    the study adds to ``info`` (files, tables), wall times and working folders of the runs."""
    result = {k: v for k, v in result.items() if k not in ("provenance", "info")}
    for ev in result["evaluations"]:
        del ev["time"], ev["workdir"]
    return result


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_a_killed_study_resumes_to_the_uninterrupted_result_repeating_no_run(folder, capsys):
    _write(folder, delay=0.05)
    write_driver(folder)
    store = folder / "output" / "store.sqlite"
    proc = subprocess.Popen(
        [sys.executable, "drive.py", "run", "toy.toml"],
        cwd=folder,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120.0
        # 12 runs done, by both pool workers (one may start late and take none of the first)
        while _count(store) < 12 or _workers(store) < 2:
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            assert time.monotonic() < deadline
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)  # the study process only, as `kill -9 PID` does
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    before = _rows(store)
    n1 = len(before)
    assert n1 >= 12 and {r[1] for r in before} == {1}
    # the pool's workers notice that their study is gone and end within seconds
    workers = {int(r[4].rsplit(":", 1)[1]) for r in before}
    assert len(workers) == 2
    deadline = time.monotonic() + 10.0
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in workers)

    capsys.readouterr()
    # resume, in this process and serially: the executor does not change the result
    assert main(["run", "toy.toml", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert f"resuming: output/store.sqlite holds {n1} forward runs of this model (0 failed)" in out
    assert "note: the last run (started " in out  # ... was stopped without a word
    after = _rows(store)
    # the runs stored before the kill are untouched, none was run again
    assert after[:n1] == before
    assert {r[1] for r in after[n1:]} == {2} and {r[2] for r in after} == {1}

    # the same study, uninterrupted, through the API
    study = load_study("toy.toml")
    with StudyStore(folder / "ref.sqlite") as ref_store:
        with fbia.SerialEvaluator(store=ref_store) as evaluator:
            reference = study.iterator.run(study.problem, evaluator)
            reused_in_reference = len(evaluator.reused)
    result = json.loads((folder / "output" / "result.json").read_text())
    assert _essence(result) == _essence(json.loads(json.dumps(reference.to_dict(), default=str)))
    assert sorted(r[0] for r in after) == sorted(r[0] for r in _rows(folder / "ref.sqlite"))
    # this session's log marks the reused records: the n1 stored ones, plus the points that
    # the iterator asks for twice (reused in the uninterrupted run too)
    log = (folder / "output" / "evaluations.jsonl").read_text().splitlines()
    assert sum(json.loads(line)["reused"] for line in log) == reused_in_reference + n1
    sessions = result["provenance"]["store"]["sessions"]
    assert [(s["id"], s["status"], s["evaluations"]) for s in sessions] == [
        (1, "running", n1),
        (2, "done", len(after) - n1),
    ]


def test_changes_that_keep_the_runs_reuse_them_others_run_anew_until_fresh(folder, capsys):
    _write(folder, delay=0.0, kind="serial")
    assert main(["run", "toy.toml"]) == 0
    n = len(_rows(folder / "output" / "store.sqlite"))
    # a third start (and another iteration limit): the first two starts' runs are stored,
    # only the new chain runs
    _write(folder, delay=0.0, kind="serial", extra=", max_iter = 40")
    text = (folder / "toy.toml").read_text()
    (folder / "toy.toml").write_text(
        text.replace("nu = -0.5 }", "nu = -0.5 }, { E = 300.0, nu = 0.0 }")
    )
    capsys.readouterr()
    assert main(["run", "toy.toml"]) == 0
    out = capsys.readouterr().out
    assert "note: the study file changed since the last run" in out
    rows = _rows(folder / "output" / "store.sqlite")
    new = len(rows) - n
    assert 0 < new < n and {r[1] for r in rows[n:]} == {2}
    assert f"evaluations: {new} run now (0 failed), " in out
    result = json.loads((folder / "output" / "result.json").read_text())
    assert len(result["starts"]) == 3 and result["success"]
    # the model's options changed: the stored runs are of another model part, kept beside
    # the new one's runs and not reused
    _write(folder, delay=0.001, kind="serial")
    assert main(["run", "toy.toml"]) == 0
    out = capsys.readouterr().out
    assert (
        out.count(
            f"store: output/store.sqlite holds 0 forward runs of this model and {n + new} of the "
            "same model class with other option values (delay = 0.0), which are not reused\n"
        )
        == 1
    )
    assert "resuming" not in out and "its model did not" not in out
    both = _rows(folder / "output" / "store.sqlite")
    assert both[: len(rows)] == rows and len(both) > len(rows)  # the stored ones untouched
    assert f"evaluations: {len(both) - len(rows)} run now (0 failed), 0 taken" in out
    assert main(["run", "toy.toml", "--fresh"]) == 0
    assert "starting over (--fresh)" in capsys.readouterr().out
    rows = _rows(folder / "output" / "store.sqlite")
    assert len(rows) == n and {r[1] for r in rows} == {1}
