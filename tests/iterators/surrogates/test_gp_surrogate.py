"""GP surrogate of the log-likelihood (Paper B eq. 26-29, Remarks 9-10)."""

import numpy as np
import pytest
from scipy.stats import qmc

import fbia
from fbia.iterators.surrogates.gp import GpSurrogate, matern32_cross


def _log_lik(x):
    """A smooth, curved log-likelihood on [0, 1]^2 (peak 0 at (0.4, 0.6))."""
    return -((x[:, 0] - 0.4) ** 2 / 0.08 + (x[:, 1] - 0.6 - 0.5 * (x[:, 0] - 0.4) ** 2) ** 2 / 0.03)


@pytest.fixture(scope="module", params=[False, True], ids=["single", "ard"])
def trained(request):
    x = qmc.Sobol(2, scramble=True, seed=4).random(64)
    gp = GpSurrogate(ard=request.param, restarts=2).fit(x, _log_lik(x), rng=0)
    return gp, x


def test_recovers_a_known_smooth_function(trained):
    gp, _ = trained
    x_test = qmc.Sobol(2, scramble=True, seed=4).random(128)[64:]  # the next Sobol points
    y_test = _log_lik(x_test)
    err = gp.test_error(x_test, y_test)
    # 64 training points: the error is a few per cent of the spread of L.
    assert err["test_max_abs"] < 0.05 * (y_test.max() - y_test.min())
    assert err["test_relative_l2"] < 0.03
    # Its maximum is where the function's maximum is.
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 101), np.linspace(0, 1, 101)), -1).reshape(-1, 2)
    np.testing.assert_allclose(grid[np.argmax(gp.predict_mean(grid))], [0.4, 0.6], atol=0.021)


def test_fast_mean_equals_gpy_predict(trained):
    gp, _ = trained
    x = np.random.default_rng(1).uniform(-0.5, 1.5, size=(3000, 2))  # also far outside
    mean_gpy, var = gp.predict(x)
    np.testing.assert_allclose(gp.predict_mean(x), mean_gpy, rtol=0, atol=1e-8)
    assert np.all(var >= 0)


def test_prior_mean_nugget_and_falloff_follow_remark_10(trained):
    gp, x = trained
    y = _log_lik(x)
    span = y.max() - y.min()
    assert gp.mean_value == pytest.approx(y.min() - 1.0 * span)
    assert gp.nugget == pytest.approx(1e-5 * span)
    # Far from the data the surrogate falls to the prior mean, below every training value.
    far = gp.predict_mean(np.array([[1e4, -1e4]]))[0]
    assert far == pytest.approx(gp.mean_value, abs=1e-6 * span)
    # The training data are interpolated up to the nugget.
    np.testing.assert_allclose(gp.predict_mean(x), y, atol=1e-3 * span)


def test_closed_form_leave_one_out_equals_refitting(trained):
    gp, x = trained
    y = _log_lik(x)
    loo = gp.loo()
    # Brute force with the same hyperparameters: condition the GP on all points but one.
    hp = gp.hyperparameters()
    xs = (x - gp.x_mean) / gp.x_std
    kern = matern32_cross(xs, xs, np.array(hp["lengthscales"]), hp["signal_variance"], gp.ard)
    kern += gp.nugget * np.eye(len(x))
    res = []
    for i in range(len(x)):
        keep = np.arange(len(x)) != i
        alpha = np.linalg.solve(kern[np.ix_(keep, keep)], y[keep] - gp.mean_value)
        res.append(gp.mean_value + kern[i, keep] @ alpha - y[i])
    res = np.array(res)
    # (K + sigma_n^2 I) has a condition number ~1e9 with the tiny nugget: agree to 1e-3.
    assert loo["loo_rmse"] == pytest.approx(np.sqrt(np.mean(res**2)), rel=1e-3)
    assert loo["loo_max_abs"] == pytest.approx(np.abs(res).max(), rel=1e-3)


def test_matern32_kernel_is_eq_27_and_the_product_of_1d_kernels():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(4, 3))
    ell = np.array([0.7, 1.3, 2.0])
    r = np.linalg.norm(a[:, None] - b[None], axis=-1) / 0.7
    eq27 = 2.5 * (1 + np.sqrt(3) * r) * np.exp(-np.sqrt(3) * r)
    np.testing.assert_allclose(matern32_cross(a, b, ell[:1], 2.5, product=False), eq27)
    rj = np.abs(a[:, None] - b[None]) / ell
    prod = 2.5 * np.prod((1 + np.sqrt(3) * rj) * np.exp(-np.sqrt(3) * rj), axis=-1)
    np.testing.assert_allclose(matern32_cross(a, b, ell, 2.5, product=True), prod)


def test_scg_optimizer_and_gpy_default_training_run():
    x = qmc.Sobol(2, scramble=True, seed=5).random(32)
    y = _log_lik(x)
    scg = GpSurrogate(ard=True, optimizer="scg", restarts=0).fit(x, y, rng=0)
    default = GpSurrogate(gpy_default=True).fit(x, y, rng=0)
    tuned = GpSurrogate(restarts=2).fit(x, y, rng=0)
    for gp in (scg, default, tuned):
        assert np.isfinite(gp.info["neg_log_evidence"])
    # Restarts from data-based guesses never end worse than one run from the same first guess.
    single = GpSurrogate(restarts=0).fit(x, y, rng=0)
    assert tuned.info["neg_log_evidence"] <= single.info["neg_log_evidence"] + 1e-9


def test_bad_options_are_config_errors():
    with pytest.raises(fbia.ConfigError, match=r"^gp: unknown GP optimizer 'bfgs'; valid: lbfgsb"):
        GpSurrogate(optimizer="bfgs")
    with pytest.raises(fbia.ConfigError, match=r"^gp: GP training data must be finite$"):
        GpSurrogate().fit(np.zeros((3, 1)), [0.0, np.nan, 1.0])
    with pytest.raises(fbia.ConfigError, match=r"not trained yet"):
        GpSurrogate().predict_mean(np.zeros((1, 1)))


def test_restored_surrogate_predicts_like_the_trained_one(trained):
    gp, _ = trained
    again = GpSurrogate.from_state(gp.state())
    x = np.random.default_rng(2).uniform(-0.2, 1.2, size=(400, 2))
    mean, var = gp.predict(x)
    # Same hyperparameters, another Cholesky of an ill-conditioned (K + sigma_n^2 I): the two
    # agree to ~1e-4 of the spread of L, far below the surrogate error itself.
    tol = 1e-4 * np.ptp(gp.y_train)
    np.testing.assert_allclose(again.predict_mean(x), mean, rtol=0, atol=tol)
    mean2, var2 = again.predict(x)
    np.testing.assert_allclose(mean2, mean, rtol=0, atol=tol)
    np.testing.assert_allclose(np.sqrt(var2), np.sqrt(var), rtol=0, atol=1e-3 * np.sqrt(var.max()))


def test_fused_numba_mean_equals_numpy_blocks(trained):
    gp, _ = trained
    x = np.random.default_rng(3).uniform(-0.5, 1.5, size=(500, 2))
    np.testing.assert_allclose(
        gp.predict_mean(x, fused=True), gp.predict_mean(x, fused=False), rtol=0, atol=1e-9
    )
    for m in (1, 2, 3, 65, 66, 67):  # the product kernel works on groups of four particles
        np.testing.assert_allclose(
            gp.predict_mean(x[:m], fused=True), gp.predict_mean(x[:m], fused=False), atol=1e-9
        )
    if gp.ard:  # length scales so short that e^(sqrt3 x / l) would overflow: the exp loop
        state = {**gp.state(), "lengthscales": np.array([2e-3, 3e-3])}
        short = GpSurrogate.from_state(state)
        assert np.abs(short.standardise(x)).max() * np.sqrt(3) / 2e-3 > 300
        np.testing.assert_allclose(
            short.predict_mean(x), short.predict_mean(x, fused=False), rtol=0, atol=1e-9
        )


def test_fused_product_kernel_equals_gpys_product_with_exact_gradients():
    """The one-pass kernel (gp_kernels.py) is GPy's product of 1-D Matérn 3/2 kernels."""
    import GPy

    from fbia.iterators.surrogates.kernels import Matern32Product

    rng = np.random.default_rng(3)
    x = rng.standard_normal((40, 4))
    x2 = rng.standard_normal((7, 4))
    ell = np.array([0.4, 0.9, 1.7, 3.0])
    k = Matern32Product(4, variance=1.7, lengthscale=ell)
    ref = GPy.kern.Matern32(1, active_dims=[0], variance=1.7, lengthscale=ell[0])
    for j in range(1, 4):
        ref = ref * GPy.kern.Matern32(1, active_dims=[j], lengthscale=ell[j])
    np.testing.assert_allclose(k.K(x), ref.K(x), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(k.K(x, x2), ref.K(x, x2), rtol=1e-13, atol=1e-15)
    # Evidence gradients w.r.t. variance and length scales match finite differences.
    y = np.sin(x.sum(1))[:, None]
    model = GPy.models.GPRegression(x, y, k, noise_var=1e-3)
    assert model.checkgrad(tolerance=1e-4)
    # Input gradients: d/dx sum(dL * K(x, x)) by central differences.
    dl = rng.standard_normal((40, 40))
    grad = k.gradients_X(dl, x)
    h = 1e-6
    for i, j in [(3, 0), (17, 2), (39, 3)]:
        xp, xm = x.copy(), x.copy()
        xp[i, j] += h
        xm[i, j] -= h
        fd = (np.sum(dl * k.K(xp)) - np.sum(dl * k.K(xm))) / (2 * h)
        assert abs(fd - grad[i, j]) < 1e-6 * max(1.0, abs(fd))


def test_guard_caps_a_mean_that_overshoots_outside_the_data_and_counts_it():
    """Issue 16, item 4: a concave quadratic peaking at (2, 2), trained on [0, 1]^2. The GP
    carries the rise on beyond the data (to hundreds of units above the largest training
    value, above the true function); the guard caps it at max L + chi2_2(0.999) / 2."""
    from fbia.iterators.smc.sampler import SmcResult

    x = qmc.Sobol(2, scramble=True, seed=4).random(64)
    y = -100.0 * np.sum((x - 2.0) ** 2, axis=1)
    gp = GpSurrogate(restarts=2).fit(x, y, rng=0)
    cap = gp.extrapolation_cap
    assert cap == pytest.approx(y.max() + 13.8155 / 2, abs=1e-3)  # chi2_2(0.999) = 13.8155
    g = np.linspace(0.0, 3.0, 31)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    raw = gp.predict_mean(grid)
    over = raw > cap
    assert raw.max() > y.max() + 100.0 and 100 < over.sum() < len(grid)
    assert np.all(over[np.all(grid >= 1.5, axis=1)])  # far beyond the data: all capped
    guarded = gp.predict_mean_guarded(grid)
    np.testing.assert_array_equal(guarded, np.where(over, cap, raw))
    inside = gp.predict_mean_guarded(x)  # a second call, nothing to cap
    np.testing.assert_array_equal(inside, gp.predict_mean(x))
    assert gp.guard.calls == 2 and gp.guard.capped_calls == 1
    assert gp.guard.points == len(grid) + len(x) and gp.guard.capped_points == over.sum()
    # The posterior mass at capped points of a (here: made-up) SMC result on the guarded mean.
    weights = np.full(len(grid), 1.0 / len(grid))
    result = SmcResult(grid, weights, guarded, np.zeros(len(grid)), 0.0, 0.0, [], [], [], 0, [])
    assert gp.extrapolated_mass(result) == pytest.approx(over.mean())
    with pytest.raises(fbia.ConfigError, match="guard_margin must be >= 0"):
        GpSurrogate(guard_margin=-1.0)
    assert GpSurrogate(guard_margin=0.0).fit(x, y, rng=0).extrapolation_cap == y.max()


def test_rotated_axes_follow_a_narrow_ridge_across_the_inputs():
    """fit(..., axes=cov): the product kernel's length scales along the principal axes of a
    covariance (the adaptive design's posterior) instead of the inputs. L is a Gaussian ridge
    along the diagonal, 13 times narrower across it than along it; with 128 Sobol runs the
    rotated GP is more than 4 times closer to L where the posterior is (measured 0.0053 against
    0.048 RMSE); an isotropic kernel is unchanged by a rotation; the state keeps the axes."""

    def ridge(x):
        return -0.5 * (((x[:, 0] - x[:, 1]) / 0.03) ** 2 + ((x[:, 0] + x[:, 1] - 1) / 0.4) ** 2)

    x = qmc.Sobol(2, scramble=True, seed=4).random(128)
    rng = np.random.default_rng(1)
    d, s = rng.normal(0, 0.03, 2000), rng.normal(0, 0.4, 2000)  # draws from exp(L)
    post = np.column_stack([0.5 + (s + d) / 2, 0.5 + (s - d) / 2])
    post = post[np.all((post > 0) & (post < 1), axis=1)]
    cov = np.cov(post.T)

    def rmse(gp):
        return float(np.sqrt(np.mean((gp.predict_mean(post) - ridge(post)) ** 2)))

    axis = GpSurrogate(ard=True).fit(x, ridge(x), rng=0)
    rotated = GpSurrogate(ard=True).fit(x, ridge(x), rng=0, axes=cov)
    assert rotated.rotation is not None and axis.rotation is None
    np.testing.assert_allclose(rotated.rotation.T @ rotated.rotation, np.eye(2), atol=1e-12)
    # the first axis (smallest variance) is across the ridge: along (1, -1) / sqrt(2)
    assert abs(abs(rotated.rotation[0, 0] - rotated.rotation[1, 0]) - np.sqrt(2)) < 0.05
    assert rmse(rotated) < 0.25 * rmse(axis)
    iso = GpSurrogate(ard=False).fit(x, ridge(x), rng=0)
    iso_rot = GpSurrogate(ard=False).fit(x, ridge(x), rng=0, axes=cov)
    assert rmse(iso_rot) == pytest.approx(rmse(iso), rel=1e-3)
    again = GpSurrogate.from_state(rotated.state())
    np.testing.assert_allclose(again.rotation, rotated.rotation)
    tol = 1e-3 * np.ptp(rotated.y_train)
    np.testing.assert_allclose(again.predict_mean(post), rotated.predict_mean(post), atol=tol)
    with pytest.raises(fbia.ConfigError, match="axes"):
        GpSurrogate(ard=True).fit(x, ridge(x), rng=0, axes=np.eye(3))


def test_warm_start_carries_length_scales_to_turned_axes():
    """An adaptive round warm-starts from the last round's hyperparameters while its kernel
    axes turn (gp_axes = "posterior"): the carried length scales describe the same kernel
    widths along the new axes (stop 38's note: they were rescaled along the input axes)."""
    rng = np.random.default_rng(4)
    x = rng.uniform(0.0, 1.0, (60, 2))
    y = np.sin(12.0 * x[:, 0]) + np.sin(2.0 * x[:, 1])  # short along x0, long along x1
    gp = GpSurrogate(ard=True).fit(x, y, rng=0)
    hp = gp.hyperparameters()
    assert "rotation" not in hp  # input axes
    ells = np.array(hp["lengthscales"])
    assert ells[1] > 2.0 * ells[0]
    # the same data on axes turned by 90 degrees (the smaller variance's axis comes first):
    # the two length scales trade places
    turned = GpSurrogate(ard=True)
    turned.fit(x, y, rng=0, axes=np.diag([4.0, 1.0]) * np.outer(x.std(0), x.std(0)))
    assert np.allclose(np.abs(turned.rotation), [[0.0, 1.0], [1.0, 0.0]])
    _, carried = turned._carried(hp)
    expect = np.abs(turned.rotation.T) @ ells  # each new axis is one of the old ones
    np.testing.assert_allclose(carried, expect, rtol=1e-9)
    # back again: a fit on the turned axes carries its own scales to the input axes
    plain = GpSurrogate(ard=True).fit(x, y, rng=0)
    hp_t = turned.hyperparameters()
    assert "rotation" in hp_t
    _, back = plain._carried(hp_t)
    np.testing.assert_allclose(back, np.abs(turned.rotation) @ hp_t["lengthscales"], rtol=1e-9)


@pytest.mark.parametrize("ard", [False, True], ids=["single", "ard"])
def test_conditioning_without_gpy_equals_gpys_exact_inference(ard):
    """A fit that keeps its hyperparameters (an adaptive round between re-optimisations)
    conditions in numpy (Cholesky, alpha): its mean, variance, evidence and leave-one-out
    predictions are GPy's for the same hyperparameters, up to round-off (with GPy's jitter of
    1e-8 on the diagonal; without it they differed by 1e-5 of the span)."""
    x = qmc.Sobol(2, scramble=True, seed=7).random(64)
    y = _log_lik(x)
    full = GpSurrogate(ard=ard, restarts=0).fit(x, y, rng=0)
    kept = GpSurrogate(ard=ard).fit(x, y, start=full.hyperparameters(), optimise=False)
    assert kept.info["optimizer"] == "none (hyperparameters kept)"
    x_test = np.random.default_rng(2).uniform(-0.2, 1.2, (200, 2))
    m_full, v_full = full.predict(x_test)
    m_kept, v_kept = kept.predict(x_test)
    span = y.max() - y.min()
    np.testing.assert_allclose(m_kept, m_full, rtol=0, atol=1e-7 * span)
    np.testing.assert_allclose(v_kept, v_full, rtol=1e-5, atol=1e-9 * span**2)
    np.testing.assert_allclose(kept.loo_predictions(), full.loo_predictions(), atol=1e-6 * span)
    assert kept.info["neg_log_evidence"] == pytest.approx(full.info["neg_log_evidence"], rel=1e-6)


def test_a_warm_start_on_many_runs_searches_on_a_subset_and_conditions_on_all():
    """Warm-started on more than WARM_SUBSET runs, the hyperparameters are searched on a
    random subset of WARM_SUBSET of them and the GP is conditioned on every run: it
    interpolates all of them and predicts as well as one optimised on all."""
    from fbia.iterators.surrogates.gp import WARM_SUBSET

    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1.0, (WARM_SUBSET + 200, 2))
    y = _log_lik(x)
    first = GpSurrogate(ard=True).fit(x[:60], y[:60], rng=0)
    warm = GpSurrogate(ard=True, restarts=0).fit(x, y, rng=0, start=first.hyperparameters())
    assert warm.info["optimizer"] == f"lbfgsb on a subset of {WARM_SUBSET}"
    assert warm.info["subset_search"]["n_train"] == WARM_SUBSET
    span = y.max() - y.min()
    np.testing.assert_allclose(warm.predict_mean(x), y, atol=1e-3 * span)  # every run
    on_all = GpSurrogate(ard=True, restarts=0, subset=10_000).fit(
        x, y, rng=0, start=first.hyperparameters(), optimise=True
    )
    x_test = qmc.Sobol(2, scramble=True, seed=4).random(256)
    err_warm = warm.test_error(x_test, _log_lik(x_test))["test_relative_l2"]
    err_all = on_all.test_error(x_test, _log_lik(x_test))["test_relative_l2"]
    assert err_warm < 1.5 * err_all + 1e-4
