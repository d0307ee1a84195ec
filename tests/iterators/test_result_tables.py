"""Results in a notebook and as tables (issue 43 item 8): ``_repr_html_`` on every result
(status first, marked when it is not a success, the message escaped, the main quantities, the
forward runs; no failed run makes it raise) and ``to_records()`` / ``to_dataframe()`` (one row
per Levenberg-Marquardt start, per input of a posterior, per Sobol' index), whose numbers are
the result's own.

The results are real runs on the closed-form mound (seconds): data made at E = 400 Pa,
nu = 0.3 with 1 um of noise; Levenberg-Marquardt from two starts, the same data with the truth
E = 3000 Pa outside the bounds [50, 1500] Pa (at a bound: ``unreliable``), gp_smc on the
forward model itself, Sobol' indices of the Ishigami function (closed form) and a starved
Sobol' design (``unreliable``); failed runs from a model that fails everywhere.
"""

from __future__ import annotations

import html
import math
import sys

import numpy as np
import pytest

import fbia
from fbia.core.problem import Result
from fbia.iterators.gp_smc.result import GpSmcResult, ParticlePosterior
from fbia.iterators.sobol_indices import SobolIndicesResult, sobol_indices

TRUTH = {"E": 400.0, "nu": 0.3}
STARTS = [{"E": 200.0, "nu": 0.4}, {"E": 1000.0, "nu": 0.0}]
#: gp_smc on the forward model itself (a second here) with a likelihood broad enough that few
#: tempering steps reach it
DIRECT = {"mode": "direct", "n_particles": 200, "n_rejuvenation": 2, "zeta": 0.5, "seed": 0}


def ishigami(x: np.ndarray) -> np.ndarray:
    """Its Sobol' indices on U(-pi, pi)^3 are known in closed form (Saltelli et al. 2008)."""
    return np.sin(x[:, 0]) + 7.0 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])


#: the closed-form S1 and ST of ``ishigami`` (a = 7, b = 0.1; test_sobol_indices.py derives them)
ISHIGAMI_S1 = (0.3139, 0.4424, 0.0)
ISHIGAMI_ST = (0.5576, 0.4424, 0.2437)


def _problem(truth=TRUTH, e_bounds=(50.0, 1500.0), noise_std=0.001, **model_options):
    clean = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(
        clean, {**truth, "inflow_rate": 100.0}, [{}], noise_std=0.001, seed=1
    )
    return fbia.InverseProblem(
        model=fbia.forward_model("analytic_mound_2d", n_points=41, **model_options),
        measure=fbia.measure("cpp"),
        observations=obs,
        noise_std=noise_std,
        parameters=[
            fbia.Parameter("E", bounds=e_bounds, unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
        fixed={"inflow_rate": 100.0},
    )


def _failing_problem():
    return _problem(failure_region={"E": (0.0, 2000.0)})


@pytest.fixture(scope="module")
def lm():
    return fbia.iterator("levenberg_marquardt", x0=STARTS).run(_problem())


@pytest.fixture(scope="module")
def lm_at_bound():
    problem = _problem(truth={"E": 3000.0, "nu": 0.3})
    return fbia.iterator("levenberg_marquardt", x0=STARTS).run(problem)


@pytest.fixture(scope="module")
def bayes():
    return fbia.iterator("gp_smc", **DIRECT).run(_problem(e_bounds=(100.0, 800.0), noise_std=0.03))


def _self_contained(page: str) -> None:
    assert page.startswith('<div class="fbia-result">') and page.endswith("</div>")
    for outside in ("<script", "<link", "<style", "http://", "https://", "@import"):
        assert outside not in page


# -- Levenberg-Marquardt --------------------------------------------------------------------------
def test_lm_records_are_the_starts_with_the_results_own_numbers(lm):
    assert lm.success and lm.status.startswith("converged")
    rows = lm.to_records()
    assert [r["start"] for r in rows] == [1, 2]
    assert [{"E": r["x0.E"], "nu": r["x0.nu"]} for r in rows] == STARTS
    (best,) = [r for r in rows if r["best"]]
    assert {"E": best["x.E"], "nu": best["x.nu"]} == lm.x
    assert best["err_res"] == lm.err_res and best["err_grad"] == lm.err_grad
    assert best["iterations"] == lm.iterations
    assert abs(lm.x["E"] - 400.0) < 5.0 and abs(lm.x["nu"] - 0.3) < 0.02  # the truth
    assert sum(r["nfev"] for r in rows) == lm.nfev
    for r, s in zip(rows, lm.starts, strict=True):
        assert r["status"] == s["status"] and r["converged"] and r["message"] == s["message"]
        assert r["at_bound"] == "" and r["n_failed"] == 0
    # the per-start numbers are those quantities() gives a study
    q = lm.quantities()
    for r in rows:
        assert (
            r["x.E"] == q[f"start.{r['start']}.E"]
            and r["err_res"] == q[f"start.{r['start']}.err_res"]
        )


def test_lm_html_shows_status_parameters_standard_errors_and_starts(lm):
    page = lm._repr_html_()
    _self_contained(page)
    assert f"<b>levenberg_marquardt: {lm.status}</b>" in page and "not a success" not in page
    assert html.escape(lm.message) in page
    assert "<th" in page and ">E</td>" in page and ">nu</td>" in page
    for name, se in lm.stderr.items():
        assert f"± {se:.3g}" in page, name
    assert f">{lm.x['E']:.6g}<" in page
    assert "fit against the stated noise: chi2 / nu" in page
    assert ">best<" in page and page.count(">converged_") == 2  # the starts' table
    assert f"{lm.nfev} forward runs, 0 failed" in page


def test_lm_at_a_bound_is_marked_unreliable_without_a_standard_error_there(lm_at_bound):
    result = lm_at_bound
    assert result.status == "unreliable" and result.quality.at_bound == ("E",)
    page = result._repr_html_()
    _self_contained(page)
    assert "&#9888; levenberg_marquardt: unreliable</b> (not a success)" in page
    # the message holds "p = ... < 0.001": escaped
    assert "< 0.001" in result.message and html.escape(result.message) in page
    assert "< 0.001" not in page
    # the cause comes first: before any table
    assert page.index("at bound: E = 1500 (its upper bound)") < page.index("<table")
    assert "none: at its upper bound" in page and f"± {result.stderr['nu']:.3g}" in page
    rows = result.to_records()
    assert all(r["at_bound"] == "E" and r["x.E"] == 1500.0 for r in rows)


def test_lm_units_come_from_the_problem_fbia_run_records(lm):
    assert lm.units() == {}  # run from Python: no provenance, no unit column
    assert "<th" in lm._repr_html_() and ">unit<" not in lm._repr_html_()
    named = Result(status="completed", success=True, message="", x={"E": 1.0})
    named.provenance = {"problem": _problem().describe()}
    assert named.units() == {"E": "Pa"}
    assert ">unit<" in named._repr_html_() and ">Pa<" in named._repr_html_()


def test_lm_without_any_result_gives_rows_of_nan_and_html():
    result = fbia.iterator("levenberg_marquardt", x0=STARTS).run(_failing_problem())
    assert result.status == "all_failed" and result.x is None
    rows = result.to_records()
    assert len(rows) == 2 and all(r["status"] == "start_failed" for r in rows)
    assert all(math.isnan(r["x.E"]) and math.isnan(r["err_res"]) for r in rows)
    assert [r["x0.E"] for r in rows] == [200.0, 1000.0]
    page = result._repr_html_()
    _self_contained(page)
    assert "all_failed</b> (not a success)" in page and html.escape(result.message) in page
    assert f"{result.nfev} forward runs, {result.nfev} failed" in page


# -- gp_smc ---------------------------------------------------------------------------------------
def test_gp_smc_records_are_the_posterior_summary(bayes):
    assert bayes.status == "completed"
    post = bayes.posterior
    rows = bayes.to_records()
    assert [r["input"] for r in rows] == ["E", "nu"] and [r["unit"] for r in rows] == ["Pa", ""]
    for j, r in enumerate(rows):
        values, w = post.particles[:, j], post.weights
        pm = np.average(values, weights=w)
        assert r["pm"] == pytest.approx(pm, rel=1e-12)
        assert r["std"] == pytest.approx(np.sqrt(np.average((values - pm) ** 2, weights=w)))
        assert r["map"] == bayes.x[r["input"]]
        assert [r["q2.5"], r["q50"], r["q97.5"]] == post.credible_intervals[r["input"]]
        assert r["q2.5"] <= TRUTH[r["input"]] <= r["q97.5"]  # the truth inside the 95 %
    q = bayes.quantities()
    assert [r["pm"] for r in rows] == [q["pm.E"], q["pm.nu"]]
    assert [r["std"] for r in rows] == [q["sd.E"], q["sd.nu"]]


def test_gp_smc_html_shows_the_posterior_with_units(bayes):
    page = bayes._repr_html_()
    _self_contained(page)
    assert "<b>gp_smc: completed</b>" in page and html.escape(bayes.message) in page
    for head in ("MAP", "PM", "std", "2.5 %", "97.5 %", "unit"):
        assert f">{head}</th>" in page
    assert ">E</td>" in page and ">Pa</td>" in page and ">nu</td>" in page
    pm = bayes.to_records()[0]["pm"]
    assert f">{pm:.6g}<" in page
    assert f"{bayes.nfev} forward runs" in page and "direct mode, 200 particles" in page


def test_gp_smc_without_a_posterior_has_no_rows_and_html():
    result = fbia.iterator("gp_smc", n_train=8, design="sobol", seed=0).run(_failing_problem())
    assert result.status == "all_failed" and result.posterior is None
    assert result.to_records() == []
    page = result._repr_html_()
    _self_contained(page)
    assert "gp_smc: all_failed</b> (not a success)" in page and "<table" not in page
    assert html.escape(result.message) in page
    # a posterior of zero particles (its summaries NaN) renders and tabulates too
    nan, none = np.full(1, np.nan), np.empty(0)
    empty = ParticlePosterior(
        names=["E"], n_x=1, particles=np.empty((0, 1)), weights=none, log_likelihood=none,
        log_prior=none, log_evidence=np.nan, log_evidence_se=np.nan, mean=nan,
        cov=np.full((1, 1), np.nan), mean_all=nan, cov_all=np.full((1, 1), np.nan),
        max_likelihood=nan, credible_intervals={"E": [np.nan] * 3}, map=nan, map_method="-",
    )  # fmt: skip
    zero = GpSmcResult(status="failed", success=False, message="no particles <0>", posterior=empty)
    (row,) = zero.to_records()
    assert row["input"] == "E" and all(math.isnan(row[k]) for k in ("map", "pm", "std", "q50"))
    page = zero._repr_html_()
    assert "no particles &lt;0&gt;" in page and ">E</td>" in page and "0 particles" in page


# -- Sobol' indices -------------------------------------------------------------------------------
def test_sobol_records_are_the_indices_of_the_closed_form():
    inputs = [fbia.Parameter(f"x{k}", bounds=(-math.pi, math.pi)) for k in (1, 2, 3)]
    ind = sobol_indices(ishigami, inputs, n_base=1024, seed=1, resamples=50)
    result = SobolIndicesResult(status="completed", success=True, message="Ishigami", indices=ind)
    rows = result.to_records()
    assert [r["input"] for r in rows] == ["x1", "x2", "x3"]
    assert [r["st"] for r in rows] == ind.st and [r["s1_conf"] for r in rows] == ind.s1_conf
    for r, a, b in zip(rows, ISHIGAMI_S1, ISHIGAMI_ST, strict=True):
        assert abs(r["s1"] - a) < 0.05 and abs(r["st"] - b) < 0.05
    page = result._repr_html_()
    _self_contained(page)
    assert ">x3</td>" in page and f">{ind.st[1]:.3f}<" in page and "95% confidence" in page
    assert "no held-out runs" in page  # test_relative_rmse NaN: built without a surrogate


def test_a_starved_sobol_design_shows_unreliable():
    it = fbia.iterator("sobol_indices", quantity="distance", n_train=6, n_test=8, n_base=256)
    result = it.run(_problem(e_bounds=(200.0, 800.0)))
    assert result.status == "unreliable"
    page = result._repr_html_()
    assert "sobol_indices: unreliable</b> (not a success)" in page
    assert html.escape(result.message) in page and "the surrogate&#x27;s held-out RMSE" in page
    assert [r["input"] for r in result.to_records()] == ["E", "nu"]


# -- any result, pandas --------------------------------------------------------------------------
def test_a_third_party_result_gets_the_defaults_with_everything_escaped():
    result = Result(
        status="stopped <early>",
        success=False,
        message='budget & "time" <out>',
        x={"k<1>": 2.5},
        nfev=3,
        n_failed=1,
        iterator="mine",
    )
    page = result._repr_html_()
    _self_contained(page)
    assert "mine: stopped &lt;early&gt;</b> (not a success)" in page
    assert "budget &amp; &quot;time&quot; &lt;out&gt;" in page
    assert ">k&lt;1&gt;</td>" in page and ">2.5</td>" in page
    assert "3 forward runs, 1 failed" in page
    assert result.to_records() == [{"parameter": "k<1>", "value": 2.5}]
    bare = Result(status="all_failed", success=False, message="")
    assert "<table" not in bare._repr_html_() and bare.to_records() == []


def test_to_dataframe_wraps_the_records(lm, bayes):
    pd = pytest.importorskip("pandas")
    frame = lm.to_dataframe()
    assert isinstance(frame, pd.DataFrame)
    rows = lm.to_records()
    assert list(frame.columns) == list(rows[0]) and len(frame) == len(rows)
    best = frame[frame["best"]].iloc[0]
    assert {"E": best["x.E"], "nu": best["x.nu"]} == lm.x
    posterior = bayes.to_dataframe().set_index("input")
    assert posterior.loc["E", "pm"] == bayes.to_records()[0]["pm"]
    assert posterior.loc["E", "unit"] == "Pa"


def test_to_dataframe_without_pandas_names_the_extra(lm, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    with pytest.raises(ImportError) as err:
        lm.to_dataframe()
    message = str(err.value)
    assert "\n" not in message and "pip install 'fbia[tables]'" in message
    assert lm.to_records()  # the same table without pandas
