"""Failed forward runs in gp_smc (issue 17, example 8): the GP classifier of where the model
runs, and a posterior cut by a failing region against quadrature."""

import numpy as np
import pytest
from test_gp_smc import _problem

import fbia
from fbia.core.likelihood import gaussian_log_likelihood, measurement_count, noise_levels
from fbia.iterators.surrogates.feasibility import Feasibility, fit_feasibility
from fbia.iterators.surrogates.residuals import restore_surrogate

# the model fails for E below this (a soft biofilm, Paper B Figs. 5-8), where the
# unconstrained posterior would still hold mass (truth E = 400 Pa)
FAIL_BELOW = 390.0


# -- the classifier ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def classifier():
    rng = np.random.default_rng(0)
    x = rng.random((300, 3)) * [700.0, 1.3, 1.0] + [100.0, -0.8, 0.0]
    ok = x[:, 0] + 200.0 * x[:, 1] > 300.0  # a slanted boundary in (E, nu)
    return x, ok, Feasibility.fit(x, ok)


def test_factor_is_one_where_the_model_runs_and_vanishes_where_it_fails(classifier):
    _, _, f = classifier
    rng = np.random.default_rng(1)
    z = rng.random((4000, 3)) * [700.0, 1.3, 1.0] + [100.0, -0.8, 0.0]
    margin = z[:, 0] + 200.0 * z[:, 1] - 300.0
    log_c = f.log_factor(z)
    assert np.all(log_c <= 0.0)
    runs, fails = margin > 60.0, margin < -60.0  # a few design spacings from the boundary
    assert np.mean(log_c[runs] > -0.01) > 0.99
    assert np.mean(log_c[fails] < -2.0) > 0.9  # the factor e^-2 or less


def test_latent_mean_is_gpy_s_and_the_state_round_trips(classifier):
    import GPy

    x, ok, f = classifier
    z = np.random.default_rng(2).random((50, 3)) * [700.0, 1.3, 1.0] + [100.0, -0.8, 0.0]
    # GPy's own prediction from the same fit (fewer than MAX_POINTS runs: all are used)
    kernel = GPy.kern.Matern52(3, ARD=True, lengthscale=0.2)
    model = GPy.models.GPClassification(f.x, ok[:, None].astype(float), kernel)
    model.optimize(max_iters=200)
    mean, _ = model._raw_predict((z - f.lower) / (f.upper - f.lower))
    # (two fits agree to the optimiser's tolerance, not to the bit)
    np.testing.assert_allclose(f.latent_mean(z), mean[:, 0], rtol=1e-3, atol=1e-3)
    again = Feasibility.from_state(f.state())
    np.testing.assert_array_equal(again.log_factor(z), f.log_factor(z))


def test_no_classifier_without_both_outcomes():
    x = np.random.default_rng(0).random((20, 2))
    assert fit_feasibility(x, np.ones(20, dtype=bool)) is None
    assert fit_feasibility(x, np.zeros(20, dtype=bool)) is None
    with pytest.raises(ValueError, match="failed and successful"):
        Feasibility.fit(x, np.ones(20, dtype=bool))


def test_subset_keeps_every_failure_and_the_boundary():
    rng = np.random.default_rng(3)
    x = rng.random((1500, 2))
    ok = x[:, 0] > 0.2
    f = Feasibility.fit(x, ok, max_points=200)
    assert len(f.x) == 200 and f.n_runs == 1500 and f.n_failed == int((~ok).sum())
    # half are failures, the rest the successful runs nearest to them
    kept = f.x[:, 0] * (x[:, 0].max() - x[:, 0].min()) + x[:, 0].min()
    assert np.sum(kept <= 0.2) == 100 and kept.max() < 0.35


# -- a posterior cut by the failing region ------------------------------------------------------
@pytest.fixture(scope="module")
def exact_cut():
    """The exact posterior by quadrature on a grid of forward runs, zero where the model fails
    (uniform priors: posterior ~ exp(L) on E >= 390 Pa)."""
    problem = _problem(failure_region={"E": (100.0, FAIL_BELOW)})
    sig, count = noise_levels(problem), measurement_count(problem)
    ee, nn = np.meshgrid(np.linspace(100.0, 800.0, 71), np.linspace(-0.8, 0.5, 66), indexing="ij")

    def loglik(e, n):
        try:
            return gaussian_log_likelihood(problem.evaluate({"E": e, "nu": n}), sig, count)
        except fbia.ForwardModelError:
            return -np.inf

    ll = np.array([loglik(e, n) for e, n in zip(ee.ravel(), nn.ravel(), strict=True)])
    w = np.exp(ll - ll[np.isfinite(ll)].max()).reshape(ee.shape)
    w /= w.sum()
    mean = np.array([np.sum(w * ee), np.sum(w * nn)])
    std = np.sqrt([np.sum(w * (ee - mean[0]) ** 2), np.sum(w * (nn - mean[1]) ** 2)])
    return problem, mean, std


SOBOL = {"design": "sobol", "n_train": 128, "n_particles": 3000, "n_rejuvenation": 8}


def test_classified_failures_keep_the_posterior_where_the_model_runs(exact_cut):
    problem, mean, std = exact_cut
    result = fbia.iterator("gp_smc", zeta=0.95, **SOBOL).run(problem)
    assert result.status == "completed" and result.check.n_failed <= 1
    assert "keeps the posterior where the forward model runs" in result.message
    design = result.design
    assert result.surrogate.summary["feasibility_n_failed"] == int((~design.ok[:128]).sum()) > 0
    # measured: 0.21 and 0.14 std (the mass the GP would put at E < 390 Pa is gone)
    assert np.all(np.abs(result.posterior.mean - mean) < 0.3 * std)
    got = np.sqrt(np.diag(result.posterior.cov))
    assert np.all((got < 1.25 * std) & (got > std / 1.25))
    # a restored result carries the classifier: E = 200 Pa is excluded
    restored = restore_surrogate(result.surrogate.state)
    assert restored.log_feasibility(np.array([[200.0, 0.3]]))[0] < -2.0


def test_ignored_failures_leave_mass_where_the_model_fails(exact_cut):
    """Paper B's procedure: the GP of L interpolates across the failing region, the posterior
    leaks into it (measured: E 0.41 std low, 4 of 8 check draws failed) and the check says so."""
    problem, mean, _ = exact_cut
    result = fbia.iterator("gp_smc", zeta=0.95, failures="ignore", **SOBOL).run(problem)
    assert result.posterior.mean[0] < mean[0]
    assert result.check.n_failed >= 3 and result.status == "unreliable"
    assert "posterior holds mass where the model produces no state" in result.message
