"""Sobol' indices (issue 16, item 5): SALib's estimators against the closed-form indices of
the Ishigami function, the same through a GP surrogate, and the iterator on a calibration
problem (its structure, the surrogate check, a study file)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

import fbia
from fbia.iterators.sobol_indices import sobol_indices
from fbia.iterators.surrogates.gp import GpSurrogate

A, B = 7.0, 0.1
PI = math.pi


def ishigami(x: np.ndarray) -> np.ndarray:
    return np.sin(x[:, 0]) + A * np.sin(x[:, 1]) ** 2 + B * x[:, 2] ** 4 * np.sin(x[:, 0])


def _exact() -> tuple[np.ndarray, np.ndarray]:
    """Closed-form indices of the Ishigami function on U(-pi, pi)^3 (Saltelli et al. 2008)."""
    v1 = 0.5 * (1 + B * PI**4 / 5) ** 2
    v2 = A**2 / 8
    v13 = B**2 * PI**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


INPUTS = [fbia.Parameter(f"x{k}", bounds=(-PI, PI)) for k in (1, 2, 3)]


def test_ishigami_indices_match_the_closed_form_within_their_confidence_intervals():
    s1, st = _exact()
    ind = sobol_indices(ishigami, INPUTS, n_base=4096, seed=1, resamples=100)
    assert ind.n_evaluations == 4096 * 5
    for k in range(3):
        assert abs(ind.s1[k] - s1[k]) < max(2 * ind.s1_conf[k], 0.02)
        assert abs(ind.st[k] - st[k]) < max(2 * ind.st_conf[k], 0.02)


def test_the_same_indices_through_a_gp_surrogate_of_the_function():
    s1, st = _exact()
    u = stats.qmc.Sobol(3, scramble=True, seed=3).random(256)
    x = -PI + 2 * PI * u
    gp = GpSurrogate(ard=True).fit(x, ishigami(x), rng=0)
    ind = sobol_indices(gp.predict_mean, INPUTS, n_base=2048, seed=1, resamples=50)
    np.testing.assert_allclose(ind.s1, s1, atol=0.05)
    np.testing.assert_allclose(ind.st, st, atol=0.05)


def _problem() -> fbia.InverseProblem:
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(  # the inflow is an input, uncertain: coordinate {}
        model, {"E": 400.0, "nu": 0.3, "inflow_rate": 100.0}, [{}], noise_std=0.0, seed=0
    )
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        noise_std=0.03,
        parameters=[
            fbia.Parameter("E", bounds=(200.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.5, 0.45)),
        ],
        uncertain=[
            fbia.Parameter(
                "inflow_rate",
                bounds=(90.0, 110.0),
                prior=fbia.priors.uniform(90.0, 110.0),
            )
        ],
    )


def test_the_iterator_ranks_the_inputs_of_the_mound_and_checks_its_surrogate(tmp_path):
    it = fbia.iterator("sobol_indices", quantity="distance", n_train=96, n_test=16, n_base=1024)
    result = it.run(_problem())
    ind = result.indices
    assert result.status == "completed" and result.test_relative_rmse < 0.1
    assert ind.names == ["E", "nu", "inflow_rate"] and result.nfev == 112
    # E moves the mound most over these ranges; the inflow's +-10 % matters least
    assert ind.st[0] > ind.st[2] and ind.st[1] > ind.st[2]
    for s1, st, c in zip(ind.s1, ind.st, ind.st_conf, strict=True):
        assert -0.05 < s1 < st + c and st < 1.05
    assert "E" in result.summary() and result.to_dict()["info"]["indices"]["st"] == ind.st
    (plot,) = it.write_plots(result, _problem(), tmp_path)
    assert plot.exists()


def test_a_starved_design_is_reported_unreliable():
    it = fbia.iterator("sobol_indices", quantity="distance", n_train=6, n_test=8, n_base=256)
    result = it.run(_problem())
    assert result.status == "unreliable" and not result.success
    assert "not reliable" in result.message


def test_a_study_file_runs_the_indices_and_writes_the_plot(study_file, tmp_path, capsys):
    from fbia.studies.cli import main

    study = study_file
    text = study.read_text()
    old = 'name = "levenberg_marquardt"\noptions = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }'
    assert old in text
    study.write_text(
        text.replace(old, 'name = "sobol_indices"\noptions = { n_train = 48, n_base = 256 }')
    )
    assert main(["run", "study.toml"]) == 0
    out = capsys.readouterr().out
    assert "sobol_indices: completed" in out and "ST" in out
    assert (tmp_path / "out" / "plots" / "sobol_indices.png").exists()
