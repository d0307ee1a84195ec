"""Noise judged over draws (``[synthetic] draws = N``, fbia.studies.draws): one run per draw,
a shared store, the range over the draws, the [paper] rows judged by it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from _studies import one_error_line

import fbia
from fbia.studies.cli import main
from fbia.studies.draws import MIN_DRAWS, DrawRecord, collect, draw_seed, draw_study
from fbia.studies.paper import compare_draws, read_paper

TRUTH_E = 400.0

STUDY = """\
[study]
name = "draws_toy"
seed = 5
output = "out"

[model]
name = "analytic_mound_2d"
options = {{ n_points = 41 }}

[[parameters]]
name = "E"
unit = "Pa"
bounds = [100.0, 800.0]

[[parameters]]
name = "nu"
bounds = [-0.8, 0.45]

[synthetic]
truth = {{ E = 400.0, nu = 0.3 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]
noise_std = 0.002
points = 12
draws = {draws}

[measure]
name = "ray"

[iterator]
name = "levenberg_marquardt"
options = {{ x0 = [ {{ E = 350.0, nu = 0.25 }}, {{ E = 500.0, nu = 0.0 }} ], max_iter = 50 }}

[executor]
kind = "serial"

[paper]
source = "Toy paper"

[[paper.values]]
quantity = "mean.E"
kind = "modulus"
paper = 400.0
unit = "Pa"
why = "the truth: inside the range"

[[paper.values]]
quantity = "mean.E"
kind = "modulus"
paper = 440.0
unit = "Pa"
why = "10 % off: outside the range of 1.6e-2 mm of noise"

[[paper.values]]
quantity = "start.2.iterations"
kind = "ordering"
above = "start.1.iterations"

[[paper.values]]
quantity = "share_negative"
kind = "shown"
paper = 0.0
"""


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    """The toy study over MIN_DRAWS draws, run once (about 15 s)."""
    folder = tmp_path_factory.mktemp("draws")
    path = folder / "study.toml"
    path.write_text(STUDY.format(draws=MIN_DRAWS).replace('"share_negative"', '"x.nu"'))
    result = fbia.run_study(fbia.load_study(path), echo=lambda line: None)
    return folder, result


def test_every_draw_runs_on_its_own_data_with_a_shared_store(ran):
    folder, result = ran
    out = folder / "out"
    assert result.status == "completed" and result.success
    assert len(result.draws) == MIN_DRAWS == len(list((out / "draws").iterdir()))
    seeds = [d.seed for d in result.draws]
    assert len(set(seeds)) == MIN_DRAWS
    assert seeds[0] == fbia.load_study(folder / "study.toml").synthetic.seed  # draw 0: the seed
    assert all((out / "draws" / f"{k:02d}" / "result.json").is_file() for k in range(20))
    assert (out / "store.sqlite").is_file()
    assert not (out / "draws" / "00" / "store.sqlite").exists()  # one store, shared
    saved = json.loads((out / "result.json").read_text())
    assert [d["seed"] for d in saved["draws"]] == seeds


def test_the_range_over_draws_matches_the_fits_standard_error(ran):
    """Paper A's covariance sigma^2 (J^T J)^-1 predicts the scatter of the optimum over noise
    draws: the draws' std of E and nu agree with the fits' standard errors (20 draws: the
    sample std is within about +-16 % (1 sd) of the true one; allowed: x 0.6 to 1.5)."""
    _, result = ran
    for name in ("E", "nu"):
        optima = np.array([d.quantities[f"x.{name}"] for d in result.draws])
        stderr = np.median([d.quantities[f"stderr.{name}"] for d in result.draws])
        assert 0.6 <= optima.std(ddof=1) / stderr <= 1.5, name
    q = result.quantities()
    assert q["low.x.E"] < TRUTH_E < q["high.x.E"]
    assert q["n_judged"] == MIN_DRAWS and q["share_negative.x"] == 0.0


def test_paper_rows_are_judged_over_the_draws(ran):
    folder, _ = ran
    record = json.loads((folder / "out" / "paper.json").read_text())
    verdicts = [r["agrees"] for r in record["rows"]]
    assert verdicts[:2] == [True, False]  # the truth inside, 10 % off outside
    assert verdicts[3] is None  # shown
    assert all(r["n_draws"] == MIN_DRAWS for r in record["rows"])
    low, high = record["rows"][0]["low"], record["rows"][0]["high"]
    assert low < TRUTH_E < high < 440.0
    text = (folder / "out" / "report.md").read_text()
    assert f"over {MIN_DRAWS} noise draws" in text and "inside the range" in text
    assert "central 95 % range over the draws" in text  # the rule, stated


def test_a_second_run_takes_every_forward_run_from_the_store(ran):
    folder, first = ran
    lines: list[str] = []
    again = fbia.run_study(fbia.load_study(folder / "study.toml"), echo=lines.append)
    assert [d.quantities["x.E"] for d in again.draws] == [d.quantities["x.E"] for d in first.draws]
    totals = [line for line in lines if " run now " in line]  # "27 evaluations: 0 run now"
    assert len(totals) == MIN_DRAWS
    assert all(line.split()[2] == "0" for line in totals), totals


def test_too_few_or_lost_draws_are_unreliable():
    ok = DrawRecord(0, 1, "converged_gradient", True, "", 10, 1.0, {"x.E": 400.0})
    bad = DrawRecord(1, 2, "all_failed", False, "", 10, 1.0, {})
    assert collect([ok] * 5, "lm").status == "unreliable"  # fewer than MIN_DRAWS
    assert collect([ok] * 20 + [bad] * 3, "lm").status == "unreliable"  # 13 % lost
    assert collect([ok] * 18 + [bad] * 2, "lm").status == "completed"  # 10 % lost
    assert collect([ok] * 27 + [bad] * 3, "lm").status == "completed"  # 10 % lost
    assert collect([bad] * 3, "lm").status == "no_result"
    spec = read_paper(
        {"source": "S", "values": [{"quantity": "x.E", "kind": "modulus", "paper": 400.0}]},
        "s.toml",
    )
    row = compare_draws(spec, [{"x.E": 400.0}] * 5, "unreliable", False)[0]
    assert row.agrees is False and "unreliable" in row.reason


def test_draw_seeds_are_distinct_and_reproducible():
    seeds = [draw_seed(11, k) for k in range(100)]
    assert seeds[0] == 11 and len(set(seeds)) == 100
    assert seeds == [draw_seed(11, k) for k in range(100)]


def test_a_quantity_no_draw_has_is_a_one_line_error():
    spec = read_paper(
        {"source": "S", "values": [{"quantity": "x.F", "kind": "modulus", "paper": 400.0}]},
        "s.toml",
    )
    with pytest.raises(fbia.ConfigError, match=r"no quantity 'x.F'; available: x.E, x.nu"):
        compare_draws(spec, [{"x.E": 1.0}, {"x.E": 2.0, "x.nu": math.nan}])


def test_draws_of_exact_data_are_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    Path("study.toml").write_text(STUDY.format(draws=3).replace("0.002", "0.0"))
    assert main(["validate", "study.toml"]) == 2
    assert one_error_line(capsys) == (
        "study.toml: [synthetic] draws: draws > 1 needs noise_std > 0: exact data draw alike"
    )


def test_every_draw_gets_a_model_of_its_own(tmp_path):
    """A model that warm-starts carries state from run to run; each draw builds its own
    model object with the study's options, so its data and fit do not depend on the draws
    before it (measured: at sigma = 1e-2 mm on ale_fsi, sharing one model changed which draws
    reached the nu bound between a fresh and a resumed run)."""
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(draws=3))
    study = fbia.load_study(path)
    models = [draw_study(study, k, tmp_path, tmp_path / "s.sqlite").model for k in range(3)]
    assert len({id(m) for m in [study.model, *models]}) == 4
    assert all(m.options == study.model.options for m in models)


def test_a_draws_result_loads_back_as_it_was(ran):
    from fbia.studies.draws import DrawsResult

    folder, result = ran
    loaded = fbia.load_result(folder / "out")
    assert isinstance(loaded, DrawsResult)
    assert loaded.draws == result.draws
    got, want = loaded.quantities(), result.quantities()
    assert got.keys() == want.keys() and all(got[k] == want[k] for k in want)
    assert loaded.summary() == result.summary()


@pytest.mark.parametrize(("n", "low", "high"), [(20, 0.85, 0.89), (100, 0.92, 0.945)])
def test_the_range_of_n_draws_holds_a_further_draw_as_the_rule_states(n, low, high):
    """DRAWS_RULE and the draws module state how often the 2.5-97.5 % range of N draws holds
    a further draw (about 87 % at N = 20, 93 % at N = 100): the coverage of the percentiles,
    which does not depend on the distribution (exact value by the order statistics of uniform
    draws, (h_high - h_low) / (N + 1) for the interpolated positions h)."""
    rng = np.random.default_rng(11)
    u = rng.uniform(size=(20_000, n))  # F(X) of any continuous distribution
    covered = np.percentile(u, 97.5, axis=1) - np.percentile(u, 2.5, axis=1)
    assert low < covered.mean() < high
    h = np.array([0.025, 0.975]) * (n - 1)  # 0-based interpolated positions
    assert low < (h[1] - h[0]) / (n + 1) < high
