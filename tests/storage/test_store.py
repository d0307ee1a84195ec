"""The study store: exact round trips, the problem hash, reuse instead of recomputation, locks.

The toy model (tests/_models.py) is closed form, so every stored value has an exact expected
value; everything here runs serially in this process (no worker start-up).
"""

from __future__ import annotations

import dataclasses
import math
import sqlite3

import numpy as np
import pytest
from _models import ToyMoundForwardModel, toy_curve, toy_problem

import fbia
from fbia.core.likelihood import gaussian_log_likelihood
from fbia.storage.fingerprints import (
    comparison_key,
    comparison_part,
    coordinates_of,
    model_part,
    problem_fingerprint,
    run_key,
)
from fbia.storage.store import StudyStore

POINTS = [{"E": 200.0, "nu": 0.1}, {"E": 400.0, "nu": 0.3}, {"E": 700.0, "nu": 0.2}]


def _exact_residuals(E: float, nu: float) -> np.ndarray:
    return toy_curve(E, nu)[:, 1] - toy_curve(400.0, 0.3)[:, 1]


def _problem(noise_std: float | None = 0.01, **options) -> fbia.InverseProblem:
    problem = toy_problem(fail_above=650.0, **options)
    return dataclasses.replace(problem, noise_std=noise_std)


@pytest.fixture
def store(tmp_path):
    with StudyStore(tmp_path / "store.sqlite") as s:
        yield s


def test_records_round_trip_exactly_and_the_likelihood_is_computed_on_read(store, tmp_path):
    problem = _problem()
    store.bind(problem)
    with fbia.SerialEvaluator(workdir=tmp_path / "runs", store=store) as ev:
        records = ev.evaluate(problem, POINTS)
    assert [r.status for r in records] == ["ok", "ok", "failed"]
    stored = store.lookup(store.key(p) for p in POINTS)
    assert len(stored) == 3 and len(store) == 3
    for r, p in zip(records, POINTS, strict=True):
        run = stored[store.key(p)]
        got = run.record
        assert (got.index, got.x, got.status, got.message) == (r.index, p, r.status, r.message)
        assert (got.time, got.workdir, got.distances) == (r.time, r.workdir, r.distances)
        assert got.diagnostics == r.diagnostics
        assert run.attempt == 1 and run.worker and run.session is None
        if r.ok:  # bit-exact residuals; L = -n/2 log(2 pi s^2) - D^2 / (2 s^2), n = 21
            np.testing.assert_array_equal(got.residuals, r.residuals)
            np.testing.assert_array_equal(got.residuals, _exact_residuals(p["E"], p["nu"]))
            d = np.linalg.norm(_exact_residuals(p["E"], p["nu"]))
            expected = -10.5 * math.log(2 * math.pi * 1e-4) - d**2 / 2e-4
            assert gaussian_log_likelihood(got, [0.01]) == pytest.approx(expected, rel=1e-14)
        else:
            assert got.residuals is None and gaussian_log_likelihood(got, [0.01]) == -math.inf
            assert got.message == "mesh distortion at E = 700.0"
    # the SQLite file is in WAL mode and readable by any client
    db = sqlite3.connect(store.path)
    assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    rows = db.execute("SELECT status, count(*) FROM runs GROUP BY status").fetchall()
    assert dict(rows) == {"ok": 2, "failed": 1}
    assert db.execute("SELECT count(*) FROM comparisons").fetchone() == (2,)
    db.close()


def test_long_residual_vectors_stay_in_the_store_not_in_the_json_records(tmp_path):
    """rkhs's default residual vector (~30 000 entries per flow-cell run) made a 1000-run
    study's result.json and evaluations.jsonl 600-760 MB; the JSON keeps their count only."""
    from fbia.core.problem import JSON_RESIDUALS_MAX

    short = fbia.Evaluation(index=0, x={"E": 1.0}, residuals=np.arange(3.0), distances=[1.0])
    long = fbia.Evaluation(
        index=1, x={"E": 1.0}, residuals=np.ones(JSON_RESIDUALS_MAX + 1), distances=[2.0]
    )
    assert short.to_dict()["residuals"] == [0.0, 1.0, 2.0]
    assert short.to_dict()["n_residuals"] == 3
    assert long.to_dict()["residuals"] is None
    assert long.to_dict()["n_residuals"] == JSON_RESIDUALS_MAX + 1
    assert long.to_dict()["distances"] == [2.0]


def test_log_likelihood_sums_observations_with_their_own_sigmas():
    ev = fbia.Evaluation(0, {}, residuals=np.zeros(10), distances=[0.3, 0.4])
    # n_k = 5 residuals per observation, sigma 0.1 and 0.2
    expected = sum(
        -2.5 * math.log(2 * math.pi * s**2) - d**2 / (2 * s**2) for d, s in [(0.3, 0.1), (0.4, 0.2)]
    )
    assert gaussian_log_likelihood(ev, [0.1, 0.2]) == pytest.approx(expected, rel=1e-14)


def _keys(problem: fbia.InverseProblem, x) -> tuple[str, str]:
    fp = problem_fingerprint(problem)
    return (
        run_key(model_part(fp), coordinates_of(fp), x),
        comparison_key(comparison_part(fp)),
    )


def test_a_run_is_keyed_by_what_the_forward_model_depends_on_and_nothing_else():
    x = POINTS[0]
    base_run, base_cmp = _keys(_problem(), x)
    assert _keys(_problem(), x) == (base_run, base_cmp)  # same content, new objects
    # neither depends on sigma_N, bounds or priors
    p = _problem(noise_std=0.02)
    p.parameters = [fbia.Parameter("E", bounds=(50.0, 900.0)), p.parameters[1]]
    assert _keys(p, x) == (base_run, base_cmp)
    # the forward run depends on the model options, the fixed inputs and the coordinates
    obs = _problem().observations[0]
    for changed in (
        _problem(delay=0.5),
        dataclasses.replace(_problem(), fixed={"inflow_rate": 90.0}),
        dataclasses.replace(
            _problem(), observations=[dataclasses.replace(obs, coordinate={"inflow_rate": 90.0})]
        ),
    ):
        assert _keys(changed, x)[0] != base_run
    # the comparison on the measure and the observed data, the run not
    moved = fbia.Interface.polyline(obs.interface.vertices + [0.0, 1e-12])
    other_data = dataclasses.replace(
        _problem(), observations=[dataclasses.replace(obs, interface=moved)]
    )
    other_measure = dataclasses.replace(_problem(), measure=fbia.measure("cpp"))
    for changed in (other_data, other_measure):
        run, cmp = _keys(changed, x)
        assert run == base_run and cmp != base_cmp


def test_keys_are_exact_in_every_bit():
    m, c = {"model": "m"}, [{"q": 1.0}]
    assert run_key(m, c, {"E": 0.3, "nu": 0.1}) == run_key(m, c, {"nu": 0.1, "E": 0.3})
    assert run_key(m, c, {"E": 0.1 + 0.2}) != run_key(m, c, {"E": 0.3})
    assert run_key(m, c, {"E": 1.0}) == run_key(m, c, {"E": 1})
    assert run_key(m, c, {"E": 1.0}) != run_key({"model": "n"}, c, {"E": 1.0})


class _OtherToyForwardModel(ToyMoundForwardModel):
    """Another model class (the same numbers: what matters is the class)."""


def test_other_option_values_share_the_store_another_model_class_says_what_changed(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as store:
        store.bind(_problem())
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(_problem(), POINTS[:2])
    with StudyStore(tmp_path / "s.sqlite") as store:
        store.bind(_problem())  # the same problem, built again: fine
        store.bind(_problem(noise_std=0.02))  # another likelihood: fine
        assert (len(store), store.total(), store.other_models()) == (2, 2, [])
        store.bind(_problem(delay=0.25, noise_std=0.03))  # other option values: kept apart
        assert (len(store), store.counts(), store.total()) == (0, {}, 2)
        assert store.other_models() == [("delay = 0.0", 2)]
        other = dataclasses.replace(
            _problem(noise_std=0.03), model=_OtherToyForwardModel(fail_above=650.0)
        )
        with pytest.raises(fbia.ConfigError) as info:
            store.bind(other)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 's.sqlite'}: the store holds 2 runs of a different ")
    assert "(changed: model _models.ToyMoundForwardModel -> " in message
    assert "_OtherToyForwardModel)" in message
    assert message.endswith("run with --fresh to start over, or write to another --output")


def test_a_new_sigma_or_measure_reuses_every_forward_run(tmp_path):
    """Changing sigma_N reuses the runs as they are; another measure or other observed data
    recompares the stored interfaces, without running the model."""
    with StudyStore(tmp_path / "s.sqlite") as store:
        with fbia.SerialEvaluator(store=store) as ev:
            first = ev.evaluate(_problem(), POINTS)
    for changed in (
        _problem(noise_std=0.5),
        dataclasses.replace(_problem(), measure=fbia.measure("cpp")),
    ):
        with StudyStore(tmp_path / "s.sqlite") as store:
            with fbia.SerialEvaluator(store=store) as ev:
                again = ev.evaluate(changed, POINTS)
            assert ev.reused == {0, 1, 2} and len(store) == 3
            fresh = [changed.evaluate(p) for p in POINTS]
        assert [r.status for r in again] == [r.status for r in first]
        for got, want in zip(again, fresh, strict=True):
            assert got.distances == want.distances
            if want.ok:
                np.testing.assert_array_equal(got.residuals, want.residuals)


def test_stored_runs_are_reused_and_a_point_asked_twice_in_a_batch_runs_once(tmp_path):
    problem = _problem()
    runs = tmp_path / "runs"
    with StudyStore(tmp_path / "s.sqlite") as store:
        with fbia.SerialEvaluator(workdir=runs, store=store) as ev:
            first = ev.evaluate(problem, [POINTS[0], POINTS[2], POINTS[0]])
            assert ev.reused == {2}
        assert len(store) == 2
        assert first[2].distance == first[0].distance and first[2].index == 2
        # a new session asks again, in another order, and a new point
        seen: list[int] = []
        with fbia.SerialEvaluator(
            workdir=runs, store=store, on_record=lambda r: seen.append(r.index)
        ) as ev:
            again = ev.evaluate(problem, [POINTS[2], POINTS[1], POINTS[0]])
            assert ev.reused == {0, 2}
        assert len(store) == 3 and sorted(seen) == [0, 1, 2]
        # numbered by request in this session; stored values unchanged, failures included
        assert [r.index for r in again] == [0, 1, 2]
        assert (again[0].status, again[0].message) == ("failed", "mesh distortion at E = 700.0")
        np.testing.assert_array_equal(again[2].residuals, first[0].residuals)
        # the new run did not reuse the folder eval_000001 of the stored failed run
        assert again[0].workdir == str(runs / "eval_000001")
        assert again[1].workdir == str(runs / "eval_000001-2")
        assert {r.attempt for r in store.runs()} == {1}


def test_retry_failed_runs_each_stored_failure_once_more(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as store:
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(_problem(), POINTS)
    with StudyStore(tmp_path / "s.sqlite") as store:
        problem = _problem()
        with fbia.SerialEvaluator(store=store) as ev:  # a stored failure is a finished run
            assert ev.evaluate(problem, POINTS[2:])[0].status == "failed"
            assert ev.reused == {0}
        with fbia.SerialEvaluator(store=store, retry_failed=True) as ev:
            records = ev.evaluate(problem, POINTS + POINTS[2:])
            assert ev.reused == {0, 1, 3}  # ok runs reused; the failure runs once, then reused
        assert [r.status for r in records] == ["ok", "ok", "failed", "failed"]
        (run,) = [r for r in store.runs() if r.record.status == "failed"]
        assert run.attempt == 2 and len(store) == 3


def test_two_runs_cannot_write_one_store(tmp_path):
    with StudyStore(tmp_path / "s.sqlite"):
        with pytest.raises(fbia.ConfigError, match=r"the study store is in use by fbia run pid"):
            StudyStore(tmp_path / "s.sqlite")
    StudyStore(tmp_path / "s.sqlite").close()  # released with the first


def test_fresh_empties_the_store(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as store:
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(_problem(), POINTS)
    with StudyStore(tmp_path / "s.sqlite", fresh=True) as store:
        assert len(store) == 0 and store.hash is None
        store.bind(_problem(delay=0.1))  # a different problem is fine now


def test_sessions_record_who_ran_what(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as store:
        store.begin_session({"kind": "serial"}, "abc")
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(_problem(), POINTS[:2])
        store.end_session("done")
        store.begin_session({"kind": "processes", "workers": 2}, "abd")
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(_problem(), POINTS)
        sessions = store.sessions()
    assert [(s["id"], s["status"], s["evaluations"]) for s in sessions] == [
        (1, "done", 2),
        (2, "running", 1),
    ]
    assert sessions[1]["executor"] == {"kind": "processes", "workers": 2}
    assert sessions[0]["study_sha256"] == "abc" and sessions[0]["finished"]


def test_a_file_option_counts_by_its_content_not_its_folder(tmp_path):
    """A mesh file named by a study: moving the study keeps its store, editing the file not."""
    from pathlib import Path

    from fbia.core.options import PluginOptions
    from fbia.storage.fingerprints import _options

    class Options(PluginOptions):
        mesh_file: Path | None = None

    class Model:
        def __init__(self, path):
            self.options = Options(mesh_file=path)

    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "cell.msh").write_text("mesh v1")
    a, b = (
        _options(Model(tmp_path / "a" / "cell.msh")),
        _options(Model(tmp_path / "b" / "cell.msh")),
    )
    assert a == b and a["mesh_file"]["file"] == "cell.msh"
    (tmp_path / "b" / "cell.msh").write_text("mesh v2")
    assert _options(Model(tmp_path / "b" / "cell.msh")) != a
    assert _options(Model(None)) == {"mesh_file": None}  # at its default: keyed as None


@pytest.mark.parametrize("isolate", [False, True])
def test_diagnostics_with_nan_and_foreign_objects_are_stored_and_reused(tmp_path, isolate):
    """Issue 14, defect 3: NaN numpy floats or objects JSON does not know in a model's
    diagnostics crashed the study when the run was stored, at every resume again."""
    problem = _problem(odd_diagnostics=True)
    path = tmp_path / "store.sqlite"
    with StudyStore(path) as s, fbia.SerialEvaluator(store=s, isolate=isolate) as ev:
        first = ev.evaluate(problem, POINTS[:2])
    assert [r.status for r in first] == ["ok", "ok"]
    d = first[0].diagnostics
    assert (d["nan"], d["inf"], d["values"], d["kinds"]) == (
        "nan",
        "inf",
        [1.0, "nan", "-inf"],
        ["a", "b"],
    )
    assert d["solver"].startswith("<object object")
    with StudyStore(path) as s, fbia.SerialEvaluator(store=s) as ev:
        again = ev.evaluate(problem, POINTS[:2])
        assert ev.reused == {0, 1}
    assert [r.diagnostics for r in again] == [r.diagnostics for r in first]
