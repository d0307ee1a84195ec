"""The gp_smc iterator (Paper B): likelihood, design, failed runs, the analytic mound."""

import math

import numpy as np
import pytest
from _paths import ROOT

import fbia
from fbia.core.likelihood import gaussian_log_likelihood as log_likelihood_of
from fbia.core.likelihood import measurement_count
from fbia.iterators.gp_smc.iterator import GpSmcIterator
from fbia.iterators.gp_smc.posterior import (
    laplace_approximation,
    load_posterior,
    map_by_binning,
    save_posterior,
)
from fbia.iterators.surrogates.design import sobol_design

TRUTH = {"E": 400.0, "nu": 0.3}
# Paper B's fixed Sobol design (the adaptive default is tested in test_gp_adaptive.py)
FAST = {"n_particles": 1000, "n_rejuvenation": 5, "zeta": 0.9, "seed": 0, "design": "sobol"}


def _parameters():
    return [
        fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
        fbia.Parameter("nu", bounds=(-0.8, 0.5)),
    ]


def _inflow():
    # Paper B Fig. 10: V_in ~ Beta(2.6, 1.4) on [0, 110] mm^2/s, mode 88 mm^2/s.
    return fbia.Parameter("inflow_rate", unit="mm^2/s", prior=fbia.priors.beta(2.6, 1.4, 0, 110))


def _problem(theta=False, noise_std=0.03, **model_options):
    model = fbia.forward_model("analytic_mound_2d", n_points=41, **model_options)
    # The observed state has an empty coordinate: the inflow rate is a model input, fixed at
    # its true value or uncertain (theta).
    clean = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(
        clean, {**TRUTH, "inflow_rate": 100.0}, [{}], noise_std=0.0, seed=0
    )
    extra = {"uncertain": [_inflow()]} if theta else {"fixed": {"inflow_rate": 100.0}}
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("rkhs", sigma_w=0.05),
        observations=obs,
        noise_std=noise_std,
        parameters=_parameters(),
        **extra,
    )


@pytest.fixture(scope="module")
def runs():
    out = {}
    for theta in (False, True):
        problem = _problem(theta)
        it = fbia.iterator("gp_smc", n_train=256, n_test=32, **FAST)
        out[theta] = (problem, it.run(problem), it)
    return out


# -- the pieces ---------------------------------------------------------------------------------
def test_gaussian_static_log_likelihood_is_eq_5():
    ev = fbia.Evaluation(index=0, x={}, residuals=np.array([0.01, -0.02, 0.005]), distances=[0.03])
    sigma = 0.01
    expected = -1.5 * math.log(2 * math.pi * sigma**2) - 0.03**2 / (2 * sigma**2)
    assert log_likelihood_of(ev, [sigma]) == pytest.approx(expected, rel=1e-14)
    # Two observations with their own noise: sum of eq. 5 per observation (n split evenly).
    ev2 = fbia.Evaluation(index=0, x={}, residuals=np.zeros(4), distances=[0.03, 0.04])
    expected2 = (
        -1.0 * math.log(2 * math.pi * 0.01**2)
        - 0.03**2 / (2 * 0.01**2)
        - 1.0 * math.log(2 * math.pi * 0.02**2)
        - 0.04**2 / (2 * 0.02**2)
    )
    assert log_likelihood_of(ev2, [0.01, 0.02]) == pytest.approx(expected2, rel=1e-14)
    failed = fbia.Evaluation(index=1, x={}, status="failed", message="mesh distortion")
    assert log_likelihood_of(failed, [sigma]) == -math.inf


def test_sobol_design_extends_by_the_next_points_of_the_same_sequence():
    params = [*_parameters(), _inflow(), fbia.Parameter("g", prior=fbia.priors.normal(1, 2))]
    small = sobol_design(params, 16, seed=3)
    large = sobol_design(params, 48, seed=3)
    np.testing.assert_array_equal(large[:16], small)
    np.testing.assert_array_equal(large[16:], sobol_design(params, 32, seed=3, start=16))
    assert np.all((large[:, 0] >= 100) & (large[:, 0] <= 800))
    assert np.all((large[:, 2] >= 0) & (large[:, 2] <= 110))
    # An unbounded theta goes through its prior: the design mean approaches the prior mean.
    assert sobol_design(params, 1024, seed=3)[:, 3].mean() == pytest.approx(1.0, abs=0.02)
    # Through the prior (Remark 7): the beta-distributed inflow is denser near its mode.
    through = sobol_design(params, 1024, seed=3, through_prior=True)[:, 2]
    assert through.mean() == pytest.approx(110 * 2.6 / 4.0, abs=1.0)


def test_map_by_binning_finds_the_heaviest_bin():
    rng = np.random.default_rng(0)
    x = np.r_[rng.uniform(0, 10, size=(4000, 2)), rng.normal([7.2, 2.2], 0.05, size=(500, 2))]
    w = np.full(len(x), 1.0 / len(x))
    params = [fbia.Parameter("a", bounds=(0, 10)), fbia.Parameter("b", bounds=(0, 10))]
    found = map_by_binning(x, w, params, bins=20)
    np.testing.assert_allclose(found.x, [7.25, 2.25])
    # a peak of 500 particles in one cell against ~10 a cell: every resampling keeps it
    assert found.support.tolist() == [1.0, 1.0] and found.cell_support == 1.0


def test_the_histogram_map_says_where_the_particles_do_not_decide_it():
    # the exact posterior is known: a is sharp (N(7.2, 0.05)), b uniform on its prior; the
    # heaviest cell's interval of a is the truth's, that of b is Monte Carlo noise
    rng = np.random.default_rng(1)
    n = 10_000
    x = np.c_[rng.normal(7.2, 0.05, n), rng.uniform(0, 10, n)]
    w = np.full(n, 1.0 / n)
    params = [fbia.Parameter("a", bounds=(0, 10)), fbia.Parameter("b", bounds=(0, 10))]
    found = map_by_binning(x, w, params, bins=10, seed=3)
    assert found.x[0] == 7.5 and found.support[0] == 1.0
    assert found.support[1] < 0.5 and found.cell_support < 0.5  # 10 equal cells in b
    again = map_by_binning(x, w, params, bins=10, seed=3)  # seeded: reproducible
    assert again.support.tolist() == found.support.tolist()
    # weights count, not particles: the same uniform cloud weighted towards b in [2, 3)
    tilted = np.where((x[:, 1] >= 2) & (x[:, 1] < 3), 3.0, 1.0)
    found = map_by_binning(x, tilted / tilted.sum(), params, bins=10)
    assert found.x[1] == 2.5 and found.support.tolist() == [1.0, 1.0]


def test_laplace_approximation_of_a_gaussian_is_exact():
    cov = np.array([[4.0, 1.2], [1.2, 0.9]])
    prec = np.linalg.inv(cov)
    mu = np.array([1.0, -2.0])

    def log_post(z):
        d = z - mu
        return -0.5 * np.einsum("ni,ij,nj->n", d, prec, d)

    lap = laplace_approximation(log_post, mu.copy(), cov)
    assert lap.negative_definite
    np.testing.assert_allclose(lap.cov, cov, rtol=1e-6)


# -- the analytic mound (Paper B Fig. 9a and 9d behaviour) ----------------------------------------
def test_map_near_ground_truth_and_surrogate_accurate(runs):
    problem, result, it = runs[False]
    assert result.success and result.status == "completed"
    assert result.nfev == 256 + 32 + 8 and result.n_failed == 0  # design, test, check
    assert abs(result.x["E"] - 400.0) < 20.0 and abs(result.x["nu"] - 0.3) < 0.03
    gp = result.surrogate.summary
    assert gp["loo_relative_l2"] < 0.05 and gp["test_relative_l2"] < 0.05
    assert gp["test_n"] == 32
    # The Laplace approximation exists at the MAP and is a proper Gaussian.
    assert result.posterior.laplace.negative_definite


def test_posterior_band_follows_the_e_nu_coupling(runs):
    problem, result, _ = runs[False]
    cov = result.posterior.cov
    corr = cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1])
    assert abs(corr) > 0.5
    # Along the posterior's long axis the forward model changes much less than across it:
    # the band lies along a direction of (near) non-identifiability of E and nu.
    width = problem.upper - problem.lower
    vals, vecs = np.linalg.eigh(cov / np.outer(width, width))
    along, across = vecs[:, 1] * width, vecs[:, 0] * width
    x_map = np.array([result.x["E"], result.x["nu"]])

    def dist(step):
        return problem.evaluate(dict(zip(problem.names, x_map + step, strict=True))).distance

    assert dist(0.03 * along) < 0.5 * dist(0.03 * across)
    assert vals[1] > 3 * vals[0]


def test_uncertain_inflow_widens_the_posterior(runs):
    _, plain, _ = runs[False]
    problem, under, _ = runs[True]
    assert plain.status == "completed"
    # A fixed Sobol design of 256 points in 3-D: a GP of L does not resolve L where this
    # posterior is (surrogate RMSE about 1 in L at posterior draws, status "unreliable"); the
    # default residual emulator does (issue 16)
    assert under.status == "completed" and under.success
    assert under.surrogate.summary["surrogate"] == "residuals"
    assert under.check.rmse < 0.5
    paper = fbia.iterator("gp_smc", n_train=256, n_test=32, surrogate="log_likelihood", **FAST)
    assert paper.run(problem).status == "unreliable"  # and it says so
    assert under.names == ["E", "nu", "inflow_rate"]
    assert under.posterior.particles.shape == (1000, 3)
    det_plain = np.linalg.det(plain.posterior.cov)
    det_under = np.linalg.det(under.posterior.cov)
    assert math.sqrt(det_under) > 1.2 * math.sqrt(det_plain)
    assert under.posterior.std[0] > plain.posterior.std[0]
    # Less inflow on average than in the data (mean 71.5 mm^2/s < 100): a softer biofilm
    # explains the deformation, so MAP and mean move to lower E (Paper B Fig. 9d).
    assert under.x["E"] < plain.x["E"] - 50.0
    assert under.posterior.mean[0] < plain.posterior.mean[0] - 50.0
    assert "histogram" in under.posterior.map_method and under.posterior.laplace is None
    support = under.posterior.map_support  # per x; the message names the undetermined ones
    assert support.shape == (2,) and plain.posterior.map_support is None
    for name, s in zip(["E", "nu"], support, strict=True):
        assert (f"map.{name}" in under.undetermined()) == (s < 0.9)
        assert (f" {name} ({s * 100:.0f} %)" in under.message) == (s < 0.9)


def test_failed_runs_are_excluded_from_training_and_reported():
    # Soft biofilms fail (mesh distortion in the FSI model, Paper B Fig. 5-8).
    problem = _problem(failure_region={"E": (100.0, 200.0)})
    result = fbia.iterator("gp_smc", n_train=64, **FAST).run(problem)
    design = result.design.points
    expected_failed = int(np.sum(design[:, 0] <= 200.0))
    assert expected_failed > 0
    assert result.success and result.n_failed == expected_failed
    failed = [ev for ev in result.evaluations if not ev.ok]
    assert len(failed) == expected_failed and all(ev.status == "failed" for ev in failed)
    assert all("mesh distortion" in ev.message for ev in failed)
    assert result.surrogate.summary["n_train"] == 64 - expected_failed
    assert abs(result.x["E"] - 400.0) < 40.0


def test_all_runs_failed_is_an_outcome_not_an_exception():
    problem = _problem(failure_region={"E": (0.0, 1000.0)})
    result = fbia.iterator("gp_smc", n_train=8, **FAST).run(problem)
    assert result.status == "all_failed" and not result.success
    assert result.n_failed == 8 and "8 of 8 forward runs failed" in result.message


def test_direct_mode_agrees_with_the_surrogate():
    problem = _problem(noise_std=0.05, failure_region={"E": (100.0, 120.0)})
    opts = {"n_particles": 100, "n_rejuvenation": 1, "zeta": 0.5, "seed": 1}
    direct = fbia.iterator("gp_smc", mode="direct", **opts).run(problem)
    assert direct.success and direct.nfev >= 100 and len(direct.evaluations) == direct.nfev
    # Every forward run SMC asked for is counted; the prior draws with E <= 120 Pa failed.
    assert direct.nfev == direct.smc.nfev_log_likelihood and direct.n_failed > 0
    surrogate = fbia.iterator("gp_smc", n_train=128, **{**opts, "n_particles": 1000}).run(problem)
    for j in range(2):
        std = surrogate.posterior.std[j]
        diff = direct.posterior.mean[j] - surrogate.posterior.mean[j]
        assert abs(diff) < 0.6 * std


def test_posterior_files_round_trip(runs, tmp_path):
    _, result, _ = runs[True]
    npz, js = save_posterior(result, tmp_path)
    data = load_posterior(tmp_path)
    assert data["names"] == ["E", "nu", "inflow_rate"] and int(data["n_x"]) == 2
    np.testing.assert_array_equal(data["particles"], result.posterior.particles)
    np.testing.assert_allclose(data["weights"].sum(), 1.0)
    np.testing.assert_array_equal(data["theta"], result.posterior.particles[:, 2:])
    np.testing.assert_allclose(data["log_posterior"], result.posterior.log_posterior)
    assert data["design"].shape == (288, 3) and data["train_mask"].sum() == 256
    meta = data["meta"]
    assert meta["x_map"] == result.x and meta["gp"]["kernel"] == "matern32"
    assert math.isfinite(meta["log_evidence"])
    # The whole Result is JSON too.
    assert result.save(tmp_path / "result.json").stat().st_size > 0


def test_options_are_validated():
    with pytest.raises(fbia.ConfigError, match=r"unknown option 'n_trian'"):
        fbia.iterator("gp_smc", n_trian=10)
    with pytest.raises(fbia.ConfigError, match=r"option 'zeta'"):
        GpSmcIterator(zeta=1.5)
    problem = _problem()
    problem.noise_std = None
    with pytest.raises(fbia.ConfigError, match=r"has no noise_std and the problem has none"):
        fbia.iterator("gp_smc", n_train=4, **FAST).run(problem)


def test_steps_yield_every_stage():
    problem = _problem()
    it = fbia.iterator("gp_smc", n_train=16, **FAST)
    stages = [state.stage for state in it.steps(problem, fbia.SerialEvaluator())]
    assert stages[:3] == ["design", "forward_runs", "surrogate"]
    assert set(stages[3:-1]) == {"smc"} and stages[-1] == "check"


def test_arviz_reads_the_posterior(runs, tmp_path):
    arviz = pytest.importorskip("arviz")
    _, result, _ = runs[True]
    save_posterior(result, tmp_path)
    from fbia.iterators.gp_smc.posterior import to_inference_data

    idata = to_inference_data(load_posterior(tmp_path))
    assert isinstance(idata, arviz.InferenceData)
    assert set(idata.posterior.data_vars) == {"E", "nu", "inflow_rate"}
    assert set(idata.sample_stats.data_vars) == {"lp", "log_prior", "weight"}
    assert set(idata.log_likelihood.data_vars) == {"L"}
    # SMC ends with a resampling at gamma = 1: the particles are the draws, ArviZ's mean is
    # the summary's weighted mean
    assert float(idata.posterior["E"].mean()) == pytest.approx(result.posterior.mean[0], rel=1e-12)


def test_to_inference_data_is_a_first_class_hand_off(runs, tmp_path):
    """Issue 43 item 4: az.summary gives the summary's weighted means; the groups, units,
    versions, study and seed are there, the SMC's diagnostics in sample_stats' attributes;
    the netCDF file reads back the same."""
    arviz = pytest.importorskip("arviz")
    problem, result, _ = runs[True]
    result.provenance = {"fbia": fbia.__version__, "plugins": [{"name": "gp_smc"}],
                         "study_name": "tiny", "seed": 7}  # fmt: skip
    idata = result.to_inference_data(problem)
    groups = set(idata.groups())
    assert {"posterior", "prior", "log_likelihood", "sample_stats", "observed_data"} <= groups
    table = arviz.summary(idata, kind="stats", round_to="none")
    post = result.posterior
    for j, name in enumerate(post.names):
        assert table.loc[name, "mean"] == pytest.approx(post.mean_all[j], rel=1e-12)
    assert idata.posterior.attrs["resampled"] == 0
    assert np.allclose(idata.sample_stats["weight"], 1.0)
    assert idata.posterior["E"].attrs["units"] == "Pa"
    assert idata.posterior["inflow_rate"].attrs["units"] == "mm^2/s"
    assert idata.posterior.attrs["fbia_version"] == fbia.__version__
    assert idata.posterior.attrs["study"] == "tiny" and idata.posterior.attrs["seed"] == 7
    assert "gp_smc" in idata.posterior.attrs["plugins"]
    stats = idata.sample_stats.attrs
    assert stats["smc_tempering_steps"] == result.smc.n_steps
    assert 0 < stats["smc_final_ess"] <= len(post.weights)
    assert stats["log_evidence"] == pytest.approx(post.log_evidence)
    # the prior group holds draws of the priors: the inflow's Beta(2.6, 1.4) on [0, 110]
    assert float(idata.prior["inflow_rate"].mean()) == pytest.approx(110 * 2.6 / 4.0, rel=0.05)
    observed = idata.observed_data["interface_1"]
    assert observed.shape[-1] == 2 and observed.attrs["units"] == "mm"
    path = tmp_path / "posterior.nc"
    idata.to_netcdf(str(path))
    back = arviz.from_netcdf(str(path))
    assert float(back.posterior["E"].mean()) == pytest.approx(post.mean_all[0], rel=1e-12)
    assert back.posterior.attrs["study"] == "tiny"


def test_hpd_mass_of_map_truth_and_a_far_point(runs):
    from fbia.iterators.gp_smc.posterior import hpd_mass

    _, result, _ = runs[False]
    assert hpd_mass(result, result.x) < 0.05
    truth = hpd_mass(result, TRUTH)
    assert 0.0 <= truth < 0.5  # the ground truth lies well inside the posterior bulk
    assert hpd_mass(result, {"E": 750.0, "nu": -0.7}) > 0.99
    with pytest.raises(fbia.ConfigError, match="without uncertain parameters"):
        hpd_mass(runs[True][1], {**TRUTH, "inflow_rate": 100.0})


def test_design_extends_reusing_the_earlier_runs():
    problem = _problem(failure_region={"E": (100.0, 150.0)})
    first = fbia.iterator("gp_smc", n_train=32, n_check=0, **FAST).run(problem)
    more = fbia.iterator("gp_smc", n_train=64, n_test=8, n_check=0, **FAST).reuse(first)
    more = more.run(problem)
    # Only the 32 + 8 new points of the same Sobol sequence ran: they are the result's
    # evaluations (the framework's books); the design holds all 72 with their status.
    assert more.nfev == len(more.evaluations) == 40 and len(more.design.status) == 72
    np.testing.assert_array_equal(more.design.points[:32], first.design.points)
    assert more.design.status[:32] == first.design.status
    assert [ev.x for ev in more.evaluations] == [
        dict(zip(problem.names, map(float, x), strict=True)) for x in more.design.points[32:]
    ]
    assert more.n_failed == sum(not ev.ok for ev in more.evaluations)
    assert more.surrogate.summary["n_train"] == 64 - sum(s != "ok" for s in more.design.status[:64])
    other = fbia.iterator("gp_smc", n_train=64, **{**FAST, "seed": 5})
    with pytest.raises(fbia.ConfigError, match="not a prefix of this one"):
        other.reuse(first).run(problem)


@pytest.mark.slow
def test_fsi_bayes_example_posterior_band_contains_the_truth(tmp_path):
    """The demo's Bayes study with ale_fsi (~70 FEM runs, ~1 min): Paper B Fig. 9a behaviour.

    The ground truth lies inside the posterior bulk, the band follows the E-nu coupling and
    the failed soft runs are reported, not fatal.
    """

    from fbia.iterators.gp_smc.posterior import hpd_mass

    example = ROOT / "examples" / "flow_cell" / "study_bayes.toml"
    result = fbia.run_study(fbia.load_study(example), tmp_path / "out", echo=lambda s: None)
    assert result.success and result.adaptive.converged and 0 < result.n_failed < 20
    assert result.nfev <= 128 + 16 + 8  # the budget, the held-out points, the check
    assert result.check.rmse < 1.0  # the surrogate is right there
    assert abs(result.x["E"] - 400.0) < 60.0 and abs(result.x["nu"] - 0.3) < 0.2
    cov = np.asarray(result.posterior.cov)
    assert cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]) > 0.5
    assert hpd_mass(result, TRUTH) < 0.6
    assert hpd_mass(result, {"E": 750.0, "nu": -0.7}) > 0.99


def test_resample_move_gives_the_algorithm_1_posterior_with_fewer_calls(runs):
    problem, result, _ = runs[False]  # the default: resample-move
    it = fbia.iterator("gp_smc", n_train=256, n_test=32, **{**FAST, "rejuvenate": "every_step"})
    ref = it.run(problem)  # Algorithm 1 as printed
    smc, smc_ref = result.smc, ref.smc
    assert smc.rejuvenate == "after_resampling" and smc_ref.rejuvenate == "every_step"
    assert smc.steps_with_moves < smc.n_steps
    assert smc.nfev_log_likelihood < smc_ref.nfev_log_likelihood
    # Same design and surrogate (same seed): the posteriors agree within Monte-Carlo error
    # (two estimates, ~4 sigma, particles correlated by few moves: 6 sd / sqrt(ESS)).
    sd = np.sqrt(np.diag(ref.posterior.cov))
    diff = np.abs(np.asarray(result.posterior.mean) - ref.posterior.mean)
    np.testing.assert_array_less(diff, 6 * sd / math.sqrt(smc.final_ess))
    np.testing.assert_allclose(np.sqrt(np.diag(result.posterior.cov)), sd, rtol=0.15)


def test_posterior_check_measures_the_surrogate_where_the_posterior_is():
    problem = _problem()
    sigmas = [0.03]
    good = fbia.iterator("gp_smc", n_train=256, n_check=8, **FAST)
    result = good.run(problem)
    check = result.check
    assert check.n == 8 and check.n_failed == 0 and result.nfev == 256 + 8
    x = np.asarray(check.x)
    assert len(np.unique(x, axis=0)) == 8  # distinct draws
    # The figures are the GP mean against the exact L at those points (eq. 5).
    exact = [
        log_likelihood_of(
            problem.evaluate(dict(zip(problem.names, row, strict=True))),
            sigmas,
            measurement_count(problem),
        )
        for row in x
    ]
    err = result.surrogate.surrogate().predict_mean(x) - np.array(exact)  # the result's GP
    assert check.rmse == pytest.approx(float(np.sqrt(np.mean(err**2))), rel=1e-9)
    assert check.rmse < 0.5 and "not reliable" not in result.message
    assert (result.status, result.success) == ("completed", True)
    # Eight training runs cannot resolve the posterior: the check says so, in the status too
    # (issue 16: never a silently wrong posterior).
    poor = fbia.iterator("gp_smc", n_train=8, n_check=8, **FAST).run(problem)
    assert poor.check.rmse > 1.0 and "not reliable" in poor.message
    assert (poor.status, poor.success) == ("unreliable", False)
    # Without the check nothing vouches for the posterior: the status says that as well.
    blind = fbia.iterator("gp_smc", n_train=256, n_check=0, **FAST).run(problem)
    assert (blind.status, blind.success) == ("unchecked", False)
    assert "not checked" in blind.message


def test_the_rkhs_residual_vector_does_not_change_the_likelihood():
    """Paper B eq. 5 counts D as one measurement per observation (n_k = 1) whether the rkhs
    measure returns its residual vector (for least squares) or D alone."""
    vector, scalar = _problem(), _problem()
    scalar.measure = fbia.measure("rkhs", sigma_w=0.05, residuals="distance")
    ev_v = vector.evaluate({"E": 350.0, "nu": 0.2})
    ev_s = scalar.evaluate({"E": 350.0, "nu": 0.2})
    assert len(ev_v.residuals) > 1000 and len(ev_s.residuals) == 1
    assert measurement_count(vector) == measurement_count(scalar) == 1
    lv = log_likelihood_of(ev_v, [0.03], measurement_count(vector))
    ls = log_likelihood_of(ev_s, [0.03], measurement_count(scalar))
    assert (
        lv
        == ls
        == pytest.approx(-0.5 * math.log(2 * math.pi * 0.03**2) - ev_s.distance**2 / (2 * 0.03**2))
    )
    # a GP of L sees the same numbers either way
    opts = {**FAST, "n_train": 32, "surrogate": "log_likelihood"}
    post_v = fbia.iterator("gp_smc", **opts).run(vector)
    post_s = fbia.iterator("gp_smc", **opts).run(scalar)
    assert post_v.x == post_s.x


def test_surrogate_uncertainty_option_widens_a_starved_posterior():
    """The expected posterior (surrogates/uncertainty.py) from the iterator: a 10-run Sobol
    design whose GP does not know L well gives wider intervals than SMC on the GP mean, and
    says so."""
    problem = _problem()
    opts = {**FAST, "n_train": 10, "n_check": 0, "laplace": False}
    mean_only = fbia.iterator("gp_smc", **opts).run(problem)
    marginal = fbia.iterator("gp_smc", surrogate_uncertainty="expected_posterior", **opts).run(
        problem
    )
    assert marginal.uncertainty is not None
    assert np.all(marginal.posterior.std > mean_only.posterior.std)
    # unchecked (n_check = 0), the starved posterior never says completed; the sample paths'
    # widening is reported (with the residual emulator's exact paths, L never above the best
    # fit, it is x1.18 here: below the x1.5 that marks it; the starved posterior is 1.56 times
    # too wide, which paths of a GP that is too unsure cannot see), and the check at
    # posterior draws marks it unreliable (its error there: 2.1 in L)
    assert mean_only.status == "unchecked" and mean_only.uncertainty is not None
    assert "averaged over the GP's sample paths" in mean_only.message
    checked = fbia.iterator("gp_smc", **{**opts, "n_check": 8}).run(problem)
    assert checked.status == "unreliable" and checked.check.centred_rmse > 1.0
    assert "GP uncertainty marginalised over" in marginal.message
    assert marginal.to_dict()["info"]["uncertainty"]["n_paths"] > 0
    with pytest.raises(fbia.ConfigError, match="surrogate_uncertainty"):
        fbia.iterator("gp_smc", mode="direct", surrogate_uncertainty="expected_posterior").run(
            problem
        )


def test_the_laplace_angle_is_measured_in_the_design_box_scale():
    from fbia.iterators.gp_smc.result import principal_angle

    # rank-one covariances: their principal axes are exactly (100 Pa, +-0.2)
    band = np.outer([100.0, 0.2], [100.0, 0.2])
    across = np.outer([100.0, -0.2], [100.0, -0.2])
    box = np.array([700.0, 1.3])
    assert principal_angle(band, band, box) == pytest.approx(0.0, abs=1e-6)
    # in the box's scale the axes make atan((0.2 / 1.3) / (100 / 700)) with the E axis each
    each = np.degrees(np.arctan2(0.2 / 1.3, 100.0 / 700.0))
    assert principal_angle(band, across, box) == pytest.approx(min(2 * each, 180 - 2 * each))
    assert principal_angle(np.diag([1.0, 0.0]), np.diag([0.0, 1.0]), box) == pytest.approx(90.0)


def test_gp_seed_refits_the_surrogate_on_the_same_design():
    """gp_seed (default: seed) seeds only the GP's restart guesses: the same design and runs,
    other restart guesses; gp_seed = seed is the default fit to the bit."""
    problem = _problem()
    opts = {**FAST, "n_train": 64, "n_test": 8, "n_check": 0, "gp_restarts": 3}
    opts["surrogate"] = "log_likelihood"
    base = fbia.iterator("gp_smc", **opts).run(problem)
    same = fbia.iterator("gp_smc", gp_seed=FAST["seed"], **opts).run(problem)
    other = fbia.iterator("gp_smc", gp_seed=7, **opts).run(problem)
    np.testing.assert_array_equal(same.posterior.particles, base.posterior.particles)
    np.testing.assert_array_equal(other.design.points, base.design.points)
    assert other.nfev == base.nfev
    guesses = [
        [str(run["start"]) for run in res.surrogate.surrogate().info["runs"]]
        for res in (base, other)
    ]
    assert guesses[0][0] == guesses[1][0]  # the data-based guess
    assert guesses[0][1:] != guesses[1][1:]  # the seeded perturbations
