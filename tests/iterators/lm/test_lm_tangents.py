"""Levenberg–Marquardt with the model's tangents (``jacobian = "tangent"``, the default where
the model gives them): one forward run per iteration, the same optimum as with differences, J
from stored tangents on resume, and clear errors where there are none."""

from __future__ import annotations

import numpy as np
import pytest

import fbia
from fbia.storage.store import StudyStore

pytest.importorskip("ngsolve")

COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06}
TRUTH = {"E": 400.0, "nu": 0.3}
COORDS = [{"inflow_rate": 100.0}]


def _problem(model, noise, sigma, e_max=1500.0):
    """E and nu of ``model`` from its own interface at TRUTH with ``noise`` [mm] (seed 3),
    compared by cpp; sigma_N = ``sigma`` [mm]."""
    obs = fbia.synthetic_observations(model, TRUTH, COORDS, noise_std=noise, seed=3)
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        parameters=[
            fbia.Parameter("E", bounds=(100, e_max)),
            fbia.Parameter("nu", bounds=(-0.8, 0.45)),
        ],
        noise_std=sigma,
    )


@pytest.fixture(scope="module")
def fsi_problem():
    return _problem(fbia.forward_model("ale_fsi", **COARSE), noise=0.0005, sigma=0.0005)


def _lm(**options):
    return fbia.iterator("levenberg_marquardt", x0={"E": 600.0, "nu": 0.0}, **options)


def test_tangents_reach_the_optimum_of_differences_at_one_run_per_iteration(fsi_problem):
    tangent = _lm().run(fsi_problem)
    forward = _lm(jacobian="forward").run(fsi_problem)
    assert tangent.info["jacobian"] == "tangent" and forward.info["jacobian"] == "forward"
    assert tangent.success and forward.success
    assert "J from tangents" in tangent.message
    # the same optimum, within 5 % of a standard error (measured: 0.003 and 0.02 of it); the
    # tangents' is the lower one (‖r‖² 1.736414e-05 against 1.736430e-05: forward differences
    # stop where the error of their J, from the solver's tolerance, stops them)
    for name in TRUTH:
        assert abs(tangent.x[name] - forward.x[name]) <= 0.05 * tangent.stderr[name]
    rr = {k: fsi_problem.evaluate(r.x).residuals for k, r in (("t", tangent), ("f", forward))}
    assert rr["t"] @ rr["t"] <= rr["f"] @ rr["f"] * (1.0 + 1e-6)
    assert tangent.iterations >= 3
    assert tangent.nfev <= 1.6 * tangent.iterations  # (issue 30: today 1 run per step taken)
    assert forward.nfev >= 3 * tangent.nfev


def test_a_resumed_study_takes_j_from_the_stored_tangents(fsi_problem, tmp_path):
    with StudyStore(tmp_path / "store.sqlite") as store:
        with fbia.SerialEvaluator(store=store) as ev:
            first = _lm().run(fsi_problem, ev)
        with fbia.SerialEvaluator(store=store) as ev:
            again = _lm().run(fsi_problem, ev)
            assert ev.reused == set(range(again.nfev))  # nothing ran again
    assert again.x == first.x and again.nfev == first.nfev
    assert all(e.jacobian is not None for e in again.evaluations)
    assert again.info["jacobians"] == {"tangent": again.nfev, "forward": 0, "central": 0}


def test_runs_stored_without_tangents_run_again_for_them(fsi_problem, tmp_path):
    """A store made with forward differences: LM with tangents reruns the points it needs
    (one run each) instead of taking J from their differences, and says where J came from."""
    with StudyStore(tmp_path / "store.sqlite") as store:
        with fbia.SerialEvaluator(store=store) as ev:
            _lm(jacobian="forward").run(fsi_problem, ev)
        with fbia.SerialEvaluator(store=store) as ev:
            again = _lm().run(fsi_problem, ev)
            rerun = set(range(again.nfev)) - ev.reused
    assert 0 < len(rerun) <= again.nfev  # the start, at least, was stored without tangents
    assert again.info["jacobians"]["forward"] == 0
    assert "J from the model's tangents" in again.summary()


def test_no_tangents_no_tangent_jacobian():
    problem = _problem(fbia.forward_model("analytic_mound_2d"), noise=0.0, sigma=0.01, e_max=800.0)
    result = _lm().run(problem)
    assert result.info["jacobian"] == "forward" and result.success
    with pytest.raises(fbia.ConfigError, match="gives no tangents for E, nu"):
        _lm(jacobian="tangent").run(problem)
    with pytest.raises(fbia.ConfigError, match="applies to mode='robust' only"):
        fbia.iterator("levenberg_marquardt", mode="paper", jacobian="tangent")
    central = _lm(jacobian="central").run(problem)
    assert central.success and central.info["jacobian"] == "central"
    assert np.allclose([central.x[n] for n in TRUTH], [result.x[n] for n in TRUTH], rtol=1e-4)
