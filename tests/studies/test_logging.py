"""Logging as libraries do (issue 43 item 7): the modules that do the work log on their own
``fbia.<module>`` loggers (forward runs with the failure's reason, the store, GP fits, the
adaptive design's checks, tempering), and ``fbia.log`` lines carry the logger's name.
"""

from __future__ import annotations

import logging
import re

from _paths import ROOT

import fbia
from fbia.execution.executors import ExecutorSpec, evaluator_for
from fbia.storage.store import StudyStore
from fbia.studies.cli import main

DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"
LINE = re.compile(r"^\d{4}-\d\d-\d\d [\d:,]+ (DEBUG|INFO|WARNING|ERROR) (fbia[\w.]*): (.*)$")


def _problem():
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(
        model, {"E": 400.0, "nu": 0.3, "inflow_rate": 100.0}, [{}], noise_std=0.0, seed=0
    )
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("rkhs", sigma_w=0.05),
        observations=obs,
        noise_std=0.03,
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
        fixed={"inflow_rate": 100.0},
    )


def _messages(caplog, name):
    return [r.getMessage() for r in caplog.records if r.name == name]


def test_the_log_file_names_each_line_s_logger_and_debug_adds_the_run_starts(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(re.sub(r"x0 = \[.*?\n\]\n", STARTS, DEMO, flags=re.S))
    assert main(["run", str(study)]) == 0
    lines = (tmp_path / "output" / "fbia.log").read_text().splitlines()
    records = [line for line in lines if re.match(r"\d{4}-\d\d-\d\d ", line)]
    parsed = [LINE.match(line) for line in records]
    assert len(records) > 50 and all(parsed)  # the rest: continuation lines of printed tables
    names = {m.group(2) for m in parsed}
    assert {"fbia.studies.runner", "fbia.execution.evaluator", "fbia.core.iteration"} <= names
    runs = [m.group(3) for m in parsed if m.group(2) == "fbia.execution.evaluator"]
    assert any(re.match(r"eval \d+ ok in [\d.e-]+ s on \S+, D = ", r) for r in runs)
    assert {m.group(1) for m in parsed} == {"INFO"}
    assert main(["run", str(study), "--log-level", "debug"]) == 0  # resumed from the store
    text = (tmp_path / "output" / "fbia.log").read_text()
    assert re.search(r"INFO fbia\.storage\.store: store .* holds \d+ runs of model", text)
    assert re.search(r"DEBUG fbia\.execution\.evaluator: eval \d+ ok \(from the store\)", text)


def test_forward_runs_log_their_start_end_and_failure_reason(caplog, tmp_path):
    problem = _problem()
    with StudyStore(tmp_path / "store.sqlite") as store:
        store.bind(problem)
        with (
            caplog.at_level(logging.DEBUG, logger="fbia"),
            evaluator_for(ExecutorSpec("serial", 1), tmp_path, store=store) as evaluator,
        ):
            evaluator.evaluate(problem, [{"E": 400.0, "nu": 0.3}, {"E": 400.0, "nu": 0.7}])
    lines = _messages(caplog, "fbia.execution.evaluator")
    assert lines[0] == "batch: 2 points, 0 from the store, 2 to run on 1 slot(s)"
    assert any(line.startswith("eval 0 starts at E = 400, nu = 0.3 in ") for line in lines)
    assert any(re.match(r"eval 0 ok in .* s on \S+, D = ", line) for line in lines)
    failed = [line for line in lines if line.startswith("eval 1 ") and " in " in line]
    assert failed and "nu" in failed[-1].split(": ", 1)[1]  # the model's reason


def test_gp_fits_design_checks_and_tempering_are_logged(caplog):
    it = fbia.iterator(
        "gp_smc", n_train=40, n_particles=500, n_rejuvenation=5, zeta=0.9, seed=0, n_check=0
    )
    with caplog.at_level(logging.DEBUG, logger="fbia"):
        it.run(_problem())
    fits = _messages(caplog, "fbia.iterators.surrogates.gp")
    assert fits and re.match(r"GP fit: \d+ points, .*length scales \[", fits[0])
    design = _messages(caplog, "fbia.iterators.gp_smc.adaptive_loop")
    assert any(m.startswith("design check on ") for m in design) or any(
        m.startswith("design stops at its budget") for m in design
    )
    assert any(m.startswith("design round 1: ") for m in design)
    smc = _messages(caplog, "fbia.iterators.smc.sampler")
    assert any(m.startswith("tempering step 1: gamma ") for m in smc)
    assert any(re.match(r"SMC: 500 particles to gamma = 1 in \d+ tempering steps", m) for m in smc)
