"""The [paper] table of a study file: schema, quantities of results, the report and summary."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _studies import STUDY, one_error_line, write_study

import fbia
from fbia.core.cli import main
from fbia.core.paper import compare, lookup, read_paper
from fbia.core.paper_report import PaperRecord, comparison_table, write_summary
from fbia.iterators.gp_smc_result import DesignRuns, GpSmcResult, ParticlePosterior, PosteriorCheck
from fbia.iterators.surrogate_convergence_result import ConvergenceRow, SurrogateConvergenceResult

PAPER = """
[paper]
source = "Toy paper, Table 9"
note = "exact data"

[[paper.values]]
quantity = "x.E"
paper = 400.0
unit = "Pa"
tolerance = 0.01
why = "exact data: the optimum is the truth"

[[paper.values]]
quantity = "x.nu"
paper = 0.35
rule = "absolute"
tolerance = 0.01
why = "a number chosen to disagree"

[[paper.values]]
quantity = "x.E"
rule = "above"
than = "x.nu"
label = "E above nu"

[[paper.values]]
quantity = "converged"
paper = 1
rule = "equal"
"""


def _spec(values: list[dict], **paper) -> fbia.core.paper.PaperSpec:
    return read_paper({"source": "S", **paper, "values": values}, "s.toml")


@pytest.mark.parametrize(
    ("paper", "values", "message"),
    [
        (
            {"sorce": "x"},
            [],
            "s.toml: [paper]: unknown key 'sorce'; valid keys: source, note, values",
        ),
        ({}, [], "s.toml: [paper]: no [[paper.values]]: give at least one published number"),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0, "tol": 1}],
            "s.toml: [[paper.values]] #1: unknown key 'tol'; valid keys: quantity, paper, unit, "
            "rule, tolerance, than, label, why",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": "400"}],
            "s.toml: [[paper.values]] #1 paper: expected a number, got a string '400'",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0}],
            "s.toml: [[paper.values]] #1: rule 'relative' needs a 'tolerance'",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0, "rule": "close"}],
            "s.toml: [[paper.values]] #1 rule: unknown rule 'close'; valid: relative, absolute, "
            "magnitude, equal, same_sign, above, below, none",
        ),
        (
            {},
            [{"quantity": "x.E", "rule": "equal"}],
            "s.toml: [[paper.values]] #1: rule 'equal' needs the published value 'paper'",
        ),
        (
            {},
            [{"quantity": "x.E", "rule": "above"}],
            "s.toml: [[paper.values]] #1: rule 'above' needs 'than' (the quantity to compare with)",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0, "rule": "equal", "tolerance": 1.0}],
            "s.toml: [[paper.values]] #1 tolerance: rule 'equal' takes no 'tolerance'",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": -1.0, "rule": "magnitude"}],
            "s.toml: [[paper.values]] #1: rule 'magnitude' needs a positive paper value, got -1.0",
        ),
    ],
)
def test_paper_table_mistakes_are_one_located_line(paper, values, message):
    with pytest.raises(fbia.ConfigError) as err:
        _spec(values, **paper)
    assert str(err.value) == message


def test_rules_judge_as_documented():
    q = {"a": 105.0, "b": -2.0, "c": 3e-3, "n": 2.0, "bad": math.nan}
    spec = _spec(
        [
            {"quantity": "a", "paper": 100.0, "tolerance": 0.05},  # 5 % off: agrees
            {"quantity": "a", "paper": 100.0, "tolerance": 0.04},
            {"quantity": "a", "paper": 100.0, "rule": "absolute", "tolerance": 4.9},
            {"quantity": "c", "paper": 1e-3, "rule": "magnitude"},
            {"quantity": "c", "paper": 1e-4, "rule": "magnitude"},
            {"quantity": "b", "paper": -0.1, "rule": "same_sign"},
            {"quantity": "b", "paper": 0.1, "rule": "same_sign"},
            {"quantity": "n", "paper": 2.0, "rule": "equal"},
            {"quantity": "a", "rule": "above", "than": "n"},
            {"quantity": "a", "rule": "below", "than": "n"},
            {"quantity": "bad", "paper": 1.0, "rule": "absolute", "tolerance": 10.0},
            {"quantity": "bad", "paper": 1.0, "rule": "none"},
        ]
    )
    rows = compare(spec, q)
    assert [r.agrees for r in rows] == [
        True,
        False,
        False,
        True,
        False,
        True,
        False,
        True,
        True,
        False,
        False,
        None,
    ]
    assert rows[0].abs_diff == pytest.approx(5.0) and rows[0].rel_diff == pytest.approx(0.05)
    assert rows[8].reference == 2.0


def test_an_unknown_quantity_lists_the_available_ones():
    spec = _spec([{"quantity": "mean.E", "paper": 1.0, "rule": "equal"}])
    with pytest.raises(fbia.ConfigError) as err:
        compare(spec, {"x.E": 1.0, "x.nu": 0.2})
    assert str(err.value) == (
        "s.toml: [[paper.values]] #1 quantity: the result has no quantity 'mean.E'; "
        "available: x.E, x.nu"
    )
    assert lookup({"x.E": 2.0}, "x.E") == 2.0


def test_lm_quantities_per_start_by_number_and_label_and_over_starts():
    t = np.linspace(0.0, 4.0, 20)
    y = 3.0 * np.exp(-0.7 * t)
    res = fbia.least_squares(
        lambda b: b[0] * np.exp(-b[1] * t) - y,
        [[1.0, 1.0], [2.0, 0.5]],
        bounds=([0.0, 0.0], [10.0, 5.0]),
    )
    q = res.quantities()
    names = res.names
    assert q["n_starts"] == 2 and q["n_results"] == 2 and q["converged"] == 1.0
    for k in ("1", "2"):
        assert q[f"start.{k}.{names[0]}"] == pytest.approx(3.0, rel=1e-6)
        assert q[f"start.{k}.converged"] == 1.0
    assert q[f"mean.{names[1]}"] == pytest.approx(0.7, rel=1e-6)
    assert q[f"std.{names[1]}"] < 1e-6
    assert q["err_res"] == q["mean.err_res"] or q["err_res"] <= q["mean.err_res"]
    res.starts[1]["label"] = "olive green"
    res.starts[1]["x"] = None
    res.starts[1]["err_res"] = None
    q = res.quantities()
    assert math.isnan(q["start.olive_green.err_res"]) and q["n_results"] == 1


def test_gp_smc_quantities_are_map_mean_and_std():
    particles = np.array([[300.0, 0.1], [500.0, 0.3]])
    w = np.array([0.5, 0.5])
    post = ParticlePosterior(
        names=["E", "nu"],
        n_x=2,
        particles=particles,
        weights=w,
        log_likelihood=np.zeros(2),
        log_prior=np.zeros(2),
        log_evidence=-1.5,
        log_evidence_se=0.1,
        mean=particles.mean(0),
        cov=np.cov(particles.T, aweights=w),
        mean_all=particles.mean(0),
        cov_all=np.diag([100.0**2, 0.1**2]),
        max_likelihood=particles[0],
        credible_intervals={"E": [300.0, 400.0, 500.0], "nu": [0.1, 0.2, 0.3]},
        map=np.array([310.0, 0.15]),
        map_method="test",
    )
    res = GpSmcResult(
        status="completed",
        success=True,
        message="",
        x={"E": 310.0, "nu": 0.15},
        posterior=post,
        names=["E", "nu"],
        n_x=2,
    )
    q = res.quantities()
    assert (q["map.E"], q["pm.E"], q["sd.E"], q["pm.nu"]) == (310.0, 400.0, 100.0, 0.2)
    assert (q["q2.5.E"], q["q97.5.nu"], q["x.nu"]) == (300.0, 0.3, 0.15)
    # the marginal's peak: the heavier particle's bin (the first and last of 30 over 300-500)
    assert q["mode.E"] == pytest.approx(300.0 + 200.0 / 60)
    post.weights[:] = [0.2, 0.8]
    assert res.quantities()["mode.E"] == pytest.approx(500.0 - 200.0 / 60)
    assert "check.rmse" not in q and "design.n_failed" not in q  # stages that did not run
    res.design = DesignRuns(
        points=np.array([[150.0, -0.5], [120.0, 0.2], [600.0, 0.1]]),
        log_likelihood=np.array([-np.inf, -np.inf, -3.0]),
        status=["failed", "failed", "ok"],
        train_mask=np.ones(3, dtype=bool),
    )
    res.check = PosteriorCheck(4, 0, np.zeros((4, 2)), np.zeros(4), 0.25, 0.5, 0.1)
    q = res.quantities()
    assert (q["check.rmse"], q["design.n_failed"]) == (0.25, 2.0)
    assert (q["design.failed_min.E"], q["design.failed_max.E"]) == (120.0, 150.0)
    assert (q["design.failed_min.nu"], q["design.failed_max.nu"]) == (-0.5, 0.2)
    res.design = DesignRuns(res.design.points[2:], np.array([-3.0]), ["ok"], np.ones(1, bool))
    q = res.quantities()
    assert q["design.n_failed"] == 0.0 and math.isnan(q["design.failed_max.E"])


def test_surrogate_convergence_quantities_per_n_train():
    def row(n: int, e: float, distance: float, rmse: float) -> ConvergenceRow:
        return ConvergenceRow(
            n, n - 1, {"E": e, "nu": 0.3}, -1.0, rmse, 2 * rmse, 0.1, distance, {}
        )

    res = SurrogateConvergenceResult(
        status="completed",
        success=True,
        message="",
        x={"E": 401.0, "nu": 0.3},
        names=["E", "nu"],
        rows=[row(10, 190.0, 0.37, 6.7), row(200, 401.0, 0.004, 0.6)],
        n_test=100,
    )
    q = res.quantities()
    assert (q["n_train.10.E"], q["n_train.10.distance"], q["n_train.10.test_rmse"]) == (
        190.0,
        0.37,
        6.7,
    )
    assert (q["n_train.200.nu"], q["n_train.200.n_used"], q["n_train.200.test_max_abs"]) == (
        0.3,
        199.0,
        1.2,
    )
    assert (q["x.E"], q["n_test"], q["n_train.200.ml_log_likelihood"]) == (401.0, 100.0, -1.0)
    spec = _spec(
        [{"quantity": "n_train.200.distance", "rule": "below", "than": "n_train.10.distance"}]
    )
    assert compare(spec, q)[0].agrees is True


def test_comparison_table_has_the_published_and_fbia_columns():
    rows = compare(
        _spec(
            [{"quantity": "x.E", "paper": 400.0, "unit": "Pa", "tolerance": 0.01, "why": "a | b"}]
        ),
        {"x.E": 410.0},
    )
    lines = comparison_table(rows)
    assert lines[0] == "| quantity | paper | fbia | difference | rel. | agrees? | why |"
    assert lines[2] == "| x.E | 400 Pa | 410 Pa | 10 | +2.5 % | **no** (within 1 %) | a \\| b |"


def test_run_writes_report_and_the_summary_collects_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER)
    assert main(["run", "study.toml"]) == 0
    out = tmp_path / "out"
    report = (out / "report.md").read_text()
    assert report.startswith("# tiny: fbia beside Toy paper, Table 9")
    assert "3 of 4 published numbers agree by their rule." in report
    assert "| x.nu | 0.35 | 0.3 | -0.05 | -14.3 % | **no** (within 0.01) |" in report
    assert "| E above nu | > x.nu (0.3) | 400 |  |  | yes (> x.nu) |" in report
    assert "- [plots/interfaces.png](plots/interfaces.png)" in report
    assert (
        "- model `analytic_mound_2d`: n_points = 41; the other options at their defaults" in report
    )
    record = PaperRecord.read(out / "paper.json")
    assert record.nfev > 0 and record.wall_time > 0 and len(record.rows) == 4
    assert record.reused == 0 and record.forward_time > 0
    assert main(["run", "study.toml"]) == 0  # resumed: every run from the store
    again = PaperRecord.read(out / "paper.json")
    assert again.reused == again.nfev == record.nfev
    assert again.forward_time == pytest.approx(record.forward_time)  # the runs' own times
    assert "runs taken from the store, not run again" in (out / "report.md").read_text()
    assert main(["reproductions", "docs/summary.md", "."]) == 0
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "| [tiny](#tiny) | Toy paper, Table 9 | 3 / 4 | " in page
    assert "Study file [../study.toml](../study.toml)" in page
    assert "## Measured times per example" not in page  # no README: nothing to copy
    (tmp_path / "README.md").write_text(
        "# Toy\n\n## Measured times\n\nA fresh run: 3 s ([the study](study.toml), "
        "[web](https://x.org/a), [here](#toy)).\n\n## Other\n\nnot copied\n"
    )
    assert main(["reproductions", "docs/summary.md", "."]) == 0
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "## Measured times per example\n" in page and "not copied" not in page
    assert "### [.](../README.md)\n\nA fresh run: 3 s ([the study](../study.toml), " in page
    assert "[web](https://x.org/a), [here](#toy))." in page
    capsys.readouterr()
    assert main(["reproductions", "s.md", "data"]) == 2
    assert one_error_line(capsys) == (
        "data: no paper.json below it: run the examples first (make reproduce)"
    )


def test_a_run_that_names_an_unknown_quantity_fails_with_the_list(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER.replace('quantity = "converged"', 'quantity = "pm.E"'))
    assert main(["run", "study.toml"]) == 2
    line = one_error_line(capsys)
    assert line.startswith(
        "study.toml: [[paper.values]] #4 quantity: the result has no quantity 'pm.E'; "
        "available: converged, err_grad, err_res, iterations, mean.E, mean.err_res, mean.nu, "
    ), line


def test_a_paper_table_needs_an_iterator(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    without = STUDY.split("[iterator]")[0] + '[executor]\nkind = "serial"\n'
    write_study(tmp_path, without + PAPER)
    assert main(["validate", "study.toml"]) == 2
    assert one_error_line(capsys) == (
        "study.toml: [paper]: a [paper] table compares an iterator's result with the paper: "
        "give [iterator]"
    )


def test_summary_refuses_a_foreign_json(tmp_path):
    (tmp_path / "paper.json").write_text(json.dumps({"x": 1}))
    with pytest.raises(fbia.ConfigError, match="not a paper.json of fbia"):
        write_summary(tmp_path / "s.md", [tmp_path])
