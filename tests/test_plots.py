"""The study's own figures: the interfaces with the residuals below them in µm."""

from __future__ import annotations

import numpy as np
from _models import toy_problem

from fbia.core.plots import _residuals_um, plot_interfaces


def test_the_residual_panel_shows_the_measures_residuals_in_micrometres(tmp_path):
    import matplotlib.image

    problem = toy_problem()
    solution = problem.model.solve({"E": 410.0, "nu": 0.3}, problem.coordinates(), tmp_path)
    ((k, r_um),) = _residuals_um(problem, solution)
    obs = problem.observations[0]
    expected = problem.measure.residuals(solution.interface(obs.coordinate), obs)
    np.testing.assert_array_equal(r_um, 1000.0 * np.asarray(expected))
    assert k == 0 and np.abs(r_um).max() > 0
    path = plot_interfaces(tmp_path / "interfaces.png", problem, solution)
    assert path is not None and matplotlib.image.imread(path).shape[0] > 600  # two panels
    alone = plot_interfaces(tmp_path / "alone.png", problem, None)  # no solution: one panel
    assert alone is not None and matplotlib.image.imread(alone).shape[0] < 500
