"""Results come back from their files as their types (fbia.load_result), and a gp_smc
posterior leaves files that ArviZ reads (issue 29 item 3)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _paths import ROOT
from _studies import edit, write_study

import fbia
from fbia.iterators.gp_smc.result import GpSmcResult
from fbia.iterators.lm.result import LMResult
from fbia.studies.cli import main

ROOT = ROOT

BAYES = edit(
    "options = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }",
    "options = { n_train = 32, n_particles = 1000, n_rejuvenation = 5, zeta = 0.9, seed = 0, "
    'design = "sobol", n_check = 4 }',
).replace('name = "levenberg_marquardt"', 'name = "gp_smc"')


def _same_quantities(a: dict[str, float], b: dict[str, float]) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])), k


def test_an_lm_result_loads_back_as_it_was(study_file, capsys):
    study = fbia.load_study(study_file)
    result = fbia.run_study(study, echo=lambda line: None)
    for source in (study_file.parent / "out", study_file.parent / "out" / "result.json"):
        loaded = fbia.load_result(source)
        assert isinstance(loaded, LMResult)
        _same_quantities(loaded.quantities(), result.quantities())
        assert loaded.summary() == result.summary()
        np.testing.assert_array_equal(loaded.cov, result.cov)
        assert len(loaded.evaluations) == len(result.evaluations) == result.nfev
        np.testing.assert_array_equal(
            loaded.evaluations[-1].residuals, result.evaluations[-1].residuals
        )


@pytest.fixture(scope="module")
def bayes_run(tmp_path_factory):
    """The BAYES study run once through the command line (~15 s), shared by the two tests
    that read its output: its study file and what it printed."""
    import contextlib
    import io
    import os

    folder = tmp_path_factory.mktemp("bayes")
    study_file = write_study(folder)
    study_file.write_text(BAYES)
    cwd, printed = os.getcwd(), io.StringIO()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(printed):
            status = main(["run", "study.toml"])
    finally:
        os.chdir(cwd)
    return study_file, status, printed.getvalue()


def test_a_gp_smc_result_loads_back_and_its_posterior_is_an_arviz_netcdf(bayes_run):
    arviz = pytest.importorskip("arviz")
    study_file, status, printed = bayes_run
    # 32 runs leave the surrogate far off at the posterior (RMSE ~ 80 in L): unreliable,
    # exit status 3, and its files are written all the same
    assert status == 3
    out = study_file.parent / "out"
    printed = printed.splitlines()
    assert any(line.startswith("wrote ") and line.endswith("posterior.nc") for line in printed)
    loaded = fbia.load_result(out)
    assert isinstance(loaded, GpSmcResult) and loaded.posterior is not None
    saved = json.loads((out / "result.json").read_text())
    assert loaded.x == saved["x"] and loaded.status == saved["status"] == "unreliable"
    post = loaded.posterior
    assert post.particles.shape == (1000, 2) and post.weights.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(post.weights @ post.particles[:, :2], post.mean)
    assert "posterior from 1000 particles" in loaded.summary()
    data = arviz.from_netcdf(out / "posterior.nc")
    assert set(data.posterior.data_vars) == {"E", "nu"}
    assert float(data.posterior["E"].mean()) == pytest.approx(post.mean[0], rel=0.02)
    assert {"lp", "log_prior"} <= set(data.sample_stats.data_vars)
    assert (out / "posterior.npz").is_file() and (out / "posterior.json").is_file()


def test_what_is_not_a_result_is_one_line(tmp_path):
    with pytest.raises(fbia.ConfigError, match="no result.json there"):
        fbia.load_result(tmp_path)
    (tmp_path / "result.json").write_text('{"x": 1}')
    with pytest.raises(fbia.ConfigError, match="not an fbia result"):
        fbia.load_result(tmp_path)
    (tmp_path / "result.json").write_text("{")
    with pytest.raises(fbia.ConfigError, match=r"result.json: not JSON \(Expecting property"):
        fbia.load_result(tmp_path / "result.json")


def test_a_field_the_file_does_not_hold_is_none_and_a_wrong_type_is_one_line(tmp_path):
    from dataclasses import dataclass, field

    from fbia.studies.result_io import FieldError, from_dict

    @dataclass
    class Row:
        n: int
        state: dict = field(metadata={"in_file": False})  # a live object the JSON leaves out

    @dataclass
    class Strict:
        n: int
        m: int

    assert from_dict(Row, {"n": 3}) == Row(3, None)
    with pytest.raises(FieldError, match="^m is missing$"):
        from_dict(Strict, {"n": 3})
    (tmp_path / "result.json").write_text(
        json.dumps({"status": "completed", "success": True, "message": "", "nfev": "many"})
    )
    with pytest.raises(fbia.ConfigError, match=r'result.json: nfev is "many", not a whole number'):
        fbia.load_result(tmp_path)


def test_the_take_away_example_loads_plots_and_hands_to_arviz(bayes_run, capsys):
    """examples/flow_cell/load_results.py on a gp_smc output (issue 29 items 3 and 6): the
    result loads, fbia.plot draws its figures with the ground truth marked, ArviZ summarises
    the posterior."""
    import runpy

    pytest.importorskip("arviz")
    study_file, status, _ = bayes_run
    assert status == 3
    example = runpy.run_path(str(ROOT / "examples" / "flow_cell" / "load_results.py"))
    paths = example["main"](study_file.parent / "out", study_file)
    printed = capsys.readouterr().out
    names = sorted(p.name for p in paths)
    assert {"posterior.png", "marginals_1d.png", "evaluations.png"} <= set(names)
    assert all(p.is_file() and p.parent.name == "replotted" for p in paths)
    assert "status unreliable" in printed and "ArviZ groups: posterior" in printed
    assert "hdi_2.5%" in printed  # az.summary's table


def test_plot_marks_the_ground_truth_of_synthetic_data(tmp_path):
    """fbia.plot of an LM result: its search paths and its evaluations carry the ground
    truth of the problem's synthetic data (a legend entry each)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    truth = {"E": 400.0, "nu": 0.3}
    problem = fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=fbia.synthetic_observations(
            model, truth, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0
        ),
        parameters=[
            fbia.Parameter("E", (100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", (-0.8, 0.5)),
        ],
        truth=truth,
    )
    result = fbia.iterator("levenberg_marquardt", x0={"E": 300.0, "nu": 0.2}).run(problem)
    seen: list[list[str]] = []
    savefig = plt.Figure.savefig

    def spy(fig, *args, **kwargs):
        seen.extend([t.get_text() for t in ax.get_legend().get_texts()] for ax in fig.axes
                    if ax.get_legend() is not None)  # fmt: skip
        return savefig(fig, *args, **kwargs)

    plt.Figure.savefig = spy
    try:
        paths = fbia.plot(result, problem, tmp_path)
    finally:
        plt.Figure.savefig = savefig
    names = sorted(p.name for p in paths)
    assert names == ["evaluations.png", "lm_errors.png", "lm_search_paths.png"]
    assert sum("ground truth" in labels for labels in seen) == 2  # search paths, evaluations


def test_a_synthetic_study_gives_its_problem_the_ground_truth(study_file):
    text = study_file.read_text()
    assert "[synthetic]" not in text  # the tiny study reads its data from files: no truth
    assert fbia.load_study(study_file).problem.truth is None
