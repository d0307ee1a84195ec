"""Isolated runs are warm (issue 30 item 5): the helper's run process serves the runs one after
another (as the worker itself would), and a run process forked after a time-out starts from the
helper's model, which ``prepare()`` meshed once and which took every finished run's
``warm_state()`` (``adopt_warm_state``)."""

from __future__ import annotations

import pytest

import fbia
from fbia.execution.isolation import IsolatedRunner

pytest.importorskip("ngsolve")

COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06}


def test_isolated_runs_are_meshed_once_and_warm_start_even_after_a_time_out(tmp_path):
    truth = fbia.forward_model("ale_fsi", **COARSE)
    obs = fbia.synthetic_observations(
        truth, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0
    )
    problem = fbia.InverseProblem(
        model=fbia.forward_model("ale_fsi", **COARSE),
        measure=fbia.measure("cpp"),
        observations=obs,
        parameters=[
            fbia.Parameter("E", bounds=(100, 800)),
            fbia.Parameter("nu", bounds=(-0.5, 0.45)),
        ],
        noise_std=0.001,
    )
    with IsolatedRunner() as runner:

        def run(k: int, E: float, timeout: float | None = None) -> fbia.Evaluation:
            x = {"E": E, "nu": 0.3}
            return runner.run(problem, x, str(tmp_path / f"{k}"), k, timeout).record

        first, second = run(0, 350.0), run(1, 360.0)
        killed = run(2, 370.0, timeout=1e-3)  # its run process is killed: a new one follows
        after = run(3, 380.0)
    assert first.ok and second.ok and after.ok
    assert not killed.ok and "time-out" in killed.message
    d0, d1, d3 = first.diagnostics, second.diagnostics, after.diagnostics
    assert d0["warm_start"] is False  # nothing solved before it
    assert d1["warm_start"] is True  # the same run process: its own last state
    # a fresh run process, forked from the helper: warm from the states it adopted, meshed
    assert d3["warm_start"] is True
    assert d3["newton_iterations"] < d0["newton_iterations"]
    # the mesh and solver were built in the helper, before any fork: no run built them
    assert all(d["setup_time"] < 0.1 * first.time for d in (d0, d1, d3))
    # the parent process never ran the model: the warm states lived in the helper only
    assert problem.model.warm_state() == []
