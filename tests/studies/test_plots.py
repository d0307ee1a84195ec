"""The study's own figures: the interfaces with the residuals below them in µm."""

from __future__ import annotations

import numpy as np
from _models import toy_problem
from _paths import ROOT

from fbia.studies.plots import _residuals_um, plot_interfaces


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
    legend of fbia's plots goes through fbia.studies.plots.legend (issue 31 item 6)."""
    import re

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fbia.figures import legend

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])  # no label
    legend(ax, fontsize=8)
    assert ax.get_legend() is None
    ax.plot([0, 1], [1, 0], label="simulated")
    legend(ax, fontsize=8)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["simulated"]
    plt.close(fig)
    assert not [w for w in recwarn if "No artists with labels" in str(w.message)]
    root = ROOT
    direct = [
        f"{path.relative_to(root)}:{n}"
        for folder in ("core", "iterators", "measures", "plugins")
        for path in sorted((root / folder).rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), start=1)
        if re.search(r"\.legend\(", line) and "ax.legend(**kwargs)" not in line
    ]
    assert direct == []


def test_no_figure_of_a_calibration_is_clipped(tmp_path):
    """Issue 29 item 6: every figure fbia.plot and the interfaces plot write holds all it
    draws (labels, tick labels, titles) inside the saved image: measured as the figure's
    tight bounding box against its own box, unless it is saved with bbox_inches='tight'.
    (Found so: the pairwise marginals' title of a two-input posterior was cut by 73 px.)"""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    import fbia
    from fbia.studies.plots import plot_interfaces

    clipped: dict[str, list[int]] = {}
    saved: list[str] = []
    savefig = Figure.savefig

    def spy(fig, fname, *args, **kwargs):
        saved.append(str(fname))
        fig.canvas.draw()
        box = fig.get_tightbbox(fig.canvas.get_renderer()).transformed(fig.dpi_scale_trans)
        out = [box.x0 - fig.bbox.x0, box.y0 - fig.bbox.y0, fig.bbox.x1 - box.x1,
               fig.bbox.y1 - box.y1]  # fmt: skip
        if min(out) < -1.0 and kwargs.get("bbox_inches") != "tight":
            clipped[str(fname).rsplit("/", 1)[-1]] = [round(v) for v in out]
        return savefig(fig, fname, *args, **kwargs)

    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    truth = {"E": 400.0, "nu": 0.3}
    obs = fbia.synthetic_observations(
        model, truth, [{"inflow_rate": 100.0}], noise_std=0.001, seed=0
    )
    problem = fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        parameters=[
            fbia.Parameter("E", (100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", (-0.8, 0.5)),
        ],
        noise_std=0.002,
        truth=truth,
    )
    Figure.savefig = spy
    try:
        x0 = [{"E": 300.0, "nu": 0.2}, {"E": 600.0, "nu": 0.0}]
        lm = fbia.iterator("levenberg_marquardt", x0=x0).run(problem)
        fbia.plot(lm, problem, tmp_path / "lm")
        # zeta = 0.9: ~30 tempering steps instead of the default's ~500 (13 s); the figures
        # are the same kinds, which is what is checked
        smc = fbia.iterator("gp_smc", n_train=40, n_particles=500, zeta=0.9, seed=0, design="sobol")
        fbia.plot(smc.run(problem), problem, tmp_path / "smc")
        best = problem.evaluate(lm.x, keep_solution=True)
        plot_interfaces(tmp_path / "interfaces.png", problem, best.solution, "LM result")
    finally:
        Figure.savefig = savefig
    assert len(saved) >= 10
    assert clipped == {}
