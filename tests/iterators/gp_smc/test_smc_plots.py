"""Figures of gp_smc results (Paper B Figs. 5-9, 12-15) and the percentile levels they draw."""

import math

import numpy as np
import pytest
from matplotlib.image import imread
from test_gp_smc import FAST, _problem  # noqa: E402

import fbia
from fbia.iterators.gp_smc.plots import FIGURES, _kde_levels


def test_percentile_levels_hold_their_mass_for_a_gaussian():
    g = np.linspace(-6, 6, 601)
    xx, yy = np.meshgrid(g, g)
    dens = np.exp(-0.5 * (xx**2 + yy**2)) / (2 * math.pi)
    levels = _kde_levels(dens, (0.1, 0.5, 0.9))
    # The q-mass HPD region of a 2-D standard normal is r^2 <= -2 log(1 - q).
    expected = sorted(math.exp(math.log(1 - q)) / (2 * math.pi) for q in (0.1, 0.5, 0.9))
    np.testing.assert_allclose(levels, expected, rtol=0.02)


def _check_images(paths):
    for p in paths:
        img = imread(p)
        assert img.shape[0] > 300 and img.shape[1] > 300
        assert img[..., :3].std() > 0.05  # not a blank canvas


def test_write_plots_makes_every_figure(tmp_path):
    problem = _problem(failure_region={"E": (100.0, 150.0)})
    it = fbia.iterator("gp_smc", n_train=48, n_test=8, **{**FAST, "n_particles": 300})
    result = it.run(problem)
    assert result.n_failed > 0
    paths = it.write_plots(result, problem, tmp_path)
    assert [p.name for p in paths] == [f"{name}.png" for name in FIGURES]
    _check_images(paths)


def test_plots_under_uncertainty_show_the_theta_marginal(tmp_path):
    problem = _problem(theta=True)
    it = fbia.iterator("gp_smc", n_train=48, **{**FAST, "n_particles": 300})
    result = it.run(problem)
    figures = ["posterior", "marginals_1d", "parallel_axes", "gp_convergence"]
    paths = it.write_plots(result, problem, tmp_path, figures=figures)
    # No GP-convergence panel in 3 inputs (it is a 2-D picture).
    assert [p.name for p in paths] == ["posterior.png", "marginals_1d.png", "parallel_axes.png"]
    _check_images(paths)
    with pytest.raises(fbia.ConfigError, match=r"unknown figure\(s\) hexbin"):
        it.write_plots(result, problem, tmp_path, figures=["hexbin"])


def test_all_failed_result_plots_the_design(tmp_path):
    problem = _problem(failure_region={"E": (0.0, 1000.0)})
    it = fbia.iterator("gp_smc", n_train=8, **FAST)
    result = it.run(problem)
    paths = it.write_plots(result, problem, tmp_path)
    assert [p.name for p in paths] == ["design.png"]


def test_the_figures_refit_no_gp_beyond_2000_runs():
    """The GP-over-n_train figures refit a GP of L on design prefixes; on a 6000-run design
    the last one (all 6000) took more than 7 min and 10 GB. They stop at 2000 runs."""
    from fbia.iterators.gp_smc.plots import _MAX_REFIT, _prefix_sizes

    assert _prefix_sizes(64) == [10, 20, 50, 64]
    assert _prefix_sizes(2000) == [50, 100, 200, 500, 1000, 2000]
    assert max(_prefix_sizes(6000)) == _MAX_REFIT == 2000
