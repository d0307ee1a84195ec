"""The quadratic trend under the GP (gp_trend): exact on quadratics, concave, restorable, and
what it is for: a surrogate that follows a tilted ridge beyond the runs."""

import numpy as np

from fbia.iterators.surrogates.gp import GpSurrogate
from fbia.iterators.surrogates.trend import QuadraticTrend


def ridge(x):
    """A log-likelihood whose maximum is a tilted ridge u = v (sharp across, long along)."""
    u, v = x[:, 0], x[:, 1]
    return -((u - v) ** 2) / 0.005 - (u + v - 1.0) ** 2 / 2.0


def test_a_concave_quadratic_is_fitted_exactly_and_a_convex_direction_is_cut():
    rng = np.random.default_rng(1)
    x = rng.random((60, 2))
    trend = QuadraticTrend.fit(x, ridge(x))
    np.testing.assert_allclose(trend(x), ridge(x), atol=1e-8)
    saddle = QuadraticTrend.fit(x, x[:, 0] ** 2 - x[:, 1] ** 2)  # not concave
    assert np.all(np.linalg.eigvalsh(saddle.h) < 0)
    back = QuadraticTrend.from_state(trend.state())
    np.testing.assert_array_equal(back(x), trend(x))


def test_the_surrogate_follows_a_ridge_beyond_the_runs():
    rng = np.random.default_rng(0)
    # runs along the middle of the ridge only (u, v in [0.35, 0.65]), and around it
    t = rng.uniform(0.35, 0.65, 40)
    x = np.column_stack([t, t + rng.normal(0.0, 0.05, 40)])
    ends = np.array([[0.1, 0.1], [0.9, 0.9]])  # on the ridge, far beyond the runs
    err = {}
    for kind in ("constant", "quadratic"):
        gp = GpSurrogate(ard=True, trend=kind).fit(x, ridge(x), rng=0)
        err[kind] = np.abs(gp.predict_mean(ends) - ridge(ends)).max()
        restored = GpSurrogate.from_state(gp.state())
        np.testing.assert_allclose(restored.predict_mean(ends), gp.predict_mean(ends), atol=1e-6)
    assert err["quadratic"] < 0.1 * err["constant"], err
