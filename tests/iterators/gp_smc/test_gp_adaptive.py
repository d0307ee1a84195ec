"""The adaptive design of gp_smc (issue 16, item 1): its pieces, and the 2-D target against the
exact posterior by quadrature."""

import math
from dataclasses import replace

import numpy as np
import pytest
from test_gp_smc import _problem

import fbia
from fbia.core.likelihood import gaussian_log_likelihood, measurement_count, noise_levels
from fbia.iterators.gp_smc.adaptive import (
    centred_rmse,
    floor_depth,
    posterior_change,
    select_batch,
    soft_floor,
)
from fbia.iterators.gp_smc.adaptive_loop import REOPTIMISE_GROWTH
from fbia.iterators.gp_smc.result import GpSmcResult, PosteriorCheck
from fbia.iterators.gp_smc.run import log_prior
from fbia.iterators.smc.sampler import SmcResult, smc
from fbia.iterators.surrogates.gp import GpSurrogate
from fbia.studies.result_io import from_dict


# -- the pieces -------------------------------------------------------------------------------
def test_soft_floor_keeps_l_above_and_the_order_below():
    y = np.array([-1e6, -500.0, -30.0, -21.0, -20.0, -3.0, 0.0])
    w = soft_floor(y, -20.0)
    np.testing.assert_array_equal(w[-3:], y[-3:])
    assert np.all(np.diff(w) > 0)  # still increasing: the ranking of runs is kept
    assert w[0] == pytest.approx(-20.0 - math.log1p(1e6 - 20.0))  # -33.8: the range collapses


def test_floor_is_deep_enough_for_the_evidence():
    # no evidence yet: the minimum depth; a concentrated posterior (log Z far below L_max)
    # pushes the floor down so that the floored region holds < 1e-3 of Z
    assert floor_depth(0.0, None) == 20.0
    assert floor_depth(10.0, -40.0) == pytest.approx(50.0 + math.log(1e3))


def _gaussian_particles(n=200_000, seed=0):
    """Equally weighted draws of N(0, 1) x N(5, 2^2) whose stored target is 0."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.standard_normal(n), 5.0 + 2.0 * rng.standard_normal(n)])
    return SmcResult(
        particles=x,
        weights=np.full(n, 1.0 / n),
        log_likelihood=np.zeros(n),
        log_prior=np.zeros(n),
        log_evidence=-1.0,
        log_evidence_se=0.0,
        gammas=[0.0, 1.0],
        ess=[float(n)],
        acceptance=[0.0],
        nfev=0,
        names=["a", "b"],
    )


def test_posterior_change_is_measured_on_the_same_particles():
    post = _gaussian_particles()
    # the same target: nothing moved, exactly (no Monte Carlo noise between two runs)
    same, change = posterior_change(post, lambda z: np.zeros(len(z)))
    assert (change.mean_shift, change.std_change, change.quantile_shift) == (0.0, 0.0, 0.0)
    assert change.evidence_change == pytest.approx(0.0, abs=1e-12)
    assert change.ess_fraction == pytest.approx(1.0) and change.settled(0.1)
    assert same.log_evidence == pytest.approx(-1.0)
    # a refit that tilts the target by 0.2 a: N(0, 1) e^(0.2 a) is N(0.2, 1): the mean of a
    # moves 0.2 std (Monte Carlo error ~ 1 / sqrt(n) = 0.002), its std and b stay, and log Z
    # changes by log E e^(0.2 a) = 0.02
    tilted, change = posterior_change(post, lambda z: 0.2 * z[:, 0])
    assert change.mean_shift == pytest.approx(0.2, abs=0.01)
    assert change.quantile_shift == pytest.approx(0.2, abs=0.02)
    assert change.std_change < 0.01 and change.evidence_change == pytest.approx(0.02, abs=0.005)
    assert not change.settled(0.1) and change.settled(0.25)
    np.testing.assert_allclose(tilted.log_likelihood, 0.2 * post.particles[:, 0])
    # a refit under which the particles no longer describe the posterior is never settled
    _, far = posterior_change(post, lambda z: 3.0 * z[:, 0])
    assert far.ess_fraction < 0.5 and not far.settled(1e9)


def test_a_constant_error_cancels_in_the_check():
    # errors 2 +- 0.1: RMSE 2, but exp(mu) is exp(L) times e^2 up to +-0.1: the same posterior
    err = 2.0 + 0.1 * np.array([1.0, -1.0, 0.5, -0.5, 0.0, 1.0, -1.0, 0.0])
    assert centred_rmse(err) == pytest.approx(float(np.std(err, ddof=1)))
    check = PosteriorCheck(
        n=8,
        n_failed=0,
        x=np.zeros((8, 2)),
        log_likelihood=np.zeros(8),
        rmse=float(np.sqrt(np.mean(err**2))),
        max_abs=float(np.max(np.abs(err))),
        mean_error=float(np.mean(err)),
    )
    assert check.rmse > 1.9 and check.centred_rmse == pytest.approx(centred_rmse(err))
    assert check.reliable and "which cancels" in check.note()
    spread = replace(check, mean_error=0.0)  # the same RMSE as spread: not reliable
    assert not spread.reliable and "not reliable" in spread.note()
    assert not replace(check, n=1).reliable  # one draw measures no spread


def test_batch_picks_distinct_points_near_the_posterior_where_the_gp_is_unsure():
    # (bounds without a prior give the uniform prior on them)
    params = [fbia.Parameter("a", bounds=(0.0, 1.0)), fbia.Parameter("b", bounds=(0.0, 1.0))]

    def exact(z):
        return -0.5 * (((z[:, 0] - 0.6) / 0.05) ** 2 + ((z[:, 1] - 0.3) / 0.08) ** 2)

    rng = np.random.default_rng(0)
    x = rng.random((25, 2))
    gp = GpSurrogate(ard=True).fit(x, exact(x), rng=0)
    post = smc(gp.predict_mean, [p.prior for p in params], n_particles=1000, zeta=0.9, seed=0)
    batch, n_draws = select_batch(
        gp, post, 8, params, lambda z: log_prior(params, z), np.random.default_rng(1)
    )
    assert batch.shape == (8, 2) and n_draws == 4
    assert len(np.unique(batch.round(12), axis=0)) == 8
    assert np.all((batch >= 0.0) & (batch <= 1.0))
    # the criterion's picks lie where the posterior is (within a few posterior std of it)
    picks = batch[n_draws:]
    z = np.abs(picks - post.mean) / np.sqrt(np.diag(post.cov))
    assert np.all(z < 6.0)
    # and where the GP is less sure than at the posterior draws
    assert gp.predict(picks)[1].mean() > gp.predict(batch[:n_draws])[1].mean()


def _dense_greedy_eiv(gp, integ, cand, n, log_prior):
    """The greedy EIV batch of adaptive.py written with the full covariance matrices (the
    rule of Jarvenpaa et al. 2019 with the kriging-believer update, as first implemented)."""
    mu, s2 = gp.predict(integ)
    log_w = mu + s2 + log_prior(integ)
    log_w -= log_w.max()
    c_ic = gp.posterior_covariance(integ, cand)
    c_cc = gp.posterior_covariance(cand, cand)
    picked = []
    for _ in range(n):
        s2_c = np.maximum(np.diag(c_cc), 0.0)
        tau2 = c_ic**2 / (s2_c + gp.nugget)[None, :]
        gain = np.exp(log_w)[:, None] * np.expm1(tau2)
        score = np.log(gain.sum(axis=0) + 1e-300)
        score[picked] = -np.inf
        best = int(np.argmax(score))
        picked.append(best)
        row, denom = c_cc[best].copy(), s2_c[best] + gp.nugget
        c_ic = c_ic - np.outer(c_ic[:, best], row) / denom
        c_cc = c_cc - np.outer(row, row) / denom
    return picked


def test_greedy_eiv_with_blocks_on_demand_picks_as_with_full_matrices():
    """The EIV batch forms only the blocks it needs (issue 42: the candidates' full block
    was most of its cost); it picks the same candidates, in the same order, as the dense
    algorithm."""
    from fbia.iterators.gp_smc.adaptive import _greedy_eiv

    params = [fbia.Parameter("a", bounds=(0.0, 1.0)), fbia.Parameter("b", bounds=(0.0, 1.0))]

    def exact(z):
        return -0.5 * (((z[:, 0] - 0.6) / 0.05) ** 2 + ((z[:, 1] - 0.3) / 0.08) ** 2)

    rng = np.random.default_rng(2)
    x = rng.random((30, 2))
    gp = GpSurrogate(ard=True).fit(x, exact(x), rng=0)
    integ, cand = rng.random((60, 2)), rng.random((80, 2))

    def lp(z):
        return log_prior(params, z)

    picks = _greedy_eiv(gp, integ, cand, 10, lp)
    reference = _dense_greedy_eiv(gp, integ, cand, 10, lp)
    np.testing.assert_array_equal(picks, cand[reference])


# -- the 2-D target (E, nu): <= 100 runs, means within 0.3 std, std within a factor 1.5 ----------
# 20 Pa and 0.04 apart: the posterior is broad (std 97 Pa, 0.076), so this grid's mean and std
# are within 0.003 std and 0.5 % of a grid twice as fine each way (71 x 66 points; measured),
# far below the target's 0.3 std and factor 1.5, at a quarter of the forward runs
E_GRID = np.linspace(100.0, 800.0, 36)
NU_GRID = np.linspace(-0.8, 0.5, 33)


@pytest.fixture(scope="module")
def exact_2d():
    """The exact posterior of the 2-D problem by quadrature on a grid of forward runs (uniform
    priors: posterior ~ exp(L))."""
    problem = _problem()
    sig, count = noise_levels(problem), measurement_count(problem)
    ee, nn = np.meshgrid(E_GRID, NU_GRID, indexing="ij")
    loglik = np.array(
        [
            gaussian_log_likelihood(problem.evaluate({"E": e, "nu": n}), sig, count)
            for e, n in zip(ee.ravel(), nn.ravel(), strict=True)
        ]
    ).reshape(ee.shape)
    w = np.exp(np.where(np.isfinite(loglik), loglik - np.nanmax(loglik), -np.inf))
    w /= w.sum()
    mean = np.array([np.sum(w * ee), np.sum(w * nn)])
    std = np.sqrt(np.array([np.sum(w * (ee - mean[0]) ** 2), np.sum(w * (nn - mean[1]) ** 2)]))
    return problem, mean, std


def test_adaptive_design_meets_the_2d_target(exact_2d):
    problem, mean, std = exact_2d
    it = fbia.iterator("gp_smc", n_train=92, n_particles=3000, n_rejuvenation=8, zeta=0.95)
    result = it.run(problem)
    assert result.status == "completed" and result.nfev <= 100
    assert result.adaptive is not None and result.adaptive.converged
    assert "adaptive design converged" in result.message
    got_std = np.sqrt(np.diag(result.posterior.cov))
    assert np.all(np.abs(result.posterior.mean - mean) < 0.3 * std)
    assert np.all((got_std < 1.5 * std) & (got_std > std / 1.5))
    # the rounds are reported, each with the error at its new posterior draws
    rounds = result.adaptive.rounds
    assert rounds and rounds[-1].validation_centred < 0.5
    assert [r.n_runs for r in rounds] == sorted(r.n_runs for r in rounds)
    assert result.to_dict()["info"]["adaptive"]["stop_reason"] == "converged"
    # the hyperparameters are optimised in the first round and again only once the design
    # has grown by REOPTIMISE_GROWTH since they last were
    last = None
    for r in rounds:
        assert r.optimised == (last is None or r.n_runs >= REOPTIMISE_GROWTH * last)
        last = r.n_runs if r.optimised else last
    # converged: the last batch moved the last posterior by less than adaptive_tol (0.1 std),
    # measured on its own particles
    change = result.adaptive.final_change
    assert change is not None and change.settled(0.1)
    back = from_dict(GpSmcResult, result.to_dict())  # result.json keeps the measures
    assert back.adaptive.final_change == change


def test_a_budget_too_small_to_converge_is_said(exact_2d):
    problem, _, _ = exact_2d
    result = fbia.iterator(
        "gp_smc", n_train=24, n_initial=20, n_particles=500, n_rejuvenation=3, zeta=0.9
    ).run(problem)
    assert result.adaptive.stop_reason == "budget"
    assert "did not converge within n_train runs" in result.message


def test_posterior_axes_meet_the_2d_target_and_need_an_adaptive_design(exact_2d):
    """gp_axes = "posterior": from the second round the kernel's axes follow the last round's
    posterior covariance (GpSurrogate.fit's axes); the same target as the input axes."""
    problem, mean, std = exact_2d
    opts = {"n_train": 92, "n_particles": 3000, "n_rejuvenation": 8, "zeta": 0.95, "ard": True}
    result = fbia.iterator("gp_smc", gp_axes="posterior", **opts).run(problem)
    assert result.status == "completed" and result.adaptive.converged
    state = result.surrogate.state  # a GP of L, or a residual emulator's component GPs
    assert all("rotation" in gp for gp in state.get("components", [state]))
    got_std = np.sqrt(np.diag(result.posterior.cov))
    assert np.all(np.abs(result.posterior.mean - mean) < 0.3 * std)
    assert np.all((got_std < 1.5 * std) & (got_std > std / 1.5))
    with pytest.raises(fbia.ConfigError, match="design = 'adaptive'"):
        fbia.iterator("gp_smc", gp_axes="posterior", design="sobol", n_train=8).run(problem)


def test_a_failed_check_is_repaired_with_its_runs_within_the_budget(exact_2d, monkeypatch):
    """issue 30: a check at posterior draws that fails adds its runs to the adaptive design,
    the surrogate is refitted and a fresh check drawn, at most check_repairs times; only the
    last check decides the status."""
    import fbia.iterators.gp_smc.result as result_module

    problem, _, _ = exact_2d
    opts = {"n_train": 200, "n_particles": 400, "n_rejuvenation": 3, "zeta": 0.9}
    opts["round_particles"] = 400
    # as it comes: each failed check costs n_check runs more, at most two
    plain = fbia.iterator("gp_smc", **opts).run(problem)
    failed = len(plain.failed_checks)
    assert f"{failed} repair(s)" in plain.message or not failed
    with monkeypatch.context() as patch:
        patch.setattr(result_module, "RELIABLE_RMSE", 0.0)  # every check fails
        once = fbia.iterator("gp_smc", check_repairs=0, **opts).run(problem)
        repaired = fbia.iterator("gp_smc", **opts).run(problem)
    assert plain.nfev == once.nfev + 8 * failed
    assert plain.status == "completed"  # the 2-D posterior is easy; after a repair if need be
    # check_repairs = 0: the first failed check decides
    assert once.status == "unreliable" and once.failed_checks == []
    assert "repair(s)" not in once.message
    n_design = int(once.design.train_mask.sum())
    assert n_design + 16 <= 200  # room for two repairs
    assert repaired.status == "unreliable" and len(repaired.failed_checks) == 2
    back = from_dict(GpSmcResult, repaired.to_dict())  # result.json keeps them
    assert back.failed_checks == repaired.failed_checks
    assert "2 repair(s)" in repaired.message
    assert repaired.nfev == once.nfev + 16
    # the failed checks' runs trained the last surrogate, the first of them once's check
    assert int(repaired.design.train_mask.sum()) == n_design + 16
    np.testing.assert_array_equal(repaired.design.points[n_design : n_design + 8], once.check.x)
    # the last check's draws are fresh: none of them is a training run
    last = repaired.check.x
    assert not any(np.any(np.all(repaired.design.points == row, axis=1)) for row in last)


def test_sample_paths_that_move_the_posterior_are_repaired_with_runs(exact_2d, monkeypatch):
    """issue 42: when the GP's sample paths move the posterior (forced here, the rounds left
    alone), runs at draws of the averaged posterior join the design, at most check_repairs
    times, and the status stays unreliable while they still move it; with no room for a
    repair (check_repairs = 0) no such runs are made at all."""
    import fbia.iterators.gp_smc.adaptive_loop as loop_module
    import fbia.iterators.gp_smc.result as result_module
    from fbia.iterators.gp_smc.iterator import GpSmcIterator
    from fbia.iterators.surrogates.uncertainty import SurrogateUncertainty

    problem, _, _ = exact_2d
    opts = {"n_train": 200, "n_particles": 400, "n_rejuvenation": 3, "zeta": 0.9}
    opts["round_particles"] = 400
    plain = fbia.iterator("gp_smc", **opts).run(problem)
    assert plain.status == "completed" and not plain.uncertainty.moves_posterior
    fit_gp, fitted = GpSmcIterator._fit_gp, []

    def spy(self, run, x, y, start, records, *args):  # the points and records of every fit
        fitted.append((np.array(x), [[ev.x[n] for n in run.names] for ev in records]))
        return fit_gp(self, run, x, y, start, records, *args)

    with monkeypatch.context() as patch:
        patch.setattr(loop_module, "_gp_unsure", lambda *args: False)  # the rounds as before
        patch.setattr(SurrogateUncertainty, "moves_posterior", property(lambda self: True))
        patch.setattr(result_module, "RELIABLE_RMSE", 1e9)  # every check passes: only paths
        none = fbia.iterator("gp_smc", check_repairs=0, **opts).run(problem)
        patch.setattr(GpSmcIterator, "_fit_gp", spy)
        repaired = fbia.iterator("gp_smc", **opts).run(problem)
    # one run, one record (issue 48): every fit, the refits after the repairs too, trains on
    # the records of its own points (a repair's, not the passed check's before it)
    assert len(fitted) >= 3
    for x, at in fitted:
        np.testing.assert_array_equal(np.array(at), x)
    assert none.status == "unreliable" and none.failed_checks == []
    assert none.nfev == plain.nfev - 8 * len(plain.failed_checks)  # no runs at its draws
    assert repaired.status == "unreliable" and len(repaired.failed_checks) == 2
    assert "2 repair(s)" in repaired.message
    # each repair: 8 runs at draws of the averaged posterior + a fresh check of 8
    assert repaired.nfev == none.nfev + 2 * 16
    assert int(repaired.design.train_mask.sum()) == int(none.design.train_mask.sum()) + 16
