"""The Levenberg–Marquardt iterator on plain residual functions: Paper A's equations, the robust
mode's handling of bounds and failed runs, batching, statistics, options, stepping, plots."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import fbia
from fbia.iterators.least_squares import ResidualFunctionProblem
from fbia.iterators.levenberg_marquardt import LevenbergMarquardtIterator, LMResult, LMState

T = np.linspace(0.0, 4.0, 25)
Y = 3.0 * np.exp(-0.7 * T)


def decay(b):
    return b[0] * np.exp(-b[1] * T) - Y


def rosenbrock(x):
    return np.array([1.0 - x[0], 10.0 * (x[1] - x[0] ** 2)])


class RecordingEvaluator(fbia.SerialEvaluator):
    """Serial evaluation that remembers the batches it was given."""

    def __init__(self) -> None:
        super().__init__()
        self.batches: list[list[dict[str, float]]] = []

    def evaluate(self, problem, points):
        self.batches.append([dict(p) for p in points])
        return super().evaluate(problem, points)


def paper_reference(fun, x0, mu0, alpha, beta, iterations, lower=-np.inf, upper=np.inf):
    """Paper A eq. 17-28 written out pass by pass as QUEENS runs them: every pass evaluates
    r and J at the current point and moves the previous errors on; a step out of bounds
    doubles mu and the next pass starts again at the same point (so eq. 27 compares the point
    with itself there); mu > mu0 * 1e6 ends the run.  Returns (x, mu, err_res, err_grad) at
    every point reached, mu as it stood on arrival."""
    x, mu = np.asarray(x0, dtype=float), mu0
    res = grad = None
    visited, arrived, k = [], True, 0
    while k < iterations:
        r = fun(x)
        dx = alpha + beta * x  # eq. 21
        J = np.column_stack(
            [(fun(x + dx[i] * np.eye(len(x))[i]) - r) / dx[i] for i in range(len(x))]
        )  # eq. 22-23
        res_o, grad_o = res, grad
        res = np.linalg.norm(r) / math.sqrt(len(r))  # eq. 25
        grad = np.linalg.norm(J.T @ r)  # eq. 24
        if res_o is None:
            res_o, grad_o = res, grad
        if arrived:
            visited.append((x.copy(), mu, res, grad))
            arrived = False
        A = J.T @ J
        step = -np.linalg.solve(A + mu * np.diag(np.diag(A)), J.T @ r)  # eq. 18
        if np.any(x + step <= lower) or np.any(x + step >= upper):  # eq. 28
            mu *= 2.0
            if mu > mu0 * 1e6:
                break
            continue
        x, arrived = x + step, True  # eq. 17
        if res < res_o and grad < grad_o:  # eq. 27
            mu *= grad / grad_o  # eq. 26
        k += 1
    return visited


# -- Paper A as published --------------------------------------------------------------------------
def test_paper_mode_follows_eq_17_to_27():
    result = fbia.least_squares(
        rosenbrock, [-1.2, 1.0], mode="paper", alpha=1e-5, beta=1e-3, max_iter=6, eps_grad=0
    )
    expected = paper_reference(rosenbrock, [-1.2, 1.0], 1.0, 1e-5, 1e-3, 7)
    taken = [h for h in result.history if h["accepted"]]
    assert len(taken) == 7  # the start and six steps
    for h, (x, mu, err_res, err_grad) in zip(taken, expected, strict=True):
        np.testing.assert_allclose(list(h["x"].values()), x, rtol=1e-12)
        assert h["mu"] == pytest.approx(mu, rel=1e-12)
        assert h["err_res"] == pytest.approx(err_res, rel=1e-12)
        assert h["err_grad"] == pytest.approx(err_grad, rel=1e-12)
    assert result.status == "iteration_limit" and not result.success
    # eq. 26 did lower μ along the way (the errors decreased)
    assert taken[-1]["mu"] < 1.0


def test_paper_mode_keeps_the_doubled_mu_after_a_declined_step_as_queens():
    # the second step from (-1.2, 1) leaves the box x1 < 1.15, and so do the steps after it:
    # with mu kept doubled after each declined step the run creeps to the bound and ends at
    # the damping limit, as QUEENS' does
    lower, upper = np.array([-2.0, -1.0]), np.array([2.0, 1.15])
    result = fbia.least_squares(
        rosenbrock,
        [-1.2, 1.0],
        (lower, upper),
        mode="paper",
        alpha=1e-5,
        beta=1e-3,
        max_iter=30,
        eps_grad=0,
    )
    expected = paper_reference(rosenbrock, [-1.2, 1.0], 1.0, 1e-5, 1e-3, 30, lower, upper)
    reached = [h for h in result.history if h["accepted"]]
    assert sum(not h["accepted"] for h in result.history) > 10  # declined steps
    assert result.status == "damping_limit"
    assert len(reached) == len(expected)
    for h, (x, mu, _, _) in zip(reached, expected, strict=True):
        np.testing.assert_allclose(list(h["x"].values()), x, rtol=1e-12)
        assert h["mu"] == pytest.approx(mu, rel=1e-12)


def test_paper_mode_can_restore_mu_after_a_declined_step():
    """declined_mu = "restored" (issue 46, Table 3): the doubling of eq. 28 serves the new
    proposal only; the next iteration starts from the mu before it, so mu on arrival never
    grows (eq. 26 only lowers it), where the default keeps it doubled (on the run of the
    test above: 1 -> 262144 over 10 points, against 1 throughout; this run creeps along the
    bound either way: Table 3's orange start is where the reading matters)."""
    lower, upper = np.array([-2.0, -1.0]), np.array([2.0, 1.15])
    kw = dict(mode="paper", alpha=1e-5, beta=1e-3, max_iter=30, eps_grad=0)
    result = fbia.least_squares(
        rosenbrock, [-1.2, 1.0], (lower, upper), declined_mu="restored", **kw
    )
    reached = [h for h in result.history if h["accepted"]]
    mus = [h["mu"] for h in reached]
    assert sum(not h["accepted"] for h in result.history) > 0  # steps were declined
    assert all(b <= a * (1 + 1e-12) for a, b in zip(mus, mus[1:], strict=False))
    kept = fbia.least_squares(rosenbrock, [-1.2, 1.0], (lower, upper), **kw)
    kept_mus = [h["mu"] for h in kept.history if h["accepted"]]
    assert kept.status == "damping_limit" and kept_mus[-1] > 1e4  # the default, as QUEENS


def test_declined_mu_is_paper_mode_only():
    with pytest.raises(fbia.ConfigError, match="option declined_mu applies to mode='paper' only"):
        fbia.least_squares(rosenbrock, [-1.2, 1.0], mode="robust", declined_mu="restored")


def test_paper_mode_perturbs_each_parameter_by_alpha_plus_beta_x_in_one_batch():
    ev = RecordingEvaluator()
    fbia.least_squares(
        decay, [2.0, -0.5], mode="paper", alpha=1e-5, beta=1e-3, max_iter=2, evaluator=ev
    )
    first = [np.array([p["x0"], p["x1"]]) for p in ev.batches[0]]
    assert len(first) == 3  # n_x + 1 runs of one Jacobian: one batch (eq. 21-23)
    np.testing.assert_array_equal(first[0], [2.0, -0.5])
    np.testing.assert_allclose(first[1] - first[0], [1e-5 + 1e-3 * 2.0, 0.0], rtol=1e-9)
    np.testing.assert_allclose(first[2] - first[0], [0.0, 1e-5 - 1e-3 * 0.5], rtol=1e-6)
    assert all(len(b) == 3 for b in ev.batches)  # every step is taken: always x and x + δx_i


def test_paper_mode_converges_on_eq_29a_and_reports_the_lowest_err_res_iterate():
    result = fbia.least_squares(decay, [1.0, 1.0], mode="paper", alpha=1e-5, beta=1e-3)
    assert result.status == "converged_gradient" and result.success
    assert result.err_grad < 1e-8
    np.testing.assert_allclose(result.x_array, [3.0, 0.7], rtol=1e-6)
    assert result.err_res == min(h["err_res"] for h in result.history if h["accepted"])


def test_paper_mode_converges_on_eq_29b():
    result = fbia.least_squares(decay, [1.0, 1.0], mode="paper", eps_res=1e-3)
    assert result.status == "converged_residual"
    assert result.err_res < 1e-3


def test_paper_mode_ends_without_result_when_a_run_fails():
    def fails_beyond(b):
        if b[1] < 0.5:  # the first full step lands here
            raise fbia.ForwardModelError("mesh distortion")
        return decay(b)

    result = fbia.least_squares(fails_beyond, [1.0, 1.0], mode="paper")
    assert result.status == "run_failed" and not result.success
    assert result.x is None
    assert "mesh distortion" in result.message and "without result" in result.message
    assert result.n_failed >= 1


def test_paper_mode_has_no_step_when_a_parameter_has_no_effect():
    result = fbia.least_squares(lambda b: decay([b[0], 0.7]), [1.0, 1.0], mode="paper")
    assert result.status == "singular" and result.x is None
    # the robust mode holds the parameter (zero column: min-norm step) and fits the other
    robust = fbia.least_squares(lambda b: decay([b[0], 0.7]), [1.0, 1.0])
    assert robust.success and robust.x_array == pytest.approx([3.0, 1.0])


# -- robust mode -----------------------------------------------------------------------------------
def test_robust_mode_steps_around_a_failing_region():
    calls = []

    def fails_beyond(b):
        calls.append(b.copy())
        if b[1] < 0.5:
            raise fbia.ForwardModelError("mesh distortion")
        return decay(b)

    result = fbia.least_squares(fails_beyond, [1.0, 1.0])
    assert result.success, result.message
    np.testing.assert_allclose(result.x_array, [3.0, 0.7], rtol=1e-7)
    assert result.n_failed >= 1  # it did run into the region ...
    declined = [h for h in result.history if h["note"] == "rejected: run failed"]
    assert declined and all(h["x"]["x1"] < 0.5 for h in declined)  # ... and declined the step


def test_a_failed_perturbed_run_is_repeated_on_the_other_side():
    def edge(b):  # linear, solvable only for b0 <= 1; the optimum b0 = 1 is on the edge
        if b[0] > 1.0 + 1e-12:
            raise fbia.ForwardModelError("beyond the edge")
        return np.array([b[0] - 1.0, 2.0 * (b[1] - 2.0), b[0] + b[1] - 3.0])

    ev = RecordingEvaluator()
    result = fbia.least_squares(edge, [1.0, 0.0], evaluator=ev)
    assert result.success, result.message
    np.testing.assert_allclose(result.x_array, [1.0, 2.0], atol=1e-9)
    # the forward perturbation of b0 failed and was repeated backwards in its own batch
    assert len(ev.batches[0]) == 3 and len(ev.batches[1]) == 1
    assert ev.batches[1][0]["x0"] < 1.0
    np.testing.assert_allclose(result.jac[:, 0], [1.0, 0.0, 1.0], atol=1e-6)


def test_a_failed_start_is_reported():
    def never(b):
        raise fbia.ForwardModelError("the solver diverged")

    result = fbia.least_squares(never, [1.0, 1.0])
    assert result.status == "all_failed" and result.x is None
    assert "the solver diverged" in result.message

    def nan_at_the_start(b):
        return decay(b) * (np.nan if np.all(b == 1.0) else 1.0)

    result = fbia.least_squares(nan_at_the_start, [1.0, 1.0])
    assert result.status == "start_failed" and "NaN or inf" in result.message
    assert result.nfev == 3 and result.n_failed == 1


def test_bounds_are_respected_and_an_active_bound_is_found():
    # unconstrained optimum b1 = 0.7; the bound b1 <= 0.5 is active at the solution
    result = fbia.least_squares(decay, [1.0, 0.2], bounds=([0.0, 0.0], [10.0, 0.5]))
    assert result.success, result.message
    assert result.x_array[1] == 0.5
    for h in result.history:
        assert 0.0 <= h["x"]["x0"] <= 10.0 and 0.0 <= h["x"]["x1"] <= 0.5
    b0 = np.dot(np.exp(-0.5 * T), Y) / np.dot(np.exp(-T), np.ones_like(T))  # optimal b0 | b1
    assert result.x_array[0] == pytest.approx(b0, rel=1e-7)
    assert result.starts[0]["at_bound"] == ["x1"]
    # a plain residual function's bounds are constraints: the active one is recorded (as
    # scipy's active_mask), not a verdict (a calibration's is: test_lm_fit_quality.py)
    assert result.status.startswith("converged") and result.quality.at_bound == ("x1",)


def test_robust_mode_needs_no_new_jacobian_after_a_declined_step():
    ev = RecordingEvaluator()
    result = fbia.least_squares(rosenbrock, [-1.2, 1.0], evaluator=ev)
    assert result.success
    np.testing.assert_allclose(result.x_array, [1.0, 1.0], rtol=1e-8)
    sizes = [len(b) for b in ev.batches]
    assert sizes[0] == 3  # x0 and its two perturbations
    # afterwards: a trial point (1 run), then the Jacobian at an accepted point (2 runs, or
    # 4 for central differences in the last phase, after which no forward J is made)
    assert set(sizes[1:]) <= {1, 2, 4}
    first_central = sizes.index(4)
    assert 2 not in sizes[first_central:]
    assert any("central-difference Jacobian" in h["note"] for h in result.history)
    declined = sum(not h["accepted"] for h in result.history)
    taken = sum(h["accepted"] for h in result.history) - 1
    assert sizes.count(1) == declined + taken  # one run per trial step, none more
    assert result.nfev == sum(sizes) == len(result.evaluations)


def test_speculative_mode_evaluates_a_trial_point_with_its_perturbations():
    ev = RecordingEvaluator()
    result = fbia.least_squares(rosenbrock, [-1.2, 1.0], speculative=True, evaluator=ev)
    assert result.success
    np.testing.assert_allclose(result.x_array, [1.0, 1.0], rtol=1e-8)
    sizes = [len(b) for b in ev.batches]
    # trial point and its two perturbations together, until the central-difference phase
    first_central = sizes.index(4)
    assert set(sizes[:first_central]) == {3}
    assert set(sizes[first_central:]) <= {1, 4}


def test_multi_start_chains_share_the_batches():
    ev = RecordingEvaluator()
    result = fbia.least_squares(decay, [[1.0, 1.0], [5.0, 0.2], [2.0, 2.0]], evaluator=ev)
    assert len(ev.batches[0]) == 9  # three starts, x0 and two perturbations each
    assert len(result.starts) == 3 and all(s["success"] for s in result.starts)
    assert sum(s["nfev"] for s in result.starts) == result.nfev
    assert result.warnings == []


def test_equally_good_but_different_optima_are_flagged():
    def product(b):  # only b0*b1 is determined by the data
        return b[0] * b[1] * T - 2.0 * T

    result = fbia.least_squares(product, [[1.0, 4.0], [4.0, 1.0]])
    xs = [np.array(list(s["x"].values())) for s in result.starts]
    assert all(s["equally_good"] for s in result.starts)
    assert xs[0][0] * xs[0][1] == pytest.approx(2.0) and xs[1][0] * xs[1][1] == pytest.approx(2.0)
    assert len(result.warnings) == 1 and "disagree" in result.warnings[0]
    assert "WARNING" in result.message
    assert result.cov_rank == 1  # J is rank deficient: (JᵀJ)⁺


# -- statistics ------------------------------------------------------------------------------------
def test_linear_problem_gives_ordinary_least_squares_covariance_and_information_criteria():
    rng = np.random.default_rng(7)
    X = np.column_stack([np.ones_like(T), T, T**2])
    y = X @ [1.0, -2.0, 0.5] + 0.05 * rng.standard_normal(len(T))
    result = fbia.least_squares(lambda b: X @ b - y, [0.0, 0.0, 0.0], names=["a", "b", "c"])
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    np.testing.assert_allclose(result.x_array, beta, rtol=1e-7)
    n, p = X.shape
    rss = float(np.sum((X @ beta - y) ** 2))
    cov = rss / (n - p) * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(result.cov, cov, rtol=1e-5)
    sd = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(result.corr, cov / np.outer(sd, sd), rtol=1e-5, atol=1e-9)
    assert list(result.stderr) == ["a", "b", "c"]
    assert result.sigma2 == pytest.approx(rss / (n - p), rel=1e-9)
    m2loglik = n * math.log(2 * math.pi * rss / n) + n
    assert result.aic == pytest.approx(m2loglik + 2 * (p + 1), rel=1e-9)
    assert result.bic == pytest.approx(m2loglik + (p + 1) * math.log(n), rel=1e-9)


def test_result_is_summarised():
    noisy = Y + 0.01 * np.random.default_rng(3).standard_normal(len(T))
    result = fbia.least_squares(
        lambda b: b[0] * np.exp(-b[1] * T) - noisy, [[1.0, 1.0], [5.0, 0.2]], names=["a", "k"]
    )
    assert isinstance(result, LMResult)
    text = result.summary()
    assert "a = 2.99" in text and "std. errors: a ± " in text and "AIC = " in text
    assert "correlation: a-k +" in text and "fits as well" in text


def test_result_json_round_trip(tmp_path):
    result = fbia.least_squares(decay, [1.0, 1.0], names=["a", "k"])
    data = json.loads(result.save(tmp_path / "r.json").read_text())
    assert data["status"] == result.status and data["x"] == result.x
    assert data["names"] == ["a", "k"] and len(data["cov"]) == 2
    assert data["starts"][0]["x0"] == {"a": 1.0, "k": 1.0}
    assert len(data["evaluations"]) == result.nfev


# -- stepping, budget, registry, options -----------------------------------------------------------
def problem_of(fun, n, lower=-np.inf, upper=np.inf):
    names = [f"x{i}" for i in range(n)]
    return ResidualFunctionProblem(fun, names, np.full(n, lower), np.full(n, upper))


def test_steps_yield_states_and_stop_returns_a_partial_result():
    it = fbia.iterator("levenberg_marquardt", x0={"x0": -1.2, "x1": 1.0})
    gen = it.steps(problem_of(rosenbrock, 2), fbia.SerialEvaluator())
    states = [next(gen) for _ in range(4)]
    assert all(isinstance(s, LMState) for s in states)
    assert [s.round for s in states] == [1, 2, 3, 4]
    assert states[-1].nfev > states[0].nfev == 3
    assert "err_res" in str(states[-1])
    result = it.stop(gen)
    assert result.status == "stopped" and not result.success
    assert result.x == states[-1].chains[0]["x"]
    assert it.result is result


def test_stop_before_the_first_step_and_after_the_end():
    it = fbia.iterator("levenberg_marquardt", x0={"x0": -1.2, "x1": 1.0})
    result = it.stop(it.steps(problem_of(rosenbrock, 2), fbia.SerialEvaluator()))
    assert result.status == "stopped" and result.nfev == 0
    gen = it.steps(problem_of(rosenbrock, 2), fbia.SerialEvaluator())
    for _ in gen:
        pass
    done = it.result
    assert it.stop(gen) is done and done.success  # a finished run keeps its result


def test_run_drains_the_generator_to_the_same_result():
    it = fbia.iterator("levenberg_marquardt", x0={"x0": -1.2, "x1": 1.0}, gtol=0)
    a = it.run(problem_of(rosenbrock, 2))
    gen = it.steps(problem_of(rosenbrock, 2), fbia.SerialEvaluator())
    for _ in gen:
        pass
    assert it.result.x == a.x and it.result.nfev == a.nfev


def test_max_nfev_ends_the_run_with_the_best_point_so_far():
    result = fbia.least_squares(rosenbrock, [-1.2, 1.0], max_nfev=10)
    assert result.status == "evaluation_limit" and not result.success
    assert 10 <= result.nfev < 13
    assert result.x is not None and result.err_res < math.sqrt(24.2 / 2)


def test_iteration_limit():
    result = fbia.least_squares(rosenbrock, [-1.2, 1.0], max_iter=2)
    assert result.status == "iteration_limit" and result.iterations == 2


def test_registry_and_lazy_least_squares():
    it = fbia.iterator("levenberg_marquardt", mode="paper", x0={"E": 1.0})
    assert isinstance(it, LevenbergMarquardtIterator) and it.options.mode == "paper"
    from fbia.iterators.least_squares import least_squares

    assert fbia.least_squares is least_squares


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"ftol": 1e-3, "mode": "paper"}, "apply to mode='robust' only"),
        ({"mu_limit": 1e3}, "applies to mode='paper' only"),
        ({"muu0": 1.0}, "unknown option 'muu0'; valid options: agree_rtol, alpha"),
        ({"beta": -1.0}, "option 'beta'"),
        ({"alpha": 0.0, "beta": 0.0}, "no finite-difference step"),
        ({"x0": []}, "empty list"),
    ],
)
def test_bad_options_are_config_errors(options, message):
    with pytest.raises(fbia.ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        fbia.iterator("levenberg_marquardt", **options)


@pytest.mark.parametrize(
    ("x0", "message"),
    [
        ({"x0": 1.0}, r"levenberg_marquardt.x0: no value for parameter\(s\) x1"),
        ({"x0": 1.0, "x1": 1.0, "E": 2.0}, r"unknown parameter\(s\) E; valid: x0, x1"),
        ([{"x0": 1.0, "x1": 1.0}, {"x0": 5.0, "x1": 1.0}], r"x0\[1\]: initial guess x0 = 5.0"),
    ],
)
def test_bad_initial_guesses_are_config_errors(x0, message):
    it = fbia.iterator("levenberg_marquardt", x0=x0)
    with pytest.raises(fbia.ConfigError, match=message):
        it.run(problem_of(rosenbrock, 2, lower=-2.0, upper=2.0))


def test_least_squares_argument_errors():
    with pytest.raises(fbia.ConfigError, match="bounds need lower < upper"):
        fbia.least_squares(decay, [1.0, 1.0], bounds=([0.0, 2.0], [1.0, 1.0]))
    with pytest.raises(fbia.ConfigError, match="lies outside the bounds"):
        fbia.least_squares(decay, [1.0, 1.0], bounds=(0.0, 0.5))
    with pytest.raises(fbia.ConfigError, match="names must be 2 distinct names"):
        fbia.least_squares(decay, [1.0, 1.0], names=["a"])
    with pytest.raises(fbia.ConfigError, match="changed length from 2 to 3"):
        fbia.least_squares(lambda b: np.ones(2 if b[0] == 1.0 else 3), [1.0])


def test_a_residual_function_bug_propagates():
    def buggy(b):
        raise KeyError("oops")

    with pytest.raises(KeyError):
        fbia.least_squares(buggy, [1.0])


# -- plots -----------------------------------------------------------------------------------------
def test_plots_two_parameters(tmp_path):
    result = fbia.least_squares(decay, [[1.0, 1.0], [5.0, 0.2]], names=["a", "k"])
    files = LevenbergMarquardtIterator().write_plots(result, None, tmp_path)
    assert sorted(f.name for f in files) == ["lm_errors.png", "lm_search_paths.png"]
    assert all(f.stat().st_size > 10_000 for f in files)


def test_plots_three_parameters(tmp_path):
    X = np.column_stack([np.ones_like(T), T, np.exp(-T)])
    result = fbia.least_squares(lambda b: X @ b - Y, [0.0, 0.0, 0.0])
    from fbia.iterators.lm.plots import plot_lm_result

    files = plot_lm_result(result, None, tmp_path / "out")
    assert sorted(f.name for f in files) == ["lm_errors.png", "lm_parameter_paths.png"]


@pytest.mark.parametrize(
    "module",
    [
        "fbia.iterators.lm.robust",
        "fbia.iterators.levenberg_marquardt",
    ],
)
def test_module_docstring_recipes_run(module):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
