"""The numerics under the robust LM mode: finite-difference stencils and the predicted
reduction of the trust-region step (``fbia.iterators.lm.finite_differences``, ``trust_region``)."""

from __future__ import annotations

import numpy as np
import pytest

from fbia.iterators.lm.finite_differences import central_factor, central_stencil, forward_steps
from fbia.iterators.lm.trust_region import lm_step, predicted_reduction, step_back

T = np.linspace(0.0, 2.0, 7)


def model(x):
    return np.exp(-x[0] * T) * np.sin(x[1] + T)


def exact_jacobian(x):
    e, s, c = np.exp(-x[0] * T), np.sin(x[1] + T), np.cos(x[1] + T)
    return np.column_stack([-T * e * s, e * c])


def central_jacobian(x, lower, upper, beta):
    stencil = central_stencil(x, np.zeros(2), beta, lower, upper)
    r0 = model(x)
    rs = [model(p) for p in stencil.points]
    return np.column_stack([stencil.column(i, r0, rs[2 * i], rs[2 * i + 1]) for i in range(2)])


def observed_order(errors, steps):
    return np.polyfit(np.log(steps), np.log(errors), 1)[0]


X = np.array([0.7, 0.3])
FREE = (np.full(2, -np.inf), np.full(2, np.inf))


def test_forward_differences_are_first_order():
    J = exact_jacobian(X)
    betas = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    errors = []
    for beta in betas:
        d = forward_steps(X, np.zeros(2), beta, *FREE)
        Jf = np.column_stack([(model(X + d[i] * np.eye(2)[i]) - model(X)) / d[i] for i in range(2)])
        errors.append(np.abs(Jf - J).max())
    assert observed_order(errors, betas) == pytest.approx(1.0, abs=0.1)


@pytest.mark.parametrize(
    "bounds",
    [FREE, (np.array([0.7, -np.inf]), np.full(2, np.inf)), (np.full(2, -np.inf), X.copy())],
    ids=["central", "one-sided forward at a lower bound", "one-sided backward at upper bounds"],
)
def test_second_order_stencils_are_second_order_and_stay_in_the_box(bounds):
    lower, upper = bounds
    J = exact_jacobian(X)
    # the stencil's step is beta^(2/3)|x|: vary it through beta
    hs = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    betas = hs**1.5
    errors = []
    for beta in betas:
        stencil = central_stencil(X, np.zeros(2), beta, lower, upper)
        for p in stencil.points:
            assert np.all(p >= lower) and np.all(p <= upper)
        errors.append(np.abs(central_jacobian(X, lower, upper, beta) - J).max())
    assert observed_order(errors, hs) == pytest.approx(2.0, abs=0.15)


def test_central_step_balances_truncation_and_noise():
    # beta = sqrt(eps) was chosen for forward differences; the central step is eps^(1/3)|x|
    eps = np.finfo(float).eps
    assert central_factor(np.sqrt(eps)) * np.sqrt(eps) == pytest.approx(eps ** (1 / 3))
    assert central_factor(0.0) == 1.0 and central_factor(1.0) == 1.0
    # at that step the central J is ~1e-10 accurate where the forward one is ~1e-8
    Jc = central_jacobian(X, *FREE, np.sqrt(eps))
    assert np.abs(Jc - exact_jacobian(X)).max() < 1e-9


def test_predicted_reduction_of_the_lm_step_has_no_cancellation():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(20, 3)) * np.array([1.0, 1e-3, 1e3])
    r = rng.normal(size=20)
    D = np.linalg.norm(J, axis=0)
    free = np.ones(3, dtype=bool)
    # a moderate step: the identity ‖r‖² − ‖r + Jp‖² = ‖Jp‖² + 2μ‖Dp‖² holds
    p, mu = lm_step(J, r, D, free, mu=0.3)
    pred, dirder = predicted_reduction(J, r, p, D, mu, exact=True)
    direct = (r @ r - np.sum((r + J @ p) ** 2)) / (r @ r)
    assert pred == pytest.approx(direct, rel=1e-12)
    assert dirder == pytest.approx(float(r @ (J @ p)) / (r @ r), rel=1e-12)
    general, _ = predicted_reduction(J, r, p, D, mu, exact=False)
    assert general == pytest.approx(direct, rel=1e-12)
    # a tiny step (near convergence): the subtraction is round-off, the identity is not
    p, mu = lm_step(J, r, D, free, mu=1e12)
    pred, _ = predicted_reduction(J, r, p, D, mu, exact=True)
    model_value = np.sum((J @ p) ** 2) + 2 * mu * np.sum((D * p) ** 2)
    assert pred > 0 and pred == pytest.approx(model_value / (r @ r), rel=1e-12)


def test_a_step_across_a_far_bound_goes_halfway_a_near_one_is_left_to_the_projection():
    """step_back: a step that would cross a bound from farther than a tenth of the range stops
    halfway to it (in its own direction); from nearer, or inside the box, or with no bound,
    the step itself is returned (within_bounds then projects or shortens it)."""
    lower, upper = np.array([100.0, -1.0]), np.array([1500.0, 0.5])
    x, p = np.array([1000.0, 0.0]), np.array([-1800.0, 0.3])  # E would reach -800 Pa
    np.testing.assert_allclose(x + step_back(x, p, lower, upper), [550.0, 0.075])
    near = np.array([200.0, 0.0])  # 100 Pa from the bound: under a tenth of 1400 Pa
    assert step_back(near, p, lower, upper) is p
    inside = np.array([-300.0, 0.1])
    assert step_back(x, inside, lower, upper) is inside
    assert step_back(x, p, np.array([-np.inf, -1.0]), np.array([np.inf, 0.5])) is p
    up = np.array([0.0, 1.4])  # nu would reach 1.4 from 0.0: halfway to 0.5
    np.testing.assert_allclose(x + step_back(x, up, lower, upper), [1000.0, 0.25])
