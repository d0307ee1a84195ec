"""Bayes -> Levenberg-Marquardt (issue 16, item 6): LM starts from a gp_smc posterior's MAP
and mean, from the Python API and from a study file that names the Bayesian result."""

from __future__ import annotations

import json

import pytest

import fbia
from fbia.studies.cli import main

FAST = {"n_train": 128, "n_particles": 1000, "n_rejuvenation": 5, "zeta": 0.9, "seed": 0}


def _problem() -> fbia.InverseProblem:
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    truth = {"E": 400.0, "nu": 0.3}
    obs = fbia.synthetic_observations(model, truth, [{"inflow_rate": 100.0}], 0.002, seed=0)
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        noise_std=0.03,
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0), prior=fbia.priors.uniform(100.0, 800.0)),
            fbia.Parameter("nu", bounds=(-0.8, 0.45), prior=fbia.priors.uniform(-0.8, 0.45)),
        ],
    )


def test_lm_starts_from_the_posterior_map_and_mean_and_labels_them():
    problem = _problem()
    bayes = fbia.iterator("gp_smc", **FAST).run(problem)
    assert bayes.status == "completed"  # a posterior worth starting from
    lm = fbia.iterator("levenberg_marquardt", x0=bayes)
    assert lm.options.x0 == [
        dict(zip(["E", "nu"], map(float, bayes.posterior.map), strict=True)),
        dict(zip(["E", "nu"], map(float, bayes.posterior.mean), strict=True)),
    ]
    result = lm.run(problem)
    assert result.success and [row["label"] for row in result.starts] == [
        "posterior MAP",
        "posterior mean",
    ]
    # both starts end at the least-squares optimum of the noisy data, near the truth
    assert result.x["E"] == pytest.approx(400.0, rel=0.05)
    assert result.x["nu"] == pytest.approx(0.3, abs=0.05)
    assert all(row["success"] for row in result.starts)


def test_a_result_without_a_posterior_is_refused():
    problem = _problem()
    lm_result = fbia.iterator("levenberg_marquardt", x0={"E": 350.0, "nu": 0.2}).run(problem)
    with pytest.raises(fbia.ConfigError, match="without a posterior .*only a Bayesian result"):
        fbia.iterator("levenberg_marquardt", x0=lm_result)
    with pytest.raises(fbia.ConfigError, match="not the result of a Bayesian calibration"):
        fbia.iterator("levenberg_marquardt", x0=lm_result.to_dict())


def test_a_bayesian_result_that_has_no_posterior_is_refused():
    """Result.posterior_estimate() is None for a gp_smc run that produced no posterior: the
    hand-off says so instead of starting anywhere."""
    from fbia.iterators.gp_smc.result import GpSmcResult

    failed = GpSmcResult(status="failed", success=False, message="every run failed")
    failed.iterator = "gp_smc"
    with pytest.raises(fbia.ConfigError, match=r"gp_smc result without a posterior \(failed\)"):
        fbia.iterator("levenberg_marquardt", x0=failed)


def test_a_study_file_chains_bayes_and_least_squares(study_file, tmp_path, capsys):
    study = study_file
    text = study.read_text()
    lm = 'name = "levenberg_marquardt"\noptions = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }'
    assert lm in text
    bayes = text.replace(lm, 'name = "gp_smc"\noptions = { n_train = 64, n_particles = 500 }')
    bayes = bayes.replace('output = "out"', 'output = "bayes"')
    # a likelihood 10x wider than the study's 0.5 um: the chain is tested, not the posterior;
    # at 0.5 um the sharp posterior took 1212 tempering steps (33 s alone)
    assert bayes.count("noise_std = 0.0005") == 2
    bayes = bayes.replace("noise_std = 0.0005", "noise_std = 0.005")
    (tmp_path / "bayes.toml").write_text(bayes)
    assert main(["run", "bayes.toml"]) == 0
    chained = text.replace(
        lm, 'name = "levenberg_marquardt"\noptions = { x0_from = "bayes/result.json" }'
    )
    (tmp_path / "lm.toml").write_text(chained)
    assert main(["run", "lm.toml"]) == 0
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["info"]["start_labels"] == ["posterior MAP", "posterior mean"]
    assert result["x"]["E"] == pytest.approx(400.0, rel=2e-2)
    capsys.readouterr()
    (tmp_path / "both.toml").write_text(
        text.replace(
            lm,
            'name = "levenberg_marquardt"\noptions = { x0 = { E = 350.0, nu = 0.2 }, '
            'x0_from = "bayes/result.json" }',
        )
    )
    assert main(["validate", "both.toml"]) == 2
    assert "give x0 or x0_from, not both" in capsys.readouterr().err
