"""The Dask executor on a real ``distributed.LocalCluster`` of 2 worker processes, started once
for this module by a DaskEvaluator (``cluster = "local"``): Levenberg-Marquardt gives the
same result on serial, processes and Dask; a study with injected faults (failure, hang past
the time-out, os._exit) completes on the cluster reached by ``fbia run --address``, each fault
recorded with its status.
"""

from __future__ import annotations

import importlib.util
import json
import os

import dask
import numpy as np
import pytest
from _models import (
    FAULT_BOUNDS,
    HISTORY_BATCHES,
    PLUGIN,
    check_injected_faults,
    expected_histories,
    toy_problem,
)

import fbia
from fbia.core.registry import Registry
from fbia.execution.dask_executor import DaskEvaluator, _jobqueue_cluster
from fbia.execution.executors import ExecutorSpec
from fbia.storage.store import StudyStore
from fbia.studies import study_file as study_module
from fbia.studies.cli import main


@pytest.fixture(scope="module")
def dask_ev(tmp_path_factory):
    root = tmp_path_factory.mktemp("dask_runs")
    with fbia.make_evaluator("dask", workers=2, workdir=root) as ev:
        yield ev


def _lm() -> fbia.IteratorBase:
    return fbia.iterator(
        "levenberg_marquardt", x0=[{"E": 200.0, "nu": 0.4}, {"E": 700.0, "nu": -0.5}]
    )


def test_the_local_cluster_has_two_single_threaded_worker_processes(dask_ev):
    assert isinstance(dask_ev, DaskEvaluator) and dask_ev.isolate
    assert sorted(dask_ev.client.nthreads().values()) == [1, 1]
    pids = dask_ev.client.run(os.getpid)
    assert len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    info = dask_ev.describe()
    assert (info["kind"], info["cluster"], info["workers"]) == ("dask", "local", 2)
    assert info["startup_seconds"] > 0 and info["distributed"]


def test_levenberg_marquardt_is_identical_on_serial_processes_and_dask(dask_ev):
    problem = toy_problem()
    with fbia.SerialEvaluator() as ev:
        serial = _lm().run(problem, ev)
    with fbia.ProcessPoolEvaluator(workers=2) as ev:
        pool = _lm().run(problem, ev)
    dask = _lm().run(problem, dask_ev)
    assert serial.status == "converged_gradient" and serial.nfev == 36
    for other in (pool, dask):
        assert (other.status, other.message, other.x) == (serial.status, serial.message, serial.x)
        assert (other.nfev, other.n_failed) == (serial.nfev, serial.n_failed)
        assert [h["x"] for h in other.history] == [h["x"] for h in serial.history]
        for a, b in zip(serial.evaluations, other.evaluations, strict=True):
            assert (a.x, a.status, a.distances) == (b.x, b.status, b.distances)
            np.testing.assert_array_equal(a.residuals, b.residuals)


def test_each_run_goes_to_the_worker_its_place_in_the_batch_fixes(tmp_path):
    """As in the process pool (issue 48): each run of a batch goes to the worker
    ``workers_of_runs`` fixes, in the batch's order, however long the runs take (the first
    takes 0.6 s, the others none; with the submission before, any free worker taking the next
    run, this failed), so two clusters give the same records.  (A second failure mode, two
    submissions reaching one worker in the wrong order, did not show with this toy model; it
    did on a real study: CHANGELOG, issue 48.)"""
    problem = toy_problem(history=True, pause_below=150.0)
    histories = []
    for k in range(2):
        with fbia.make_evaluator("dask", workers=2, workdir=tmp_path / str(k)) as ev:
            got = [
                [r.diagnostics["earlier"] for r in ev.evaluate(problem, b)] for b in HISTORY_BATCHES
            ]
            workers = ev.client.scheduler_info()["workers"]
            assert sorted(str(w["name"]) for w in workers.values()) == ["0", "1"]
        histories.append(got)
    expected = expected_histories(HISTORY_BATCHES, 2)
    assert histories == [expected, expected]


def test_a_workers_next_run_is_submitted_before_the_last_one_is_recorded(dask_ev, monkeypatch):
    """Recording a finished run (its folder, the store, the listeners) happens on the client;
    the worker's next run is submitted first, so that the worker does not wait for it
    (``benchmarks/bench_dask_3d.py``: the 2-D batch 0.90-0.92x -> 1.02x of serial).  Each
    lane still runs its runs in the batch's order (the test above)."""
    from fbia.execution.local_executors import workers_of_runs

    events: list[tuple[str, int]] = []
    client = dask_ev.client
    submit = client.submit

    def logged(*args, key, **kwargs):  # type: ignore[no-untyped-def]
        events.append(("submit", int(key.rsplit("-", 1)[1])))
        return submit(*args, key=key, **kwargs)

    monkeypatch.setattr(client, "submit", logged)
    monkeypatch.setattr(dask_ev, "on_record", lambda ev: events.append(("record", ev.index)))
    batch = [{"E": 211.1 + 37.0 * k, "nu": 0.31} for k in range(6)]
    records = dask_ev.evaluate(toy_problem(), batch)
    assert all(r.ok for r in records)
    lane = workers_of_runs(len(batch), 2)
    order = {event: n for n, event in enumerate(events)}
    for w in (0, 1):
        runs = [r.index for r, k in zip(records, lane, strict=True) if k == w]
        assert len(runs) == 3
        for earlier, later in zip(runs, runs[1:], strict=False):
            assert order["submit", later] < order["record", earlier]


STUDY = f"""\
[model]
name = "toy_mound"
options = {{ fault_rate = 0.2 }}

[[parameters]]
name = "E"
bounds = {list(FAULT_BOUNDS[0])}

[[parameters]]
name = "nu"
bounds = {list(FAULT_BOUNDS[1])}

[synthetic]
truth = {{ E = 400.0, nu = 0.3 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]

[measure]
name = "vertical"

[iterator]
name = "grid"
options = {{ n = 4 }}

[executor]
kind = "processes"
timeout = 1.0
"""


def test_a_study_with_faults_completes_on_the_cluster_at_an_address(
    dask_ev, tmp_path, monkeypatch, capsys
):
    registry = Registry.load(extra=[PLUGIN])
    monkeypatch.setattr(study_module, "default_registry", lambda: registry)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "faults.toml").write_text(STUDY)
    address = dask_ev.client.scheduler.address
    assert address.startswith("tls://")
    # a tls:// scheduler is reached with the certificate Dask's configuration names (here the
    # cluster's own, in memory)
    security = dask_ev.dask.security
    tls = {
        "distributed.comm.tls.ca-file": security.tls_ca_file,
        "distributed.comm.tls.client.cert": security.tls_client_cert,
        "distributed.comm.tls.client.key": security.tls_client_key,
    }
    with dask.config.set(tls):
        assert main(["run", "faults.toml", "--address", address]) == 0
    out = capsys.readouterr().out
    assert (
        f"running grid on toy_mound with the vertical measure (dask, scheduler {address}, " in out
    )
    assert "16 evaluations: 16 run now (4 failed), 0 taken from the store" in out
    result = json.loads((tmp_path / "output" / "result.json").read_text())
    assert (result["status"], result["nfev"], result["n_failed"]) == ("grid_done", 16, 4)
    executor = result["provenance"]["executor"]
    assert (executor["kind"], executor["cluster"], executor["scheduler"]) == (
        "dask",
        "scheduler",
        address,
    )
    assert executor["timeout"] == 1.0 and executor["isolate"] is True
    with StudyStore(tmp_path / "output" / "store.sqlite") as store:
        runs = sorted(store.runs(), key=lambda r: r.record.index)
    check_injected_faults([r.record for r in runs], timeout=1.0)
    # every run ran on a worker of the cluster; the failed runs' folders are kept
    workers = set(dask_ev.client.nthreads())
    assert {r.worker for r in runs} <= workers
    assert all((r.record.workdir is None) == r.record.ok for r in runs)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"cluster": "k8s"}, "unknown cluster 'k8s'; valid: local, slurm, pbs, sge, lsf, "),
        ({"address": "tcp://a:1", "workers": 2}, "with an address the cluster exists already"),
        ({"workers": 0}, "workers must be at least 1, got 0"),
        ({"timeout": 5.0, "isolate": False}, "a time-out needs isolated runs"),
        ({"cluster_options": {"preload": ["x.py"]}}, "cluster_options: 'preload' is not all"),
        ({"cluster_options": {"host": "0.0.0.0"}}, "cluster_options: 'host' is not allowed"),
        (
            {"cluster": "slurm", "cluster_options": {"python": "/tmp/evil"}},
            "cluster_options: 'python' is not allowed",
        ),
    ],
)
def test_bad_dask_options_are_config_errors(options, message):
    with pytest.raises(fbia.ConfigError) as info:
        fbia.make_evaluator("dask", **options)
    assert str(info.value).startswith(message)


def test_a_jobqueue_cluster_gets_its_options_or_a_clear_error(monkeypatch, tmp_path):
    options = {"cores": 8, "memory": "16GB", "walltime": "04:00:00", "queue": "short"}
    if importlib.util.find_spec("dask_jobqueue") is None:  # the optional extra "cluster"
        with pytest.raises(fbia.ConfigError, match=r"^cluster 'slurm' needs the package 'dask-"):
            fbia.make_evaluator("dask", cluster="slurm", cluster_options=options)
        return
    # passed through unchanged into the job script (an sbatch on the PATH; no job is sent)
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "sbatch").write_text("#!/bin/sh\nexit 1\n")
    (fake / "sbatch").chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake}{os.pathsep}{os.environ['PATH']}")
    cluster = _jobqueue_cluster("slurm", options)
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    for line in ("#SBATCH -p short", "#SBATCH --cpus-per-task=8", "#SBATCH -t 04:00:00"):
        assert line in script
    # no sbatch here: an error now, not a study that waits for workers that never come
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(fbia.ConfigError, match=r"^cluster 'slurm' submits jobs with 'sbatch', wh"):
        fbia.make_evaluator("dask", cluster="slurm", cluster_options=options)


EXECUTOR_CASES = [
    (
        'kind = "dask"\ncluster = "sge2"',
        "[executor] cluster: unknown cluster 'sge2'; valid: local, slurm, pbs, sge, lsf, htcondor",
    ),
    (
        'kind = "processes"\naddress = "tcp://a:1"',
        "[executor] address: address only for kind = \"dask\" (kind is 'processes')",
    ),
    (
        'kind = "dask"\naddress = "tcp://a:1"\nworkers = 3',
        "[executor] address: a scheduler address names a running cluster: workers, cluster and "
        "cluster_options do not apply",
    ),
    ('kind = "serial"\ntimeout = -1.0', "[executor] timeout: must be positive, got -1.0"),
    (
        'kind = "serial"\ntimeout = 10.0\nisolate = false',
        "[executor] isolate: a time-out needs isolated runs",
    ),
    ('kind = "dask"\ncluster_options = 3', "[executor] cluster_options: expected a table, got "),
]
# A study file is data: no cluster option that runs code or binds a network interface
# (issue 14, defect 5); refused before Dask or dask-jobqueue is imported
REFUSED = "is not allowed: a study file may not run code or open the network"
EXECUTOR_CASES += [
    (f'kind = "dask"\ncluster_options = {{ {key} }}', f"[executor] cluster_options: {what}")
    for key, what in [
        ('preload = ["evil.py"]', f"'preload' {REFUSED}"),
        ('host = "0.0.0.0"', f"'host' {REFUSED}"),
        ('dashboard_address = ":8787"', f"'dashboard_address' {REFUSED}"),
        ("scheduler_port = 8786", f"'scheduler_port' {REFUSED}"),
        ('env = { LD_PRELOAD = "x.so" }', f"'env' {REFUSED}"),
        ('memory_limit = "4GB", worker_class = "x.Y"', f"'worker_class' {REFUSED}"),
    ]
] + [
    (
        f'kind = "dask"\ncluster = "slurm"\ncluster_options = {{ {key} }}',
        f"[executor] cluster_options: {what}",
    )
    for key, what in [
        ('job_script_prologue = ["curl x | sh"]', f"'job_script_prologue' {REFUSED}"),
        ('env_extra = ["curl x | sh"]', f"'env_extra' {REFUSED}"),
        ('python = "/tmp/evil"', f"'python' {REFUSED}"),
        ('worker_extra_args = ["--preload", "x.py"]', f"'worker_extra_args' {REFUSED}"),
        ('interface = "eth0"', f"'interface' {REFUSED}"),
        ('scheduler_options = { host = "0.0.0.0" }', f"'scheduler_options' {REFUSED}"),
        ('shebang = "#!/tmp/evil"', f"'shebang' {REFUSED}"),
        (
            'walltime = "01:00:00\\nrm -rf ~"',
            "'walltime': a value with a line break is not allowed",
        ),
        (
            'job_extra_directives = ["--qos=low\\ncurl x | sh"]',
            "'job_extra_directives': '--qos=low\\ncurl x | sh' is refused (a line break would ",
        ),
    ]
]


@pytest.mark.parametrize(("section", "message"), EXECUTOR_CASES)
def test_the_executor_section_is_checked(tmp_path, section, message):
    text = STUDY.split("[executor]")[0] + "[executor]\n" + section + "\n"
    (tmp_path / "bad.toml").write_text(text)
    registry = Registry.load(extra=[PLUGIN])
    with pytest.raises(fbia.ConfigError) as info:
        study_module.load_study(tmp_path / "bad.toml", registry=registry, build=False)
    assert str(info.value).startswith(f"{tmp_path / 'bad.toml'}: {message}")


def test_a_dask_executor_section_reads_into_the_spec(tmp_path):
    text = STUDY.split("[executor]")[0] + (
        '[executor]\nkind = "dask"\ncluster = "pbs"\nworkers = 4\ntimeout = 60.0\n'
        'cluster_options = { cores = 8, memory = "16GB" }\n'
    )
    (tmp_path / "ok.toml").write_text(text)
    study = study_module.load_study(
        tmp_path / "ok.toml", registry=Registry.load(extra=[PLUGIN]), build=False
    )
    spec = study.executor  # resources are allowed
    assert spec == ExecutorSpec(
        "dask", 4, False, 60.0, None, None, "pbs", {"cores": 8, "memory": "16GB"}
    )
    assert spec.label() == "dask, pbs cluster, 4 workers, time-out 60 s"
    assert spec.with_workers(2).workers == 2 and spec.with_workers(2).kind == "dask"
    moved = spec.with_address("tcp://h:8786")
    assert (moved.kind, moved.address, moved.workers, moved.cluster) == (
        "dask",
        "tcp://h:8786",
        None,
        "local",
    )
    with pytest.raises(fbia.ConfigError, match="--workers does not apply to a running Dask"):
        moved.with_workers(2)
