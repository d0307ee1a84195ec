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


def _problem(parameters: list[str], noise: float = 0.001) -> fbia.InverseProblem:
    """A coarse ale_fsi problem against a noise-free observation at E = 400 Pa, nu = 0.3,
    its model a fresh one (``nu`` fixed at 0.3 unless it is a parameter)."""
    truth = fbia.forward_model("ale_fsi", **COARSE)
    obs = fbia.synthetic_observations(
        truth, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0
    )
    bounds = {"E": (100, 800), "nu": (-0.5, 0.45)}
    return fbia.InverseProblem(
        model=fbia.forward_model("ale_fsi", **COARSE),
        measure=fbia.measure("cpp"),
        observations=obs,
        parameters=[fbia.Parameter(n, bounds=bounds[n]) for n in parameters],
        fixed={} if "nu" in parameters else {"nu": 0.3},
        noise_std=noise,
    )


def test_isolated_runs_are_meshed_once_and_warm_start_even_after_a_time_out(tmp_path):
    problem = _problem(["E", "nu"])
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


def test_an_equal_problem_in_another_object_keeps_the_helpers_warm_model(tmp_path, caplog):
    """A Dask worker may rebuild its copy of the scattered problem between tasks: the runner
    sees another object of the same problem.  The helper keeps its model (warm states, the run
    process and its factorisation) instead of loading the problem afresh, which made a cold
    run among warm ones (``benchmarks/bench_dask_3d.py``); a different problem is loaded."""
    import pickle

    from fbia.execution.isolation import run_view

    # a Dask worker's copies of the scattered problem: each one rebuilt from the same bytes
    scattered = pickle.dumps(run_view(_problem(["E"])))
    reloaded = "helper loads another problem"
    with IsolatedRunner() as runner, caplog.at_level("INFO", logger="fbia.execution.isolation"):

        def run(p: object, k: int) -> tuple[fbia.Evaluation, int | None]:
            out = runner.run(p, {"E": 350.0 + k}, str(tmp_path / f"{k}"), k)
            return out.record, runner.pid

        first, helper = run(pickle.loads(scattered), 0)
        same, helper_same = run(pickle.loads(scattered), 1)  # equal, another object
        assert reloaded not in caplog.text
        other, _ = run(run_view(_problem(["E"], noise=0.002)), 2)  # another: loaded afresh, cold
        assert reloaded in caplog.text
    assert first.ok and same.ok and other.ok
    assert first.diagnostics["warm_start"] is False
    assert same.diagnostics["warm_start"] is True and helper_same == helper
    assert same.diagnostics["newton_iterations"] < first.diagnostics["newton_iterations"]
    assert other.diagnostics["warm_start"] is False


def test_a_packed_problem_is_known_by_its_bytes_on_the_worker(tmp_path, monkeypatch):
    """Dask scatters the problem as a :class:`PackedProblem` (the bytes the study pickled and
    their digest).  A worker's rebuilt copy is then the same problem without pickling it again
    there (a rebuilt copy need not pickle to the same bytes: that reloaded the helper and made
    a cold run among warm ones), isolated or not: runs in the worker itself share one model."""
    import pickle

    from fbia.execution import isolation
    from fbia.execution.isolation import PackedProblem, run_isolated_or_here

    problem = _problem(["E"])
    scattered = pickle.dumps(PackedProblem.pack(problem))

    def refuse(cls: object, problem: object) -> None:
        raise AssertionError("a worker pickled the problem again")

    monkeypatch.setattr(PackedProblem, "pack", classmethod(refuse))
    for isolate in (True, False):
        records = [
            run_isolated_or_here(
                pickle.loads(scattered),  # each task another copy of the same bytes
                {"E": 350.0 + k},
                str(tmp_path / f"{isolate}{k}"),
                k,
                None,
                isolate,
            ).record
            for k in range(2)
        ]
        assert all(r.ok for r in records), [r.message for r in records]
        assert records[0].diagnostics["warm_start"] is False
        assert records[1].diagnostics["warm_start"] is True
    isolation.thread_runner().stop()
    assert problem.model.warm_state() == []  # the study's own model never ran
