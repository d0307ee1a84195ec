"""sigma_N as an inferred input of the posterior (issue 16, item 7): the profile likelihood,
the problem and study-file rules, and the marginal posterior against quadrature."""

import math

import numpy as np
import pytest
from _paths import ROOT

import fbia
from fbia.core.errors import ConfigError
from fbia.core.likelihood import (
    gaussian_log_likelihood,
    log_likelihood_from_profile,
    profile_log_likelihood,
    squared_distance,
)

TRUTH = {"E": 400.0, "nu": 0.3}
NOISE = 0.004  # mm, the synthetic data's noise
NOISE_PRIOR = fbia.priors.lognormal(math.log(0.01), 1.0)  # median 10 um, broad


def test_profile_is_eq_5_maximised_over_sigma_and_gives_eq_5_back():
    ev = fbia.Evaluation(index=0, x={}, residuals=np.zeros(40), distances=[0.05, 0.03])
    sigma = np.geomspace(1e-3, 1e-1, 4001)
    full = np.array([gaussian_log_likelihood(ev, [s]) for s in sigma])
    profile = profile_log_likelihood(ev)
    assert profile == pytest.approx(full.max(), abs=1e-4)  # the grid is 1e-3 apart
    assert profile >= full.max()  # the maximum itself, not a grid value below it
    for s in (0.002, 0.01, 0.05):
        exact = gaussian_log_likelihood(ev, [s])
        assert log_likelihood_from_profile(profile, 40, s) == pytest.approx(exact, rel=1e-12)
    failed = fbia.Evaluation(index=1, x={}, status="failed", message="boom")
    assert profile_log_likelihood(failed) == -math.inf
    assert squared_distance(ev) == (pytest.approx(0.05**2 + 0.03**2), 40)


def _problem(**extra):
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(
        model, {**TRUTH, "inflow_rate": 100.0}, [{}], noise_std=NOISE, seed=4
    )
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.8, 0.45)),
        ],
        fixed={"inflow_rate": 100.0},
        **extra,
    )


def test_a_noise_prior_needs_positive_support_and_excludes_a_known_sigma():
    with pytest.raises(ConfigError, match="positive support"):
        _problem(noise_prior=fbia.priors.normal(0.01, 0.01))
    with pytest.raises(ConfigError, match="not both"):
        _problem(noise_prior=NOISE_PRIOR, noise_std=0.01)


def test_study_file_noise_prior(tmp_path):
    text = """
[model]
name = "analytic_mound_2d"
[[parameters]]
name = "E"
bounds = [100.0, 800.0]
[synthetic]
truth = { E = 400.0, nu = 0.3 }
coordinates = [ { inflow_rate = 100.0 } ]
noise_std = 0.004
[measure]
name = "cpp"
[likelihood]
noise_prior = { distribution = "lognormal", mu_ln = -4.6, sigma_ln = 1.0 }
"""
    path = tmp_path / "study.toml"
    path.write_text(text)
    problem = fbia.load_study(path).problem
    assert problem.noise_prior is not None and problem.noise_prior.kind == "lognormal"
    assert problem.describe()["noise_prior"]["distribution"] == "lognormal"
    path.write_text(text.replace("[likelihood]\n", "[likelihood]\nnoise_std = 0.01\n"))
    with pytest.raises(ConfigError, match=r"\[likelihood\].*noise_prior.*not both"):
        fbia.load_study(path)
    path.write_text(text.replace('"lognormal", mu_ln', '"lognormal", mu'))
    with pytest.raises(ConfigError, match="noise_prior"):
        fbia.load_study(path)


@pytest.fixture(scope="module")
def exact():
    """The exact joint posterior of (E, nu, sigma_N) on a grid: forward runs on the (E, nu)
    grid, sigma_N in closed form (eq. 5 through S and n)."""
    problem = _problem(noise_prior=NOISE_PRIOR)
    e_grid = np.linspace(100.0, 800.0, 57)
    nu_grid = np.linspace(-0.8, 0.45, 51)
    s_grid = np.geomspace(5e-4, 0.05, 300)
    ee, nn = np.meshgrid(e_grid, nu_grid, indexing="ij")
    s_n = [
        squared_distance(problem.evaluate({"E": e, "nu": n}))
        for e, n in zip(ee.ravel(), nn.ravel(), strict=True)
    ]
    s = np.array([v[0] for v in s_n]).reshape(ee.shape)
    n = s_n[0][1]
    sig = s_grid[None, None, :]
    log_post = (
        -0.5 * n * np.log(2 * math.pi * sig**2)
        - s[..., None] / (2 * sig**2)
        + NOISE_PRIOR.logpdf(s_grid)[None, None, :]
        + np.log(np.gradient(s_grid))[None, None, :]  # the grid's cell widths in sigma
    )
    w = np.exp(np.where(np.isfinite(log_post), log_post - np.nanmax(log_post), -np.inf))
    w /= w.sum()
    grids = np.meshgrid(e_grid, nu_grid, s_grid, indexing="ij")
    mean = np.array([np.sum(w * g) for g in grids])
    std = np.sqrt(np.array([np.sum(w * (g - m) ** 2) for g, m in zip(grids, mean, strict=True)]))
    return problem, mean, std


def test_sigma_n_posterior_matches_quadrature(exact, tmp_path):
    problem, mean, std = exact
    result = fbia.iterator("gp_smc", n_train=60, n_particles=3000, n_rejuvenation=8, zeta=0.95).run(
        problem
    )
    assert result.status == "completed", result.message
    assert result.names == ["E", "nu", "sigma_N"] and result.nfev <= 70
    got_mean = result.posterior.mean_all
    got_std = np.sqrt(np.diag(result.posterior.cov_all))
    assert np.all(np.abs(got_mean - mean) < 0.3 * std), (got_mean, mean, std)
    assert np.all((got_std < 1.5 * std) & (got_std > std / 1.5)), (got_std, std)
    # the data's noise lies in the marginal's 95 % interval, which the message reports
    lo, _, hi = result.posterior.credible_intervals["sigma_N"]
    assert lo < NOISE < hi
    assert "sigma_N = " in result.message and "inferred" in result.message
    # its marginal is drawn beside the parameters'
    from fbia.iterators.gp_smc.iterator import GpSmcIterator

    (path,) = GpSmcIterator.write_plots(result, problem, tmp_path, figures=["marginals_1d"])
    assert path.name == "marginals_1d.png" and path.stat().st_size > 10_000


@pytest.mark.slow
def test_the_example_study_infers_sigma_n(tmp_path):
    """The example study file end to end (a verification run of ~40 s, so in make test-slow):
    in make test, test_study_file_noise_prior reads the same [likelihood] noise_prior, and
    test_sigma_n_posterior_matches_quadrature runs the same problem through gp_smc and checks
    sigma_N's interval and marginal plot more strictly, against quadrature."""
    example = ROOT / "examples" / "flow_cell" / "study_noise.toml"
    result = fbia.run_study(fbia.load_study(example), tmp_path / "out", echo=lambda s: None)
    assert result.status == "completed" and result.names == ["E", "nu", "sigma_N"]
    lo, _, hi = result.posterior.credible_intervals["sigma_N"]
    assert lo < NOISE < hi
    assert (tmp_path / "out" / "plots" / "marginals_1d.png").exists()
