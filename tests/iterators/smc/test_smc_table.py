"""Tabulated log-densities for Algorithm 1 (fbia.iterators.smc.table): the spline is scipy's,
it converges at order 4, the sampler on the table gives the exact posterior, and a run is the
same on one thread and on two."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from scipy.ndimage import map_coordinates

import fbia
from fbia.iterators.smc.sampler import SequentialMonteCarlo
from fbia.iterators.smc.table import LogTables, tabulable

PRIORS = [fbia.priors.uniform(50.0, 1000.0), fbia.priors.uniform(-0.8, 0.5)]


def smooth(x):
    """A smooth log-likelihood of the size of Paper B's (tens of units over the box)."""
    return 20.0 * np.sin(x[:, 0] / 150.0) * np.cos(3.0 * x[:, 1]) - 1e-4 * (x[:, 0] - 400) ** 2


def test_the_spline_is_scipys_cubic_b_spline():
    table = LogTables.build(smooth, PRIORS, 65)
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.uniform(50, 1000, 2000), rng.uniform(-0.8, 0.5, 2000)])
    u = (x - table.grid_lower) * table.inv_step
    scipy = map_coordinates(table.coeffs, u.T, order=3, mode="mirror", prefilter=False)
    ours = table.log_likelihood(x)
    np.testing.assert_allclose(ours, scipy, rtol=0, atol=1e-10 * np.abs(scipy).max())
    # on the grid the spline interpolates L itself
    on_grid = np.array([[50.0, -0.8], [1000.0, 0.5], [50.0 + 950.0 / 64 * 17, 0.5]])
    np.testing.assert_allclose(table.log_likelihood(on_grid), smooth(on_grid), atol=1e-9)
    # outside the prior's box: -inf, as the prior
    assert np.all(table.log_likelihood(np.array([[49.0, 0.0], [400.0, 0.51]])) == -np.inf)


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_the_interpolation_error_falls_at_order_four(dim):
    priors = [fbia.priors.uniform(0.0, 3.0)] * dim

    def f(x):
        return np.sin(np.sum(x, axis=1)) * np.exp(0.3 * x[:, 0])

    rng = np.random.default_rng(1)
    # the middle of the box: near its edges the coefficients' boundary condition leaves an
    # O(h^2) error damped by 0.268 per cell of padding (4e-4 at the box), measured by check()
    x = rng.uniform(0.75, 2.25, (4000, dim))
    errors = [LogTables.build(f, priors, n).check(f, x)["max_abs_error"] for n in (17, 33)]
    rate = np.log2(errors[0] / errors[1])  # 33 points halve the spacing of 17
    assert rate > 3.5, errors


def test_log_priors_are_tabulated_within_their_grid_error():
    priors = [
        fbia.priors.lognormal(5.86, 0.4).truncated(50.0, 1000.0),
        fbia.priors.beta(43 / 13, 22 / 13, lower=-0.8, upper=0.5),
    ]
    table = LogTables.build(smooth, priors, 33)
    rng = np.random.default_rng(2)
    x = np.column_stack([rng.uniform(50, 1000, 3000), rng.uniform(-0.79, 0.49, 3000)])
    exact = priors[0].logpdf(x[:, 0]) + priors[1].logpdf(x[:, 1])
    # linear interpolation on 8193 points: h^2/8 |(log p)''| < 1e-4 for these priors
    np.testing.assert_allclose(table.log_prior(x), exact, rtol=0, atol=1e-4)


def gaussian(mean, cov):
    inv = np.linalg.inv(cov)

    def log_likelihood(x):
        d = x - mean
        return -0.5 * np.einsum("ij,jk,ik->i", d, inv, d)

    return log_likelihood


def test_the_sampler_on_the_table_gives_the_exact_posterior():
    """A correlated Gaussian far inside a uniform box: the posterior is that Gaussian."""
    mean = np.array([420.0, 0.2])
    cov = np.array([[15.0**2, 0.8 * 15.0 * 0.05], [0.8 * 15.0 * 0.05, 0.05**2]])
    f = gaussian(mean, cov)
    s = SequentialMonteCarlo(
        f, PRIORS, n_particles=4000, zeta=0.9, n_rejuvenation=10, seed=3, table_points=513
    )
    post = s.run()
    std = np.sqrt(np.diag(cov))
    assert np.all(np.abs(post.mean - mean) < 0.1 * std)  # MC error ~ 0.02 std
    np.testing.assert_allclose(np.sqrt(np.diag(post.cov)), std, rtol=0.06)
    assert post.table is not None and post.table["max_abs_error"] < 1e-3
    assert post.table["points_per_input"] == 513 and post.table["n_checked"] > 500
    # the evidence: log of the Gaussian's integral over the uniform prior's density
    exact = np.log(2 * np.pi * np.sqrt(np.linalg.det(cov)) / (950.0 * 1.3))
    assert abs(post.log_evidence - exact) < 3 * post.log_evidence_se


def test_a_run_is_the_same_on_one_thread_and_on_two():
    f = gaussian(np.array([420.0, 0.2]), np.diag([20.0**2, 0.1**2]))
    runs = []
    threads = numba.get_num_threads()
    try:
        for n in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(n)
            s = SequentialMonteCarlo(
                f, PRIORS, n_particles=500, zeta=0.8, n_rejuvenation=5, seed=4, table_points=129
            )
            runs.append(s.run())
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(runs[0].particles, runs[1].particles)
    assert runs[0].gammas == runs[1].gammas


def test_what_a_table_cannot_serve_is_said_and_sampled_directly():
    assert tabulable(PRIORS) is None
    assert "4 inputs" in str(tabulable(PRIORS * 2))
    assert "unbounded" in str(tabulable([fbia.priors.normal(0.0, 1.0)]))
    s = SequentialMonteCarlo(
        gaussian(np.zeros(1), np.eye(1)),
        [fbia.priors.normal(0.0, 3.0)],
        n_particles=500,
        zeta=0.8,
        n_rejuvenation=5,
        seed=5,
        table_points=129,
    )
    post = s.run()
    assert post.table == {"note": "no table: the normal prior has an unbounded support (-inf, inf)"}
    assert abs(post.mean[0]) < 0.2
