"""SerialEvaluator and ProcessPoolEvaluator: same records, order, folders, failures, crashes,
time-outs.

The toy model (tests/_models.py) is closed form, so every ok record has exact residuals.  It
fails on purpose: ForwardModelError above E = 650 Pa, RuntimeError above 680 Pa, os._exit above
750 Pa, and takes 30 s above 790 Pa; with ``fault_rate`` it fails, hangs or exits on a fraction
of its inputs.  One problem object and one pool (2 spawned workers) serve the pool tests, so
the workers start once (plus the restarts that a killed worker forces).
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import threading
import time

import numpy as np
import pytest
from _models import (
    FAULT_GRID,
    HISTORY_BATCHES,
    check_injected_faults,
    expected_histories,
    toy_curve,
    toy_problem,
)

import fbia
from fbia.storage.store import StudyStore
from fbia.studies.evaluation_log import EvaluationLog
from fbia.studies.progress import RunProgress

PROBLEM = toy_problem(fail_above=650.0, bug_above=680.0, die_above=750.0, slow_above=790.0)
POINTS = [{"E": E, "nu": nu} for E, nu in [(200.0, 0.1), (400.0, 0.3), (600.0, -0.2), (300.0, 0.0)]]
FAILING = [*POINTS, {"E": 700.0, "nu": 0.3}, {"E": 660.0, "nu": 0.3}]


def _exact_residuals(E: float, nu: float) -> np.ndarray:
    return toy_curve(E, nu)[:, 1] - toy_curve(400.0, 0.3)[:, 1]


@pytest.fixture(scope="module")
def pool_root(tmp_path_factory):
    return tmp_path_factory.mktemp("pool_runs")


@pytest.fixture(scope="module")
def pool(pool_root):
    with fbia.ProcessPoolEvaluator(workers=2, workdir=pool_root, start_method="spawn") as ev:
        yield ev


def _check_failing_batch(records: list[fbia.Evaluation], first_index: int) -> None:
    assert [r.index for r in records] == list(range(first_index, first_index + len(FAILING)))
    assert [r.x for r in records] == FAILING
    # E = 700 is above both thresholds: the RuntimeError (a plugin bug) comes first -> "error"
    # with the type name; E = 660 only fails (ForwardModelError) -> "failed" with the message
    assert [r.status for r in records] == ["ok", "ok", "ok", "ok", "error", "failed"]
    assert records[4].message == "RuntimeError: toy bug at E = 700.0"
    assert records[5].message == "mesh distortion at E = 660.0"
    for r in records[4:]:
        assert r.residuals is None and np.isnan(r.distance)
    for r, p in zip(records[:4], POINTS, strict=True):
        np.testing.assert_allclose(r.residuals, _exact_residuals(p["E"], p["nu"]), atol=1e-15)
        assert r.distance == pytest.approx(np.linalg.norm(_exact_residuals(p["E"], p["nu"])))
    assert records[1].distance == 0.0  # the truth


def test_serial_records_are_exact_in_batch_order_with_failures_recorded(tmp_path):
    with fbia.SerialEvaluator(workdir=tmp_path) as ev:
        records = ev.evaluate(PROBLEM, FAILING)
    _check_failing_batch(records, 0)
    # each run in its own folder, where the model wrote its file
    folders = [tmp_path / f"eval_{i:06d}" for i in range(len(FAILING))]
    assert [r.workdir for r in records] == [str(f) for f in folders]
    assert [(f / "toy.txt").read_text() for f in folders[:4]] == [f"E={p['E']}\n" for p in POINTS]


def test_pool_gives_the_serial_records_for_the_same_batch(pool, pool_root):
    with fbia.SerialEvaluator() as serial:
        expected = serial.evaluate(PROBLEM, FAILING)
    start = pool.count
    got = pool.evaluate(PROBLEM, FAILING)
    _check_failing_batch(got, start)
    for a, b in zip(expected, got, strict=True):
        assert (a.index + start, a.x, a.status, a.message) == (b.index, b.x, b.status, b.message)
        assert a.distances == b.distances
        if a.residuals is not None:
            np.testing.assert_array_equal(a.residuals, b.residuals)
    # each run in its own folder, named by its index, written by a worker process
    for r, p in zip(got[:4], POINTS, strict=True):
        assert r.workdir == str(pool_root / f"eval_{r.index:06d}")
        assert (pool_root / r.workdir).joinpath("toy.txt").read_text() == f"E={p['E']}\n"
        assert not (pool_root / r.workdir).joinpath(".fbia-started").exists()


def test_a_run_that_kills_its_worker_fails_alone_and_the_pool_carries_on(pool):
    stored: list[fbia.Evaluation] = []
    pool.on_record = stored.append
    batch = [*POINTS, {"E": 780.0, "nu": 0.2}, {"E": 250.0, "nu": 0.4}, {"E": 500.0, "nu": 0.2}]
    start = pool.count
    try:
        records = pool.evaluate(PROBLEM, batch)
    finally:
        pool.on_record = None
    assert [r.status for r in records] == ["ok"] * 4 + ["failed", "ok", "ok"]
    assert records[4].message.startswith("the worker process died during this run")
    assert records[4].x == {"E": 780.0, "nu": 0.2}
    for r, p in zip(records, batch, strict=True):
        if r.ok:
            np.testing.assert_allclose(r.residuals, _exact_residuals(p["E"], p["nu"]), atol=1e-15)
    # every record reached on_record exactly once, as it finished
    assert sorted(r.index for r in stored) == list(range(start, start + len(batch)))
    # the evaluator is still usable for the next batch
    again = pool.evaluate(PROBLEM, POINTS[:2])
    assert [r.status for r in again] == ["ok", "ok"]
    assert [r.index for r in again] == [start + len(batch), start + len(batch) + 1]
    assert again[1].distance == 0.0


def test_each_run_goes_to_the_worker_its_place_in_the_batch_fixes_after_its_earlier_runs():
    """What a worker ran before decides a warm-starting model's result (issue 48): each run of
    a batch goes to the worker ``workers_of_runs`` fixes by its place in the batch, each
    worker taking its runs in the batch's order, however long they take (the first run here
    takes 0.6 s, the others none: any free worker taking the next run gave the other worker
    the runs 1-6).  So two evaluators give the same records, batch after batch."""
    from fbia.execution.local_executors import workers_of_runs

    problem = toy_problem(history=True, pause_below=150.0)
    histories = []
    for _ in range(2):
        with fbia.ProcessPoolEvaluator(workers=2, start_method="spawn") as ev:
            got = [
                [r.diagnostics["earlier"] for r in ev.evaluate(problem, b)] for b in HISTORY_BATCHES
            ]
        histories.append(got)
    for batch in HISTORY_BATCHES:
        assert sorted(set(workers_of_runs(len(batch), 2))) == [0, 1]
    expected = expected_histories(HISTORY_BATCHES, 2)
    assert histories[0] == expected
    assert histories[1] == expected


def test_workers_of_runs_share_a_batch_evenly_and_break_its_patterns():
    from fbia.execution.local_executors import workers_of_runs

    for n, w in [(1, 2), (7, 2), (1000, 2), (10, 3), (5, 8)]:
        got = workers_of_runs(n, w)
        assert got == workers_of_runs(n, w)  # fixed by n
        counts = [got.count(k) for k in range(w)]
        assert max(counts) - min(counts) <= 1 and sum(counts) == n
    # a Sobol design alternates between halves of its first input: no worker gets one half
    halves = [workers_of_runs(1000, 2)[k] for k in range(1, 1000, 2)]
    assert 200 < halves.count(0) < 300


def test_injected_faults_with_a_time_out_leave_the_pool_working(pool):
    # 16 runs, 4 with faults: a failure, a hang past the 1 s time-out, two os._exit; each
    # worker runs its runs in a child process, so the pool itself is never broken
    problem = toy_problem(fault_rate=0.2)
    pool.executor.timeout, pool.executor.isolate = 1.0, True
    try:
        records = pool.evaluate(problem, FAULT_GRID)
        check_injected_faults(records, timeout=1.0)
        workers = {p.pid for p in pool.executor.worker_processes()}
        clean = [r.x for r in records if r.ok][:2]
        assert [r.status for r in pool.evaluate(problem, clean)] == ["ok", "ok"]
        assert {p.pid for p in pool.executor.worker_processes()} == workers  # the same ones
    finally:
        pool.executor.timeout, pool.executor.isolate = None, False


def test_serial_isolated_runs_survive_hangs_and_exits(tmp_path):
    with fbia.SerialEvaluator(workdir=tmp_path, timeout=1.0) as ev:
        assert ev.isolate
        check_injected_faults(ev.evaluate(toy_problem(fault_rate=0.2), FAULT_GRID), 1.0)


def test_a_time_out_needs_isolation():
    with pytest.raises(fbia.ConfigError, match=r"^a time-out needs isolated runs"):
        fbia.SerialEvaluator(timeout=1.0, isolate=False)
    with pytest.raises(fbia.ConfigError, match=r"^timeout must be a positive number"):
        fbia.make_evaluator("processes", timeout=0.0)


def test_ctrl_c_stops_the_workers_at_once_and_keeps_the_finished_records(pool):
    # (runs after the other tests of the module pool: it stops the pool's processes)
    # Ctrl-C arrives 0.5 s after the first record, while both workers are in 30 s runs.
    stored: list[fbia.Evaluation] = []
    workers: list = []
    timers: list[threading.Timer] = []

    def on_record(record: fbia.Evaluation) -> None:
        stored.append(record)
        workers.extend(pool.executor.worker_processes())
        timers.append(threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)))
        timers[-1].start()

    pool.on_record = on_record
    batch = [{"E": 200.0, "nu": 0.1}, {"E": 795.0, "nu": 0.3}, {"E": 799.0, "nu": 0.3}]
    try:
        with pytest.raises(KeyboardInterrupt):
            pool.evaluate(PROBLEM, batch)
        t_stop = time.monotonic()
    finally:
        for t in timers:
            t.cancel()
        pool.on_record = None
    assert [(r.x, r.status) for r in stored] == [({"E": 200.0, "nu": 0.1}, "ok")]
    assert len(workers) == 2
    for proc in workers:  # the 30 s runs were stopped, not waited for
        proc.join(timeout=5.0)
        assert not proc.is_alive()
    assert time.monotonic() - t_stop < 5.0
    # a later batch starts a new pool
    assert [r.status for r in pool.evaluate(PROBLEM, POINTS[:1])] == ["ok"]


def test_a_run_that_kills_its_worker_costs_no_other_workers_run(tmp_path):
    # E = 250 (worker 0) waits until E = 780 (worker 1) has started and is about to kill its
    # worker, so both are under way when worker 1 dies: E = 250 ends as it would have, E = 780
    # fails, E = 400 (worker 0, after E = 250) runs.
    flag = tmp_path / "rendezvous"
    problem = toy_problem(die_above=750.0, wait_below=260.0, rendezvous=str(flag))
    batch = [{"E": 250.0, "nu": 0.4}, {"E": 780.0, "nu": 0.2}, {"E": 400.0, "nu": 0.3}]
    with fbia.ProcessPoolEvaluator(workers=2, start_method="fork") as ev:
        records = ev.evaluate(problem, batch)
        assert len(ev.executor.worker_processes()) == 1  # worker 1 is replaced when needed
    assert flag.exists()
    assert [r.status for r in records] == ["ok", "failed", "ok"]
    assert records[1].message == (
        "the worker process died during this run (killed, crashed or exited: e.g. os._exit, "
        "a segfault, the out-of-memory killer)"
    )
    np.testing.assert_allclose(records[0].residuals, _exact_residuals(250.0, 0.4), atol=1e-15)
    assert records[2].distance == 0.0


def test_workers_that_cannot_start_fail_their_runs_once_and_say_so(monkeypatch, tmp_path):
    """No run started, so no run is to blame: each fails with that reason, once, instead of
    the batch starting worker after worker (fork: the children take the patched start-up)."""
    import fbia.execution.local_executors as local

    def cannot_start(*args):
        raise RuntimeError("no worker today")

    monkeypatch.setattr(local, "_init_worker", cannot_start)
    with fbia.ProcessPoolEvaluator(workers=2, start_method="fork", workdir=tmp_path) as ev:
        records = ev.evaluate(PROBLEM, POINTS)
    assert [r.status for r in records] == ["failed"] * len(POINTS)
    assert {r.message for r in records} == {"the worker process died before this run started"}


def test_serial_on_record_sees_every_record_in_order():
    seen: list[tuple[int, str]] = []
    with fbia.SerialEvaluator(on_record=lambda r: seen.append((r.index, r.status))) as ev:
        ev.evaluate(PROBLEM, FAILING)
    assert seen == [(0, "ok"), (1, "ok"), (2, "ok"), (3, "ok"), (4, "error"), (5, "failed")]


def test_make_evaluator_rejects_unknown_kinds():
    with pytest.raises(
        fbia.ConfigError, match=r"unknown executor 'dask2'; valid: serial, processes, dask$"
    ):
        fbia.make_evaluator("dask2")
    with pytest.raises(fbia.ConfigError, match=r"bad option for executor 'serial': .*'workers'"):
        fbia.make_evaluator("serial", workers=2)


def test_progress_lines_bar_and_log_follow_the_batch(tmp_path, capsys):
    batch = [*POINTS, {"E": 660.0, "nu": 0.3}]
    lines: list[str] = []
    with (
        StudyStore(tmp_path / "s.sqlite") as store,
        EvaluationLog(tmp_path / "e.jsonl") as log,
    ):
        plain = RunProgress(log, lines.append, tty=False, interval=0.0)
        with fbia.SerialEvaluator(store=store, listener=plain) as ev:
            ev.evaluate(PROBLEM, batch)
            ev.evaluate(PROBLEM, batch[3:])  # from the store: nothing to show
        # a line per finished run (interval 0) with the time left, and one at the end
        assert len(lines) == 6
        assert re.fullmatch(
            r"  batch 1: 1/5 runs done, failed 0, running 1, about \d+ s left", lines[0]
        )
        assert lines[-1] == "  batch 1: 5/5 runs done, failed 1, running 0"
        assert plain.totals == {"runs": 5, "reused": 2, "failed": 1}
        # on a terminal: a bar with the same counts, on stderr
        bar = RunProgress(log, lines.append, tty=True)
        with fbia.SerialEvaluator(store=store, listener=bar) as ev:
            ev.evaluate(PROBLEM, [{"E": 700.0, "nu": 0.1}, {"E": 210.0, "nu": 0.1}])
        err = capsys.readouterr().err
        assert "batch 1:   0%|" in err and "0/2 [00:00<?, ?run/s, failed 0, running 1]" in err
        assert err.endswith(" " * 60 + "\r")  # the bar is gone when the batch is done
        assert len(lines) == 6  # no plain lines from a bar
    records = [json.loads(line) for line in (tmp_path / "e.jsonl").read_text().splitlines()]
    assert [(r["index"], r["reused"]) for r in records] == [
        (0, False), (1, False), (2, False), (3, False), (4, False), (5, True), (6, True),
        (0, False), (1, False),
    ]  # fmt: skip
    assert all(
        r["worker"] == f"{socket.gethostname()}:{os.getpid()}" for r in records if not r["reused"]
    )


def test_a_worker_that_dies_while_the_batch_is_submitted_costs_only_its_own_run(pool, monkeypatch):
    """Issue 14, defect 2: submitting the rest of a batch after a worker died raised
    BrokenProcessPool out of evaluate.  Submissions are slowed down here so that the run that
    kills its worker (E = 780 Pa, submitted second, to worker 1) dies before the batch is
    submitted: its worker's next run is refused at submission and runs on a new worker."""
    import time as _time

    real_lanes_for = pool.executor._lanes_for
    calls = {"n": 0}

    def slow_lanes(problem):
        lanes = real_lanes_for(problem)
        for lane in lanes:
            submit = lane.submit

            def slow_submit(*args, _submit=submit, **kwargs):
                calls["n"] += 1
                if calls["n"] == 3:
                    _time.sleep(3.0)  # the killer runs and takes its worker down meanwhile
                return _submit(*args, **kwargs)

            monkeypatch.setattr(lane, "submit", slow_submit)
        return lanes

    monkeypatch.setattr(pool.executor, "_lanes_for", slow_lanes)
    batch = [POINTS[0], {"E": 780.0, "nu": 0.2}, POINTS[1], POINTS[2], POINTS[3]]
    records = pool.evaluate(PROBLEM, batch)
    assert [r.status for r in records] == ["ok", "failed", "ok", "ok", "ok"]
    assert records[1].message.startswith("the worker process died during this run")
    monkeypatch.undo()
    assert [r.status for r in pool.evaluate(PROBLEM, POINTS[:2])] == ["ok", "ok"]


def _threads_here() -> tuple[dict[str, str], list[int]]:
    import os

    from threadpoolctl import threadpool_info

    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
    return {k: os.environ.get(k, "") for k in names}, [i["num_threads"] for i in threadpool_info()]


def _limited_pool_threads(workers: int) -> tuple[dict[str, str], list[int]]:
    """The thread settings a spawned worker sees after ``limit_threads(workers)``."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from fbia.execution.local_executors import limit_threads

    with ProcessPoolExecutor(
        max_workers=1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=limit_threads,
        initargs=(workers,),
    ) as pool:
        return pool.submit(_threads_here).result()


def test_pool_workers_share_the_cores(monkeypatch):
    """Every worker of a pool of n gets cpu_count // n BLAS, OpenMP and numba threads (issue
    29 item 7): two workers each using every core would oversubscribe the machine."""
    import os

    import numpy  # noqa: F401  (a BLAS loaded before the limit, as unpickling a problem does)

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    workers = os.cpu_count() or 1
    env, blas = _limited_pool_threads(workers)
    assert set(env.values()) == {"1"}
    assert blas and set(blas) == {1}
    # the user's OMP_NUM_THREADS wins
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    env, blas = _limited_pool_threads(workers)
    assert set(env.values()) == {"3"} and max(blas) <= 3  # a BLAS may cap it at its own size
