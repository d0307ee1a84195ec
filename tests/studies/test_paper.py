"""The [paper] table of a study file: schema, quantities of results, the report and summary."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from _paths import ROOT
from _studies import STUDY, one_error_line, write_study

import fbia
from fbia.iterators.convergence.result import ConvergenceRow, SurrogateConvergenceResult
from fbia.iterators.gp_smc.result import DesignRuns, GpSmcResult, ParticlePosterior, PosteriorCheck
from fbia.studies.cli import main
from fbia.studies.paper import KINDS, compare, lookup, read_paper
from fbia.studies.paper_report import PaperRecord, comparison_table, rules_table, write_summary
from fbia.studies.study_sources import read_sources

EXAMPLES = ROOT / "examples"
PAPER_STUDIES = sorted(
    p
    for p in [*EXAMPLES.glob("paper_*/*/*.toml"), *EXAMPLES.glob("growth/*.toml")]
    if "paper" in read_sources(p).raw
)

PAPER = """
[paper]
source = "Toy paper, Table 9"
note = "exact data"

[[paper.values]]
quantity = "x.E"
kind = "modulus"
paper = 400.0
unit = "Pa"
why = "exact data: the optimum is the truth"

[[paper.values]]
quantity = "x.nu"
kind = "ratio"
paper = 0.35
why = "a number chosen to disagree"

[[paper.values]]
quantity = "x.E"
kind = "ordering"
above = "x.nu"
label = "E above nu"

[[paper.values]]
quantity = "converged"
kind = "count"
paper = 1
"""

KINDS_LIST = "modulus, ratio, scale, count, ordering, shown"


def _spec(values: list[dict], **paper) -> fbia.studies.paper.PaperSpec:
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
            [{"quantity": "x.E", "kind": "modulus", "paper": 1.0, "tol": 1}],
            "s.toml: [[paper.values]] #1: unknown key 'tol'; valid keys: quantity, kind, paper, "
            "unit, above, below, label, why",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "modulus", "paper": "400"}],
            "s.toml: [[paper.values]] #1 paper: expected a number, got a string '400'",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0}],
            "s.toml: [[paper.values]] #1: missing key 'kind'",
        ),
        (
            {},
            [{"quantity": "x.E", "paper": 1.0, "rule": "relative", "tolerance": 0.05}],
            "s.toml: [[paper.values]] #1 rule: 'rule' is no longer given per value: give kind = "
            f"one of {KINDS_LIST} instead: the kind fixes the rule",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "modulus", "paper": 1.0, "tolerance": 0.5}],
            "s.toml: [[paper.values]] #1 tolerance: 'tolerance' is no longer given per value: "
            f"give kind = one of {KINDS_LIST} instead: the kind fixes the tolerance",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "ordering", "than": "x.nu"}],
            "s.toml: [[paper.values]] #1 than: 'than' is no longer given per value: an ordering "
            'is kind = "ordering" with above = or below = the other quantity',
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "close", "paper": 1.0}],
            f"s.toml: [[paper.values]] #1 kind: unknown kind 'close'; valid: {KINDS_LIST}",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "count"}],
            "s.toml: [[paper.values]] #1: kind 'count' needs the published value 'paper'",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "ordering"}],
            "s.toml: [[paper.values]] #1: kind 'ordering' needs one of 'above' and 'below' (the "
            "quantity to compare with)",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "ordering", "above": "a", "below": "b"}],
            "s.toml: [[paper.values]] #1: kind 'ordering' needs one of 'above' and 'below' (the "
            "quantity to compare with)",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "ordering", "above": "x.nu", "paper": 1.0}],
            "s.toml: [[paper.values]] #1 paper: kind 'ordering' compares two quantities of the "
            "result: it takes no 'paper'",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "modulus", "paper": 1.0, "below": "x.nu"}],
            "s.toml: [[paper.values]] #1 below: 'below' only for kind 'ordering', not 'modulus'",
        ),
        (
            {},
            [{"quantity": "x.E", "kind": "scale", "paper": -1.0}],
            "s.toml: [[paper.values]] #1: kind 'scale' needs a positive paper value, got -1.0",
        ),
    ],
)
def test_paper_table_mistakes_are_one_located_line(paper, values, message):
    with pytest.raises(fbia.ConfigError) as err:
        _spec(values, **paper)
    assert str(err.value) == message


@pytest.mark.parametrize(
    ("kind", "paper", "fbia_value", "agrees"),
    [
        ("modulus", 400.0, 400.0 * 1.019, True),  # 1.9 % off
        ("modulus", 400.0, 400.0 * 0.981, True),
        ("modulus", 400.0, 400.0 * 1.021, False),  # 2.1 % off
        ("modulus", 400.0, 400.0 * 0.979, False),
        ("ratio", 0.3, 0.319, True),  # 0.019 off
        ("ratio", 0.3, 0.281, True),
        ("ratio", 0.3, 0.321, False),  # 0.021 off
        ("ratio", -0.6, -0.579, False),
        ("ratio", 0.0, 0.019, True),
        ("scale", 1e-3, 1.9e-3, True),  # a factor 1.9
        ("scale", 1e-3, 1e-3 / 1.9, True),
        ("scale", 1e-3, 2.1e-3, False),  # a factor 2.1
        ("scale", 1e-3, 1e-3 / 2.1, False),
        ("scale", 1e-3, -1e-3, False),
        ("count", 11.0, 11.0, True),
        ("count", 11.0, 10.0, False),
        ("count", 1.0, 1.0 + 1e-12, False),  # counts are exact
        ("modulus", 400.0, math.nan, False),  # no result agrees with nothing
        ("shown", 400.0, 100.0, None),
        ("shown", 400.0, math.nan, None),
    ],
)
def test_each_kind_has_one_rule_strict_enough_to_fail(kind, paper, fbia_value, agrees):
    (row,) = compare(_spec([{"quantity": "q", "kind": kind, "paper": paper}]), {"q": fbia_value})
    assert row.agrees is agrees
    assert row.reason == ""


def test_orderings_compare_two_quantities_of_the_result():
    q = {"olive": 57.0, "red": 8.0, "bad": math.nan}
    spec = _spec(
        [
            {"quantity": "olive", "kind": "ordering", "above": "red"},
            {"quantity": "olive", "kind": "ordering", "below": "red"},
            {"quantity": "red", "kind": "ordering", "below": "olive"},
            {"quantity": "olive", "kind": "ordering", "above": "bad"},
        ]
    )
    rows = compare(spec, q)
    assert [r.agrees for r in rows] == [True, False, True, False]
    assert rows[0].reference == 8.0 and rows[0].value.criterion() == "> red"
    assert rows[1].value.criterion() == "< red"
    with pytest.raises(fbia.ConfigError, match=r"#1 above: the result has no quantity 'red'"):
        compare(spec, {"olive": 1.0})


@pytest.mark.parametrize(
    ("status", "success", "reason"),
    [
        ("unreliable", False, "the result is flagged unreliable (status unreliable)"),
        ("unreliable", True, "the result is flagged unreliable (status unreliable)"),
        ("max_iterations", False, "the result is not a success (status max_iterations)"),
    ],
)
def test_an_unreliable_result_agrees_with_nothing(status, success, reason):
    q = {"x.E": 400.0, "x.nu": 0.3, "n": 2.0, "m": 1.0}
    spec = _spec(
        [
            {"quantity": "x.E", "kind": "modulus", "paper": 400.0},
            {"quantity": "x.nu", "kind": "ratio", "paper": 0.3},
            {"quantity": "n", "kind": "count", "paper": 2.0},
            {"quantity": "n", "kind": "ordering", "above": "m"},
            {"quantity": "x.E", "kind": "shown", "paper": 400.0},
        ]
    )
    assert [r.agrees for r in compare(spec, q, "completed", True)] == [True] * 4 + [None]
    rows = compare(spec, q, status, success)
    assert [r.agrees for r in rows] == [False] * 4 + [None]  # shown rows stay unjudged
    assert [r.reason for r in rows] == [reason] * 4 + [""]
    assert rows[0].rel_diff == 0.0  # the numbers are still shown
    line = comparison_table(rows)[2]
    assert f"| **no**: {reason} |" in line


def test_an_undetermined_quantity_agrees_with_nothing_that_uses_it():
    # the result says its histogram MAP of nu is decided by Monte Carlo noise: a row of it,
    # or an ordering against it, is "no" with that reason; the rest are judged as usual
    q = {"map.E": 400.0, "map.nu": 0.3, "map.E2": 200.0}
    spec = _spec(
        [
            {"quantity": "map.E", "kind": "modulus", "paper": 400.0},
            {"quantity": "map.nu", "kind": "ratio", "paper": 0.3},
            {"quantity": "map.E", "kind": "ordering", "above": "map.nu"},
            {"quantity": "map.E", "kind": "ordering", "above": "map.E2"},
            {"quantity": "map.nu", "kind": "shown"},
        ]
    )
    why = "the histogram MAP's interval of nu is not determined"
    rows = compare(spec, q, "completed", True, {"map.nu": why})
    assert [r.agrees for r in rows] == [True, False, False, True, None]
    assert [r.reason for r in rows][:3] == ["", why, why]
    assert [r.agrees for r in compare(spec, q, "completed", True, {})][:4] == [True] * 4


def test_the_rules_are_the_kinds_table():
    assert {k: (v.rule, v.tolerance) for k, v in KINDS.items()} == {
        "modulus": ("relative", 0.02),
        "ratio": ("absolute", 0.02),
        "scale": ("factor", 2.0),
        "count": ("equal", None),
        "ordering": ("ordering", None),
        "shown": ("none", None),
    }
    text = "\n".join(rules_table())
    for name, kind in KINDS.items():
        assert f"| `{name}` | {kind.covers} | {kind.criterion}: " in text
    assert "within 2 %: \\|f - p\\| <= 0.02 \\|p\\|" in text
    assert "within a factor 2: \\|log2(f / p)\\| <= 1" in text


def test_an_unknown_quantity_lists_the_available_ones():
    spec = _spec([{"quantity": "mean.E", "paper": 1.0, "kind": "count"}])
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
    assert res.undetermined() == {} and "map_support.E" not in q  # the best particle's MAP
    res.posterior = dataclasses.replace(post, map_support=np.array([0.97, 0.41]))
    q = res.quantities()
    assert (q["map_support.E"], q["map_support.nu"]) == (0.97, 0.41)
    assert list(res.undetermined()) == ["map.nu"] and "41 %" in res.undetermined()["map.nu"]
    assert "not determined (< 90 %): nu" in res.summary()
    res.posterior = post
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
        [{"quantity": "n_train.200.distance", "kind": "ordering", "below": "n_train.10.distance"}]
    )
    assert compare(spec, q)[0].agrees is True


def test_comparison_table_has_the_published_and_fbia_columns():
    rows = compare(
        _spec(
            [
                {
                    "quantity": "x.E",
                    "kind": "modulus",
                    "paper": 400.0,
                    "unit": "Pa",
                    "why": "a | b",
                },
                {"quantity": "s", "kind": "scale", "paper": 1e-3, "unit": "mm"},
            ]
        ),
        {"x.E": 410.0, "s": 4e-4},
    )
    lines = comparison_table(rows)
    assert lines[0] == "| quantity | paper | fbia | difference | rel. | agrees? | why |"
    assert lines[2] == "| x.E | 400 Pa | 410 Pa | 10 | +2.5 % | **no** (within 2 %) | a \\| b |"
    assert lines[3] == (
        "| s | 0.001 mm | 0.0004 mm | -0.0006 | f/p = 0.4 | **no** (within a factor 2) |  |"
    )


def test_run_writes_report_and_the_summary_collects_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER)
    assert main(["run", "study.toml"]) == 0
    out = tmp_path / "out"
    report = (out / "report.md").read_text()
    assert report.startswith("# tiny: fbia beside Toy paper, Table 9")
    assert "3 of 4 published numbers agree by the rule of their kind." in report
    assert "| x.nu | 0.35 | 0.3 | -0.05 | -14.3 % | **no** (within 0.02) |" in report
    assert "| E above nu | > x.nu (0.3) | 400 |  |  | yes (> x.nu) |" in report
    assert "## Rules\n\n" + "\n".join(rules_table()) in report
    assert "![plots/interfaces.png](plots/interfaces.png)" in report
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
    assert page.count("| `modulus` |") == 1  # the rules once, at the top
    assert page.index("## Rules") < page.index("## tiny")
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
        "data: no paper.json below them: run the examples first (make reproduce)"
    )


def test_the_summary_marks_a_row_whose_code_changed_since_it_was_made(
    tmp_path, monkeypatch, caplog
):
    """Issue 46 item 1: paper.json records the commit and the code of the study's model,
    measure and iterator; the page says per study whether that code is what runs now, and
    marks a row made by other code (here: the recorded digest of one of the model's files
    edited, as a change of the model would leave it) or by an fbia that did not record it."""
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER)
    assert main(["run", "study.toml"]) == 0
    path = tmp_path / "out" / "paper.json"
    record = PaperRecord.read(path)
    assert set(record.code) == {"model", "measure", "iterator"}
    assert record.code["model"]["class"].startswith("fbia.plugins.analytic.")
    assert record.code["model"]["files"] and record.code["model"]["sha256"]
    assert main(["reproductions", "docs/summary.md", "."]) == 0
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert (
        "unchanged |" in page and "the code of its model, measure and iterator is unchanged" in page
    )
    data = json.loads(path.read_text())
    recorded = json.loads(json.dumps(data["code"]))
    files = data["code"]["model"]["files"]
    first = sorted(files)[0]
    files[first] = "code:" + "0" * 64
    data["code"]["model"]["sha256"] = "0" * 64
    path.write_text(json.dumps(data))
    assert main(["reproductions", "docs/summary.md", "."]) == 0
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "**changed since: model** |" in page
    assert f"**The code has changed since**: model ({first})" in page
    # a record of an earlier fbia, of the files' bytes: unchanged while they are, and
    # recorded in the current form (without documentation) by the page
    from fbia.storage.fingerprints import code_digest_like

    data["code"] = {
        role: code_digest_like({"files": {"x": "0" * 64}}, _class_of(d))
        for role, d in recorded.items()
    }
    path.write_text(json.dumps(data))
    # a record that cannot be written keeps its old form, with a warning; its row is unchanged
    real_write = Path.write_text

    def refuse(self: Path, *args: object, **kwargs: object) -> int:
        if self.name == "paper.json":
            raise PermissionError("read-only")
        return real_write(self, *args, **kwargs)  # type: ignore[arg-type]

    with monkeypatch.context() as m:
        m.setattr(Path, "write_text", refuse)
        caplog.clear()
        assert main(["reproductions", "docs/summary.md", "."]) == 0
    assert "its code digests stay in the old form (read-only)" in caplog.text
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "the code of its model, measure and iterator is unchanged" in page
    assert json.loads(path.read_text())["code"] == data["code"]
    caplog.clear()
    with caplog.at_level("INFO", logger="fbia.studies.paper_report"):
        assert main(["reproductions", "docs/summary.md", "."]) == 0
    assert "recorded without documentation" in caplog.text and "old form" not in caplog.text
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "the code of its model, measure and iterator is unchanged" in page
    assert json.loads(path.read_text())["code"] == recorded
    caplog.clear()  # in the current form: nothing to write, nothing said
    with caplog.at_level("INFO", logger="fbia.studies.paper_report"):
        assert main(["reproductions", "docs/summary.md", "."]) == 0
    assert "code digests" not in caplog.text
    del data["code"]
    path.write_text(json.dumps(data))
    assert main(["reproductions", "docs/summary.md", "."]) == 0
    page = (tmp_path / "docs" / "summary.md").read_text()
    assert "| not recorded: **rerun** |" in page


def test_a_run_that_names_an_unknown_quantity_fails_with_the_list(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER.replace('quantity = "converged"', 'quantity = "pm.E"'))
    assert main(["run", "study.toml"]) == 2
    line = one_error_line(capsys)
    assert line.startswith(
        "study.toml: [[paper.values]] #4 quantity: the result has no quantity 'pm.E'; "
        "available: chi2, converged, err_grad, err_res, iterations, mean.E, mean.err_res, "
        "mean.nu, "
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


def test_a_readme_that_is_not_utf8_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_study(tmp_path, STUDY + PAPER)
    assert main(["run", "study.toml"]) == 0
    (tmp_path / "README.md").write_bytes(b"## Measured times\n\xff 10 s\n")
    assert main(["reproductions", "docs/summary.md", "."]) == 2
    assert one_error_line(capsys) == f"{tmp_path / 'README.md'}: not UTF-8 (byte 18)"


def test_a_study_file_with_a_per_value_rule_is_one_line_naming_the_file(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    old = PAPER.replace('kind = "ratio"', 'rule = "absolute"\ntolerance = 0.1')
    write_study(tmp_path, STUDY + old)
    assert main(["validate", "study.toml"]) == 2
    assert one_error_line(capsys) == (
        "study.toml: [[paper.values]] #2 rule: 'rule' is no longer given per value: give kind "
        f"= one of {KINDS_LIST} instead: the kind fixes the rule"
    )


def test_a_paper_json_of_the_per_row_rules_is_listed_stale(tmp_path):
    """paper.json files written before the kinds (rows with their own rule and tolerance)
    keep their lenient verdicts out of the summary."""
    old_row = {
        "value": {
            "quantity": "std.E",
            "paper": 0.01168,
            "unit": "Pa",
            "rule": "magnitude",
            "tolerance": 2.0,
            "than": None,
            "label": "",
            "why": "within a factor 100",
        },
        "fbia": 0.0005119,
        "abs_diff": -0.01117,
        "rel_diff": -0.956,
        "agrees": True,
        "reference": None,
    }
    record = {
        "study": "old",
        "study_file": str(tmp_path / "study.toml"),
        "source": "Paper A, Table 2",
        "note": "",
        "status": "converged_gradient",
        "wall_time": 64.0,
        "forward_time": 60.0,
        "nfev": 444,
        "finished": "2024-01-01",
        "rows": [old_row],
        "reused": 0,
    }
    (tmp_path / "study.toml").write_text('[paper]\nsource = "Paper A, Table 2"\n')
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "paper.json").write_text(json.dumps(record))
    rec = PaperRecord.read(tmp_path / "out" / "paper.json")
    assert rec.stale and rec.rows == ()
    page, n = write_summary(tmp_path / "s.md", [tmp_path])
    text = page.read_text()
    assert n == 1
    assert "| [old](#old) | Paper A, Table 2 | stale | converged_gradient |" in text
    assert "This `paper.json` is stale: written by an older fbia" in text
    assert "within a factor 100" not in text and "magnitude" not in text


@pytest.mark.parametrize("path", PAPER_STUDIES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_paper_examples_tables_read_under_the_kinds(path):
    """Every [paper] table of examples/paper_*: kinds only, each row a kind's rule."""
    spec = read_paper(read_sources(path).raw["paper"], str(path))
    assert spec.values and all(v.kind in KINDS for v in spec.values)


def test_there_are_paper_examples_to_check():
    assert len(PAPER_STUDIES) >= 27  # Paper A: 16 and growth 2, Paper B: 9


def _ran(folder, name: str, source: str, rows: tuple, table: bool = True) -> None:
    """A study file ``name.toml`` (with a [paper] table of ``source``, or without one) and the
    ``out_name/paper.json`` its run wrote with ``rows``."""
    text = f'[paper]\nsource = "{source}"\n' if table else f'[study]\nname = "{name}"\n'
    (folder / f"{name}.toml").write_text(text)
    rec = PaperRecord(
        name, str(folder / f"{name}.toml"), source, "", "converged_gradient", 1.0, 1.0, 3,
        "now", rows,
    )  # fmt: skip
    (folder / f"out_{name}").mkdir()
    (folder / f"out_{name}" / "paper.json").write_text(json.dumps(rec.to_dict()))


def test_the_summary_counts_all_rows_and_lists_studies_not_run_and_records_left_out(tmp_path):
    """The page totals the verdicts; a study file with [paper] but no paper.json is listed as
    not run; a paper.json whose study file lost its [paper] table is left out (and listed)."""
    spec = read_paper(
        {
            "source": "S",
            "values": [
                {"quantity": "x.E", "kind": "modulus", "paper": 400.0},
                {"quantity": "x.nu", "kind": "ratio", "paper": 0.5},
            ],
        },
        "a.toml",
    )
    rows = tuple(compare(spec, {"x.E": 401.0, "x.nu": 0.3}))
    for name, table in (("a", True), ("b", False)):
        _ran(tmp_path, name, "S", rows, table)
    (tmp_path / "study_c.toml").write_text('[paper]\nsource = "S"\n')  # never run
    page, n = write_summary(tmp_path / "s.md", [tmp_path])
    text = page.read_text()
    assert n == 1 and "| [a](#a) | S | 1 / 2 |" in text and "## b" not in text
    assert "In all: 1 of 2 judged published numbers agree (50 %)." in text
    assert "have no `paper.json` (not run yet):\n\n- `study_c.toml`" in text
    assert "has no `[paper]` table (any more):\n\n- `out_b/paper.json`" in text


def test_the_summary_counts_each_published_number_once(tmp_path):
    """Issue 46 item 3: a published number two studies judge (a Table 2 row over one draw
    and over many draws) is one number in the totals, and agrees only where it agrees in
    both; the per-study verdicts stay as they are."""
    spec = read_paper(
        {
            "source": "Paper A, Table 2",
            "values": [
                {"quantity": "mean.E", "kind": "modulus", "paper": 408.0},
                {"quantity": "mean.nu", "kind": "ratio", "paper": 0.378},
            ],
        },
        "a.toml",
    )
    one = tuple(compare(spec, {"mean.E": 409.0, "mean.nu": 0.30}))  # E agrees, nu not
    many = tuple(compare(spec, {"mean.E": 430.0, "mean.nu": 0.38}))  # E not, nu agrees
    for name, rows in (("one", one), ("many", many)):
        _ran(tmp_path, name, "Paper A, Table 2", rows)
    page, n = write_summary(tmp_path / "s.md", [tmp_path])
    text = page.read_text()
    assert n == 2 and "| [one](#one) | Paper A, Table 2 | 1 / 2 |" in text
    assert "| [many](#many) | Paper A, Table 2 | 1 / 2 |" in text
    assert "In all: 0 of 2 judged published numbers agree (0 %). Each published number is " in text
    assert "counted once (4 judgements over the studies)" in text


def _class_of(digest: dict) -> type:
    import importlib

    module, _, name = digest["class"].rpartition(".")
    return getattr(importlib.import_module(module), name)
