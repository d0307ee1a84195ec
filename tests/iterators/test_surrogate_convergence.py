"""The ``surrogate_convergence`` iterator (Paper B Fig. 8): the GP of L on growing prefixes of
one Sobol design, its ML point and held-out error per n_train; the design is gp_smc's, so a
store shares the runs; and studies that name one ``[study] store`` share their forward runs."""

from __future__ import annotations

import numpy as np
import pytest
from _studies import STUDY, write_study

import fbia
from fbia.iterators.surrogates.design import sobol_design
from fbia.storage.store import StudyStore

TRUTH = {"E": 400.0, "nu": 0.3}


def _problem() -> fbia.InverseProblem:
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    obs = fbia.synthetic_observations(model, TRUTH, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0)
    return fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=obs,
        noise_std=0.01,
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
    )


def test_the_ml_point_approaches_the_truth_and_the_held_out_error_falls(tmp_path):
    it = fbia.iterator(
        "surrogate_convergence", n_train=[10, 40, 160], n_test=40, seed=0, reference=TRUTH
    )
    result = it.run(_problem())
    assert result.status == "completed" and result.nfev == 200 and result.n_failed == 0
    assert [r.n_train for r in result.rows] == [10, 40, 160]
    assert [r.n_used for r in result.rows] == [10, 40, 160]
    first, last = result.rows[0], result.rows[-1]
    # measured: |ML - truth| in box units 0.10, 0.14, 0.003; held-out RMSE in L 164, 37, 11
    assert last.reference_distance < 0.03 < first.reference_distance
    assert last.ml_point["E"] == pytest.approx(400.0, abs=15.0)
    assert last.test_rmse < 0.1 * first.test_rmse
    assert result.x == last.ml_point
    # the GP mean at its ML point is at least the best training run's L
    assert last.ml_log_likelihood >= np.max(result.log_likelihood[:160]) - 1e-6
    # Fig. 12's gain of a larger design: the held-out error at a over the one at n
    q = result.quantities()
    rel = {r.n_train: r.test_relative_l2 for r in result.rows}
    assert q["n_train.160.gain_over.10"] == pytest.approx(rel[10] / rel[160])
    assert q["n_train.40.gain_over.10"] == pytest.approx(rel[10] / rel[40])
    assert "n_train.10.gain_over.40" not in q and q["n_train.160.gain_over.10"] > 1.0
    text = result.summary()
    assert "n_train" in text and "|ML-ref|" in text
    assert result.to_dict()["info"]["rows"][-1]["n_train"] == 160  # JSON without GP states
    paths = it.write_plots(result, _problem(), tmp_path)
    assert sorted(p.name for p in paths) == [
        "surrogate_convergence.png",
        "surrogate_convergence_fields.png",
    ]


def test_its_design_is_gp_smcs_so_a_store_runs_nothing_twice(tmp_path):
    problem = _problem()
    x = sobol_design(problem.parameters, 30, seed=4)
    with StudyStore(tmp_path / "store.sqlite") as store:
        store.bind(problem)
        with fbia.SerialEvaluator(store=store) as ev:
            smc = fbia.iterator(
                "gp_smc", design="sobol", n_train=30, seed=4, n_particles=100, n_check=0
            )
            first = smc.run(problem, ev)
        assert first.design is not None
        np.testing.assert_array_equal(first.design.points, x)
        with fbia.SerialEvaluator(store=store) as ev:
            it = fbia.iterator("surrogate_convergence", n_train=[10, 20], n_test=10, seed=4)
            result = it.run(problem, ev)
            assert len(ev.reused) == 30  # every point came from the store
    np.testing.assert_array_equal(result.points, x)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"n_train": [20, 10]}, "increasing"),
        ({"n_train": [1, 10]}, "increasing"),
        ({"reference": {"E": 400.0}}, "the inputs are"),
    ],
)
def test_bad_options_are_one_line_errors(options, message):
    with pytest.raises(fbia.ConfigError, match=message):
        fbia.iterator("surrogate_convergence", **options).run(_problem())


def test_studies_that_name_one_store_share_its_forward_runs(tmp_path, capsys):
    write_study(tmp_path)
    text = STUDY.replace('output = "out"', 'output = "out_a"\nstore = "shared/runs.sqlite"')
    text = text.replace(
        'name = "levenberg_marquardt"\noptions = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }',
        'name = "surrogate_convergence"\noptions = { n_train = [8, 16], n_test = 4 }',
    )
    (tmp_path / "a.toml").write_text(text)
    (tmp_path / "b.toml").write_text(
        text.replace('"out_a"', '"out_b"').replace('name = "cpp"', 'name = "ray"')
    )
    first = fbia.run_study(fbia.load_study(tmp_path / "a.toml"), echo=lambda _: None)
    second = fbia.run_study(fbia.load_study(tmp_path / "b.toml"), echo=print)
    assert first.nfev == second.nfev == 20
    assert "0 run now (0 failed), 20 taken from the store" in capsys.readouterr().out
    assert (tmp_path / "shared" / "runs.sqlite").exists()
    assert not (tmp_path / "out_a" / "store.sqlite").exists()
    assert (tmp_path / "out_b" / "result.json").exists()
