"""Adaptive tempered SMC (Paper B, Algorithm 1) against closed forms and quadrature."""

import math

import numpy as np
import pytest
from scipy import stats

import fbia
from fbia.iterators.smc.sampler import SequentialMonteCarlo, ess, systematic_resample
from fbia.iterators.smc.tempering import EssTempering, default_max_steps

N = 2000


@pytest.fixture(scope="module", params=["every_step", "after_resampling"])
def linear_gaussian(request):
    """y = A x + e, e ~ N(0, sigma^2 I), independent normal priors: everything is exact."""
    rng = np.random.default_rng(0)
    d, m, sigma = 3, 6, 0.3
    a = rng.normal(size=(m, d))
    m0, s0 = np.array([0.5, -0.2, 0.1]), np.array([1.0, 0.7, 1.5])
    y = a @ np.array([0.8, -0.5, 0.3]) + sigma * rng.normal(size=m)
    cov0 = np.diag(s0**2)
    cov = np.linalg.inv(np.linalg.inv(cov0) + a.T @ a / sigma**2)
    mean = cov @ (np.linalg.solve(cov0, m0) + a.T @ y / sigma**2)
    log_z = stats.multivariate_normal(a @ m0, a @ cov0 @ a.T + sigma**2 * np.eye(m)).logpdf(y)

    def log_likelihood(x):  # eq. 5 with n = m individual measurements
        r = y - x @ a.T
        return -0.5 * np.sum(r**2, axis=1) / sigma**2 - 0.5 * m * math.log(2 * math.pi * sigma**2)

    priors = [fbia.priors.normal(mu, s) for mu, s in zip(m0, s0, strict=True)]
    post = fbia.smc(
        log_likelihood, priors, n_particles=N, n_rejuvenation=5, seed=3, rejuvenate=request.param
    )
    return post, mean, cov, log_z


def test_linear_gaussian_mean_within_monte_carlo_error(linear_gaussian):
    post, mean, cov, _ = linear_gaussian
    sd = np.sqrt(np.diag(cov))
    # MC standard error of a weighted mean with ESS ~ N; 1.5 allows for MCMC correlation.
    np.testing.assert_array_less(np.abs(post.mean - mean), 4 * 1.5 * sd / math.sqrt(N))


def test_linear_gaussian_covariance_matches_exact(linear_gaussian):
    post, _, cov, _ = linear_gaussian
    np.testing.assert_allclose(np.diag(post.cov), np.diag(cov), rtol=0.1)
    corr = post.cov / np.sqrt(np.outer(np.diag(post.cov), np.diag(post.cov)))
    exact = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(corr, exact, atol=0.06)


def test_linear_gaussian_log_evidence_within_its_error(linear_gaussian):
    post, _, _, log_z = linear_gaussian
    assert 0 < post.log_evidence_se < 0.05
    assert abs(post.log_evidence - log_z) < 4 * post.log_evidence_se


def test_resample_move_moves_only_when_resampling_and_at_the_end(linear_gaussian):
    post = linear_gaussian[0]
    moved = [h["moved"] for h in post.history]
    resampled = [h["resampled"] for h in post.history]
    assert moved[-1]
    if all(moved):  # Algorithm 1: every step moves; N evaluations per MH step and step
        assert post.nfev == N * (1 + 5 * post.n_steps)
    else:
        assert any(resampled)
        assert moved == [r or i == len(moved) - 1 for i, r in enumerate(resampled)]
        assert post.nfev == N * (1 + 5 * sum(moved)) < N * (1 + 5 * post.n_steps) / 3


def _quadrature_moments(log_density, box, n=801):
    grids = [np.linspace(lo, hi, n) for lo, hi in box]
    mesh = np.meshgrid(*grids, indexing="ij")
    pts = np.column_stack([g.ravel() for g in mesh])
    lw = log_density(pts)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    mean = w @ pts
    dx = pts - mean
    return pts, w, mean, (dx * w[:, None]).T @ dx


def _banana(x):
    return -0.5 * (x[:, 0] ** 2 + (x[:, 1] - x[:, 0] ** 2) ** 2 / 0.3**2)


def _bimodal(x):
    a = -0.5 * np.sum((x - [-2.0, -1.5]) ** 2, axis=1) / 0.5**2 + math.log(0.3 / 0.5**2)
    b = -0.5 * np.sum((x - [2.0, 1.0]) ** 2, axis=1) / 0.7**2 + math.log(0.7 / 0.7**2)
    return np.logaddexp(a, b)


def test_banana_moments_match_quadrature():
    box = [(-3.0, 3.0), (-2.0, 7.0)]
    _, _, mean, cov = _quadrature_moments(_banana, box)
    priors = [fbia.priors.uniform(*b) for b in box]
    post = fbia.smc(_banana, priors, n_particles=N, n_rejuvenation=5, seed=1)
    sd = np.sqrt(np.diag(cov))
    np.testing.assert_array_less(np.abs(post.mean - mean), 0.1 * sd)
    np.testing.assert_allclose(np.diag(post.cov), np.diag(cov), rtol=0.1)
    # The banana is symmetric in x1: no linear correlation although x2 depends on x1^2.
    assert abs(post.cov[0, 1]) / (sd[0] * sd[1]) < 0.06
    # The curved ridge: E[x2] = E[x1^2] holds for the particles too.
    np.testing.assert_allclose(post.weights @ post.particles[:, 0] ** 2, mean[1], rtol=0.1)
    # Prior support respected: no particle outside the uniform box.
    assert np.all(post.particles >= [b[0] for b in box])
    assert np.all(post.particles <= [b[1] for b in box])


def test_bimodal_both_modes_found_with_their_mass():
    box = [(-5.0, 5.0), (-5.0, 5.0)]
    pts, w, mean, cov = _quadrature_moments(_bimodal, box)
    mass_left = w[pts.sum(axis=1) < 0].sum()
    assert mass_left == pytest.approx(0.3, abs=0.01)
    priors = [fbia.priors.uniform(*b) for b in box]
    post = fbia.smc(_bimodal, priors, n_particles=N, n_rejuvenation=5, seed=2)
    left = post.particles.sum(axis=1) < 0
    assert post.weights[left].sum() == pytest.approx(mass_left, abs=0.05)
    # Each mode is populated around its centre.
    np.testing.assert_allclose(
        post.weights[left] @ post.particles[left] / post.weights[left].sum(), [-2, -1.5], atol=0.1
    )
    np.testing.assert_allclose(
        post.weights[~left] @ post.particles[~left] / post.weights[~left].sum(), [2, 1], atol=0.1
    )
    np.testing.assert_array_less(np.abs(post.mean - mean), 0.1 * np.sqrt(np.diag(cov)))
    np.testing.assert_allclose(np.diag(post.cov), np.diag(cov), rtol=0.1)


def test_tempering_keeps_ess_ratio_zeta_and_ends_at_one():
    priors = [fbia.priors.uniform(-3.0, 3.0)] * 2
    sampler = SequentialMonteCarlo(_banana, priors, n_particles=500, zeta=0.9, seed=0)
    gen = sampler.steps()
    states = []
    while True:
        try:
            states.append(next(gen))
        except StopIteration as stop:
            post = stop.value
            break
    gammas = [s.gamma for s in states]
    assert gammas[-1] == 1.0 and np.all(np.diff(gammas) > 0)
    assert post.gammas == [0.0, *gammas]
    # Steps that did not resample: ESS_s = zeta ESS_{s-1} (eq. 14, Algorithm 1), but for the
    # last one, which goes to gamma = 1 and may lose less.
    ess_hist = post.ess
    for s in range(1, len(ess_hist) - 1):
        prev = 500.0 if post.history[s - 2]["resampled"] or s == 1 else ess_hist[s - 1]
        assert ess_hist[s] == pytest.approx(0.9 * prev, rel=1e-6)
    assert all(0.0 < a <= 1.0 for a in post.acceptance)
    assert post.weights.sum() == pytest.approx(1.0)
    # nfev counts the prior draws plus the in-support proposals of every rejuvenation step.
    assert 500 < post.nfev <= 500 * (1 + 10 * post.n_steps)


def test_same_seed_same_result_and_map_is_best_particle():
    priors = [fbia.priors.normal(0.0, 2.0)] * 2
    a = fbia.smc(_banana, priors, n_particles=300, n_rejuvenation=3, seed=11)
    b = fbia.smc(_banana, priors, n_particles=300, n_rejuvenation=3, seed=11)
    np.testing.assert_array_equal(a.particles, b.particles)
    assert a.log_evidence == b.log_evidence
    i = np.argmax(a.log_likelihood + a.log_prior)
    np.testing.assert_array_equal(a.map, a.particles[i])


def test_constant_likelihood_is_one_step_to_the_prior():
    priors = [fbia.priors.normal(1.0, 2.0)]
    post = fbia.smc(lambda x: np.zeros(len(x)), priors, n_particles=4000, seed=5)
    assert post.n_steps == 1 and post.log_evidence == pytest.approx(0.0, abs=1e-12)
    assert post.mean[0] == pytest.approx(1.0, abs=4 * 2.0 / math.sqrt(4000) * 1.5)


def test_ess_and_systematic_resampling():
    assert ess(np.log(np.full(10, 0.1))) == pytest.approx(10.0)
    assert ess(np.array([0.0, -np.inf, -np.inf])) == pytest.approx(1.0)
    w = np.array([0.5, 0.25, 0.125, 0.125])
    counts = np.bincount(systematic_resample(w, np.random.default_rng(0)), minlength=4)
    np.testing.assert_array_equal(counts, [2, 1, 0, 1] if counts[2] == 0 else [2, 1, 1, 0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"zeta": 1.0}, r"^smc: zeta must lie in \(0, 1\), got 1.0$"),
        ({"n_particles": 1}, r"^smc: n_particles must be at least 2, got 1$"),
        ({"ess_min": 2.0}, r"^smc: ess_min is a fraction of N in \[0, 1\], got 2.0$"),
    ],
)
def test_bad_arguments_are_config_errors(kwargs, message):
    with pytest.raises(fbia.ConfigError, match=message):
        fbia.smc(_banana, [fbia.priors.uniform(0, 1)] * 2, **kwargs)


def test_wrong_output_shape_is_a_config_error():
    with pytest.raises(fbia.ConfigError, match=r"returned shape \(10, 1\) for 10 points"):
        fbia.smc(lambda x: x[:, :1], [fbia.priors.uniform(0, 1)] * 2, n_particles=10)


def test_fbia_smc_is_the_standalone_sampler():
    from fbia.iterators.smc import sampler as smc_module

    assert fbia.smc is smc_module.smc
    assert "gp_smc" in {e.name for e in fbia.list_plugins("iterator")}


def test_a_likelihood_below_minus_700_everywhere_does_not_underflow_the_weights():
    """Issue 14, defect 1: L = -800 - 1000 (x - 0.3)^2 on U(0, 1).  The posterior is
    N(0.3, 1/2000) (the box cuts nothing), the evidence exp(-800) sqrt(pi/1000)."""
    post = fbia.smc(
        lambda x: -800.0 - 1e3 * (x[:, 0] - 0.3) ** 2,
        [fbia.priors.uniform(0.0, 1.0)],
        n_particles=400,
        seed=0,
    )
    mean = post.weights @ post.particles[:, 0]
    std = np.sqrt(post.weights @ (post.particles[:, 0] - mean) ** 2)
    exact_std = np.sqrt(1 / 2000)
    assert abs(mean - 0.3) < 4 * exact_std / np.sqrt(100)
    assert std == pytest.approx(exact_std, rel=0.25)
    exact_log_z = -800.0 + 0.5 * np.log(np.pi / 1000.0)
    assert abs(post.log_evidence - exact_log_z) < 4 * post.log_evidence_se + 0.05


def test_a_stalled_tempering_says_why_and_what_to_change():
    """Issue 16, item 4: a sharp likelihood with zeta close to 1 cannot reach gamma = 1 in a
    few steps; the error names the cycle length, the likelihood's spread and the remedies."""
    prior = fbia.priors.uniform(0.0, 1.0)
    with pytest.raises(fbia.ConfigError) as err:
        fbia.smc(
            lambda x: -1e4 * (x[:, 0] - 0.3) ** 2,
            [prior],
            n_particles=200,
            zeta=0.998,
            n_rejuvenation=1,
            max_steps=20,
            seed=0,
        )
    text = str(err.value)
    assert "no convergence to gamma = 1 in 20 tempering steps" in text
    assert "one resampling cycle takes about 346 steps" in text
    assert "lower zeta" in text and "spans" in text
    assert "fewer than two resamplings" in text


def _stall(training_range, **kwargs):
    with pytest.raises(fbia.ConfigError) as err:
        fbia.smc(
            lambda x: -1e4 * (x[:, 0] - 0.3) ** 2,
            [fbia.priors.uniform(0.0, 1.0)],
            n_particles=200,
            n_rejuvenation=2,
            seed=0,
            training_range=training_range,
            **kwargs,
        )
    return str(err.value)


def test_a_stall_says_how_fast_gamma_grows_and_whether_a_surrogate_extrapolates():
    """Issue 16, item 4: with the training range of a surrogate, the error says whether the
    particles' L lies beyond its largest value + chi2_1(0.999) / 2 = 5.41, and from the
    growth of gamma per resampling cycle how many steps gamma = 1 would need."""
    text = _stall((-1e4, -30.0), zeta=0.9, max_steps=16)
    assert "gamma grew by a factor" in text and "max_steps of at least" in text
    assert "above the largest training value, far beyond the margin 5.41" in text
    assert "That is the surrogate extrapolating" in text
    text = _stall((-1e4, 0.0), zeta=0.9, max_steps=16)
    assert "trained on log-likelihoods in [-1e+04, 0]" in text and "no extrapolation" in text
    with pytest.raises(fbia.ConfigError, match=r"training_range must be \(min, max\)"):
        fbia.smc(_banana, [fbia.priors.uniform(0, 1)] * 2, training_range=(1.0, 0.0))


def test_the_default_step_limit_scales_with_zeta():
    """100 halvings of the ESS (at least 1000 steps): the paper's zeta = 0.998 is not cut off
    at a fixed 5000 or 10 000 steps."""
    assert default_max_steps(0.998) == 34_623
    assert default_max_steps(0.995) == 13_829
    assert default_max_steps(0.9) == 1000
    priors = [fbia.priors.uniform(0, 1)]
    assert SequentialMonteCarlo(_banana, priors, zeta=0.998).max_steps == 34_623
    assert SequentialMonteCarlo(_banana, priors, zeta=0.998, max_steps=50).max_steps == 50


def _brent_gamma(gamma, log_w, loglik, zeta):
    """The previous implementation of the tempering rule (Brent's method on the ESS)."""
    from scipy.optimize import brentq

    target = zeta * ess(log_w)
    finite = np.isfinite(loglik)
    lw, ll = log_w[finite], loglik[finite]

    def excess(g):
        z = lw + (g - gamma) * ll
        w = np.exp(z - z.max())
        return w.sum() ** 2 / np.dot(w, w) - target

    if excess(1.0) >= 0.0:
        return 1.0
    if excess(gamma) < 0.0:
        return float(np.nextafter(gamma, 2.0))
    return brentq(excess, gamma, 1.0, xtol=1e-14, rtol=1e-10)


@pytest.mark.parametrize("case", ["equal", "unequal", "minus_inf", "to_one"])
def test_newton_on_log_ess_finds_the_same_gamma_as_brent(case):
    rng = np.random.default_rng(7)
    n = 5000
    loglik = -0.5 * rng.chisquare(5, size=n) * 1e3
    log_w = np.full(n, -math.log(n))
    gamma, zeta = 0.0, 0.998
    if case == "unequal":  # weights not a function of L (after moves in Algorithm 1)
        log_w = rng.normal(size=n)
        gamma = 0.3
    if case == "minus_inf":
        loglik[rng.random(n) < 0.001] = -np.inf
    if case == "to_one":
        loglik *= 1e-6
    tempering = EssTempering(zeta, n)
    for _ in range(5):  # a few steps: the later ones start from the previous increments
        g = tempering.next_gamma(gamma, log_w, loglik, ess(log_w))
        assert g == pytest.approx(_brent_gamma(gamma, log_w, loglik, zeta), rel=1e-9, abs=0)
        assert g > gamma
        log_w = log_w + np.where(np.isfinite(loglik), (g - gamma) * loglik, -np.inf)
        log_w -= np.logaddexp.reduce(log_w)
        gamma = g
        if gamma >= 1.0:
            break
    assert (gamma == 1.0) == (case == "to_one")
    assert tempering.evaluations <= (12 if case == "unequal" else 16)


def test_a_sharp_posterior_needs_thousands_of_steps_and_is_still_exact():
    """The paper's zeta = 0.998 on a posterior 10^4 times narrower than its prior in 3-D:
    about 7000 tempering steps, more than the old fixed limit of 5000 (gp_smc) allowed.
    Conjugate: posterior N(y / (1 + s^2), s^2 / (1 + s^2)) per direction, evidence closed."""
    s, y = 1e-4, np.array([0.3, -1.2, 2.0])
    post = fbia.smc(
        lambda x: -0.5 * np.sum((x - y) ** 2, axis=1) / s**2 - 1.5 * math.log(2 * math.pi * s**2),
        [fbia.priors.normal(0.0, 1.0)] * 3,
        n_particles=1000,
        zeta=0.998,
        n_rejuvenation=5,
        seed=4,
        rejuvenate="after_resampling",
    )
    assert 5000 < post.n_steps < 20_000 and post.gammas[-1] == 1.0
    mean, sd = y / (1 + s**2), s / math.sqrt(1 + s**2)
    np.testing.assert_array_less(np.abs(post.mean - mean), 4 * 1.5 * sd / math.sqrt(1000))
    np.testing.assert_allclose(np.sqrt(np.diag(post.cov)), sd, rtol=0.15)
    log_z = float(np.sum(stats.norm(0.0, math.sqrt(1 + s**2)).logpdf(y)))
    assert abs(post.log_evidence - log_z) < 4 * post.log_evidence_se + 0.05


def test_keep_gamma_gives_the_tempered_posterior_on_the_way():
    """A step ends exactly at keep_gamma, and its particles are draws of exp(gamma L) p: for
    L = -x^2 / (2 s^2) under a wide uniform prior that is N(0, s^2 / gamma)."""
    from fbia.iterators.smc.sampler import SequentialMonteCarlo

    s = 0.05
    sampler = SequentialMonteCarlo(
        lambda z: -0.5 * (z[:, 0] / s) ** 2,
        [fbia.priors.uniform(-1.0, 1.0)],
        n_particles=4000,
        zeta=0.9,
        n_rejuvenation=5,
        seed=3,
        keep_gamma=0.25,
    )
    post = sampler.run()
    assert post.tempered is not None and 0.25 in post.gammas
    assert post.tempered.gammas[-1] == 0.25
    tempered_std = float(np.sqrt(post.tempered.cov[0, 0]))
    assert tempered_std == pytest.approx(s / 0.5, rel=0.1)  # s / sqrt(gamma) = 0.1
    assert float(np.sqrt(post.cov[0, 0])) == pytest.approx(s, rel=0.1)
    with pytest.raises(fbia.ConfigError, match="keep_gamma"):
        SequentialMonteCarlo(lambda z: z[:, 0], [fbia.priors.uniform(0, 1)], keep_gamma=1.0)
