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


def test_a_plot_without_labelled_artists_gets_no_legend_and_no_warning(recwarn):
    """An empty plot (every run failed) prints no "No artists with labels" warning: every
    legend of fbia's plots goes through fbia.core.plots.legend (issue 31 item 6)."""
    import pathlib
    import re

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fbia.core.plots import legend

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])  # no label
    legend(ax, fontsize=8)
    assert ax.get_legend() is None
    ax.plot([0, 1], [1, 0], label="simulated")
    legend(ax, fontsize=8)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["simulated"]
    plt.close(fig)
    assert not [w for w in recwarn if "No artists with labels" in str(w.message)]
    root = pathlib.Path(__file__).resolve().parents[1]
    direct = [
        f"{path.relative_to(root)}:{n}"
        for folder in ("core", "iterators", "measures", "plugins")
        for path in sorted((root / folder).rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), start=1)
        if re.search(r"\.legend\(", line) and "ax.legend(**kwargs)" not in line
    ]
    assert direct == []
