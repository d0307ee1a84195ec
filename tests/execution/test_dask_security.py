"""Only the study reaches the Dask cluster fbia starts for it (issue 44 item 5).

The local cluster, started as ``fbia run`` starts it (a DaskEvaluator, ``cluster = "local"``,
one worker here), speaks TLS with certificates made for it: its own client runs tasks, a
client of this or of another process without them (plain, or with other certificates of its
own) is refused within seconds; no port of its processes answers HTTP unless ``dashboard``
asks for Dask's dashboard.  A study's ``job_extra_directives`` are flags of the batch system's
allow-list: ``fbia validate`` refuses ``--export=ALL,LD_PRELOAD=...``, a line break or a
shell command in one line naming the directive (exit 2).
"""

from __future__ import annotations

import gc
import http.client
import os
import subprocess
import sys

import psutil
import pytest
from _models import FAULT_BOUNDS, PLUGIN
from distributed import Client, Security

import fbia
from fbia.core.registry import Registry
from fbia.execution.cluster_options import check_cluster_options
from fbia.studies import study_file as study_module
from fbia.studies.cli import main

REFUSED = (OSError, TypeError)  # TypeError: a tls:// address without any certificate


@pytest.fixture(scope="module")
def dask_ev(tmp_path_factory):
    with fbia.make_evaluator("dask", workers=1, workdir=tmp_path_factory.mktemp("runs")) as ev:
        yield ev


def _add(a: int, b: int) -> int:
    return a + b


def test_the_studys_own_client_runs_tasks_over_tls(dask_ev):
    address = dask_ev.client.scheduler.address
    assert address.startswith("tls://127.0.0.1:")
    assert dask_ev.client.submit(_add, 1, 2).result(timeout=10) == 3
    assert dask_ev.dask.security.require_encryption


@pytest.mark.parametrize(
    "client",
    [
        pytest.param(lambda a: Client(a, timeout=3), id="no certificate"),
        pytest.param(lambda a: Client(a, security=Security.temporary(), timeout=3), id="other"),
        pytest.param(lambda a: Client(a.replace("tls://", "tcp://"), timeout=3), id="plain tcp"),
    ],
)
def test_a_client_without_the_clusters_certificate_cannot_connect(dask_ev, client):
    with pytest.raises(REFUSED):
        client(dask_ev.client.scheduler.address).close()
    # the refused Client's __del__ now, not when the garbage collector runs it while another
    # Client starts: both take distributed's LoopRunner lock, a deadlock
    gc.collect()


ATTACK = """\
import sys
from pathlib import Path
from distributed import Client
try:
    client = Client(sys.argv[1], timeout=3)
    client.run(lambda: Path(sys.argv[2]).write_text("ran"))
except Exception as exc:
    print(type(exc).__name__)
    sys.exit(1)
"""


def test_another_process_cannot_run_code_on_the_workers(dask_ev, tmp_path):
    marker = tmp_path / "ran"
    done = subprocess.run(
        [sys.executable, "-c", ATTACK, dask_ev.client.scheduler.address, str(marker)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert not marker.exists()


def _answers_http(port: int) -> bool:
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=3)
        conn.request("GET", "/health")
        conn.getresponse()
    except (OSError, http.client.HTTPException):  # a TLS port hangs up
        return False
    return True


def _listening_ports(pids: set[int]) -> set[int]:
    return {
        c.laddr.port
        for c in psutil.net_connections("inet")
        if c.status == psutil.CONN_LISTEN and c.pid in pids
    }


def _cluster_pids(ev) -> set[int]:
    return {os.getpid(), *ev.client.run(os.getpid).values()}


def test_no_port_of_the_cluster_answers_http_by_default(dask_ev):
    ports = _listening_ports(_cluster_pids(dask_ev))
    assert len(ports) >= 3  # the scheduler, the nanny and the worker: TLS all
    assert not [p for p in ports if _answers_http(p)]
    assert dask_ev.dask._cluster.dashboard_link == ""


def test_the_dashboard_is_served_on_loopback_when_asked_for(tmp_path):
    options = {"dashboard": True}
    with fbia.make_evaluator("dask", workers=1, workdir=tmp_path, cluster_options=options) as ev:
        link = ev.dask._cluster.dashboard_link
        assert link.startswith("http://127.0.0.1:")
        port = int(link.split(":")[2].split("/")[0])
        assert _answers_http(port)
        assert ev.client.scheduler.address.startswith("tls://")


def test_a_tls_address_without_a_certificate_is_one_line(dask_ev, tmp_path, capsys):
    with pytest.raises(fbia.ConfigError) as info:
        fbia.make_evaluator("dask", address=dask_ev.client.scheduler.address, workdir=tmp_path)
    assert str(info.value).startswith("cannot reach the Dask scheduler at tls://127.0.0.1:")
    assert "needs this user's certificate in Dask's configuration" in str(info.value)


STUDY = f"""\
[model]
name = "toy_mound"

[[parameters]]
name = "E"
bounds = {list(FAULT_BOUNDS[0])}

[synthetic]
truth = {{ E = 400.0 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]

[measure]
name = "vertical"

[iterator]
name = "grid"
options = {{ n = 4 }}

[executor]
kind = "dask"
"""


@pytest.mark.parametrize(
    ("cluster", "directive", "reason"),
    [
        ("slurm", "--export=ALL,LD_PRELOAD=/tmp/x.so", "--export sets the job's environment"),
        ("slurm", "--partition=LD_PRELOAD=/tmp/x.so", "LD_ variables load code into the job's"),
        ("slurm", "--qos=low\\ncurl x | sh", "a line break would add lines to the job script"),
        ("slurm", "--partition=short; rm -rf ~", "the character ';'"),
        ("slurm", "--partition=short --export=ALL", "--export sets the job's environment"),
        ("slurm", "--wrap=id", "--wrap is not an allowed flag"),
        ("pbs", "-v LD_PRELOAD=/tmp/x.so", "-v sets the job's environment"),
        ("pbs", "-l walltime=1:00:00 $(id)", "the character '$'"),
        ("slurm", "--partition=short", None),
        ("slurm", "-p short", None),
        ("slurm", "--gres=gpu:a100:2", None),
        ("pbs", "-l select=1:ncpus=8:mem=16gb", None),
        ("sge", "-pe smp 8", None),
    ],
)
def test_validate_takes_only_allowed_job_directives(
    tmp_path, monkeypatch, capsys, cluster, directive, reason
):
    registry = Registry.load(extra=[PLUGIN])
    monkeypatch.setattr(study_module, "default_registry", lambda: registry)
    monkeypatch.chdir(tmp_path)
    executor = (
        f'cluster = "{cluster}"\ncluster_options = {{ job_extra_directives = ["{directive}"] }}\n'
    )
    (tmp_path / "study.toml").write_text(STUDY + executor)
    status = main(["validate", "study.toml"])
    err = capsys.readouterr().err
    if reason is None:
        assert status == 0, err
        return
    assert status == 2
    [line] = err.splitlines()
    shown = directive  # the TOML escape is the repr of the line break
    assert line.startswith(
        f"fbia: error: study.toml: [executor] cluster_options: 'job_extra_directives': "
        f"'{shown}' is refused ({reason}"
    ), line
    assert line.endswith(", -q, -t, -w, -x" if cluster == "slurm" else "-P, -q")


def test_other_job_script_values_are_one_word(tmp_path, monkeypatch, capsys):
    registry = Registry.load(extra=[PLUGIN])
    monkeypatch.setattr(study_module, "default_registry", lambda: registry)
    monkeypatch.chdir(tmp_path)
    executor = 'cluster = "slurm"\ncluster_options = { queue = "short --export=ALL,PATH=/tmp" }\n'
    (tmp_path / "study.toml").write_text(STUDY + executor)
    assert main(["validate", "study.toml"]) == 2
    assert (
        "[executor] cluster_options: 'queue': 'short --export=ALL,PATH=/tmp' is refused "
        "(a space): a value goes into the job script" in capsys.readouterr().err
    )


@pytest.mark.parametrize(
    ("cluster", "options", "message"),
    [
        (
            "htcondor",
            {"job_extra_directives": {"environment": "LD_PRELOAD=/tmp/x.so"}},
            "'job_extra_directives': environment = 'LD_PRELOAD=/tmp/x.so' is refused ('envir",
        ),
        (
            "htcondor",
            {"job_extra_directives": {"requirements": "$ENV(HOME)"}},
            "'job_extra_directives': requirements = '$ENV(HOME)' is refused (a macro, a comm",
        ),
        ("htcondor", {"job_extra_directives": {"request_gpus": 1}}, None),
        ("slurm", {"local_directory": "/scratch;sh"}, "'local_directory': '/scratch;sh' is ref"),
        ("local", {"dashboard": "yes"}, "'dashboard': expected true or false, got 'yes'"),
        ("local", {"dashboard": True}, None),
    ],
)
def test_cluster_options_checks(cluster, options, message):
    if message is None:
        check_cluster_options(cluster, options)
        return
    with pytest.raises(fbia.ConfigError) as info:
        check_cluster_options(cluster, options)
    assert str(info.value).startswith(message)
