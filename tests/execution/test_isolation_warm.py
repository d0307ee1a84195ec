"""Isolated runs start warm (issue 30 item 5): the isolation helper meshes the model once
(``prepare()``) before it forks the runs, and takes each finished run's ``warm_state()``, so
the next forked run warm-starts as it would in one process."""

from __future__ import annotations

import pytest

import fbia
from fbia.execution.isolation import IsolatedRunner

pytest.importorskip("ngsolve")

COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06}


def test_isolated_runs_are_meshed_once_and_warm_start_from_earlier_runs(tmp_path):
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
    records = []
    with IsolatedRunner() as runner:
        for k, E in enumerate([350.0, 360.0, 370.0]):
            records.append(
                runner.run(problem, {"E": E, "nu": 0.3}, str(tmp_path / f"{k}"), k).record
            )
    assert all(r.ok for r in records)
    first, *later = (r.diagnostics for r in records)
    assert first["warm_start"] is False  # nothing solved before it
    assert all(d["warm_start"] is True for d in later)  # from the helper's adopted states
    assert all(d["newton_iterations"] < first["newton_iterations"] for d in later)
    # the mesh and solver were built in the helper, before the fork: no run built them
    assert all(d["setup_time"] < 0.1 * records[0].time for d in (first, *later))
    # the parent process never ran the model: the warm states lived in the helper only
    assert problem.model.warm_state() == []
