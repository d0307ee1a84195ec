"""Issue 14, defect 12: a forward model that returns NaN coordinates has failed (a diverged
solve), it is not a plugin bug: a failed run for every iterator, the others go on."""

from __future__ import annotations

import dataclasses

import pytest
from _models import toy_problem

import fbia

#: the toy model returns NaN coordinates above this E
NAN_ABOVE = 600.0


def test_nan_coordinates_are_a_failed_run_with_a_clear_message():
    problem = toy_problem(nan_above=NAN_ABOVE)
    with fbia.SerialEvaluator() as ev:
        ok, bad = ev.evaluate(problem, [{"E": 400.0, "nu": 0.3}, {"E": 700.0, "nu": 0.3}])
    assert ok.status == "ok"
    assert bad.status == "failed"
    assert "NaN or infinite coordinates" in bad.message and "diverged" in bad.message


def test_levenberg_marquardt_loses_only_the_start_in_the_nan_region():
    lm = fbia.iterator(
        "levenberg_marquardt",
        x0=[{"E": 350.0, "nu": 0.2}, {"E": 700.0, "nu": 0.2}, {"E": 450.0, "nu": 0.1}],
    )
    result = lm.run(toy_problem(nan_above=NAN_ABOVE))
    statuses = [row["status"] for row in result.starts]
    assert statuses[1] == "start_failed" and statuses[0] != "plugin_error"
    assert result.success
    assert result.x["E"] == pytest.approx(400.0, rel=1e-6)
    assert "2 of 3 starts converged" in result.message


def test_gp_smc_counts_nan_runs_as_failed():
    gp = fbia.iterator("gp_smc", n_train=24, n_particles=200, seed=1, n_check=0)
    problem = dataclasses.replace(toy_problem(nan_above=NAN_ABOVE), noise_std=0.01)
    result = gp.run(problem)
    failed = [e for e in result.evaluations if not e.ok]
    assert failed and all(e.status == "failed" for e in failed)
    assert all(e.x["E"] > NAN_ABOVE for e in failed)
