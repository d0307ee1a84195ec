"""A store written by fbia 0.1.0 in the first format (``tests/data/store_v1``) is migrated
when opened, and its runs are reused afterwards: with the same problem, after a change of the
likelihood's sigma_N, and, once rerun (format 1 kept no interfaces), after a measure change.

The fixture holds five runs of ``analytic_mound_2d`` (default options) against the observed
interface stored beside it (read from .npy, so that its digest is the same on every machine),
compared by ``cpp`` with sigma_N = 0.01 mm; ``expected.json`` holds what those runs gave.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from _paths import TESTS

import fbia
from fbia.storage import fingerprints
from fbia.storage.store import STORE_FORMAT, StudyStore

DATA = TESTS / "data" / "store_v1"
EXPECTED = json.loads((DATA / "expected.json").read_text())
POINTS = EXPECTED["points"]


@pytest.fixture(autouse=True)
def as_written_by_fbia_0_1_0(monkeypatch):
    """Runs are keyed by the plugin version too; the fixture was written by 0.1.0."""
    original = fingerprints._class_version

    def pinned(obj):
        out = original(obj)
        return {**out, "version": "0.1.0"} if out["class"].startswith("fbia.") else out

    monkeypatch.setattr(fingerprints, "_class_version", pinned)


@pytest.fixture
def store_path(tmp_path):
    path = tmp_path / "store.sqlite"
    shutil.copy(DATA / "store.sqlite", path)
    return path


def problem(measure: str = "cpp", noise_std: float = 0.01, **measure_options):
    gamma = fbia.Interface(
        np.load(DATA / "observed_vertices.npy"), np.load(DATA / "observed_cells.npy")
    )
    return fbia.InverseProblem(
        model=fbia.forward_model("analytic_mound_2d"),
        measure=fbia.measure(measure, **measure_options),
        observations=[fbia.Observation(gamma, coordinate={"inflow_rate": 100.0})],
        parameters=[
            fbia.Parameter("E", bounds=(100, 800)),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
        noise_std=noise_std,
    )


def evaluate(path: Path, prob: fbia.InverseProblem):
    with StudyStore(path) as store:
        with fbia.SerialEvaluator(store=store) as ev:
            records = ev.evaluate(prob, POINTS)
        return records, ev.reused, len(store), {r.attempt for r in store.runs()}


def test_the_first_format_is_migrated_with_a_copy_of_the_original(store_path):
    with StudyStore(store_path) as store:
        assert len(store) == 5 and store.counts() == {"ok": 5}
        assert [s["status"] for s in store.sessions()] == ["done"]
    db = sqlite3.connect(store_path)
    assert db.execute("SELECT value FROM meta WHERE key = 'format'").fetchone() == (STORE_FORMAT,)
    tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    assert {"runs", "comparisons", "sessions", "meta", "models"} <= tables
    assert "evaluations" not in tables
    # every run under the store's model part (format 3)
    (key,) = db.execute("SELECT value FROM meta WHERE key = 'model_key'").fetchone()
    assert db.execute("SELECT model, count(*) FROM runs GROUP BY model").fetchall() == [(key, 5)]
    assert db.execute("SELECT key FROM models").fetchall() == [(key,)]
    db.close()
    backup = sqlite3.connect(store_path.with_name("store.v1.sqlite"))
    assert backup.execute("SELECT count(*) FROM evaluations").fetchone() == (5,)
    backup.close()


@pytest.mark.parametrize("noise_std", [0.01, 0.05], ids=["same problem", "new sigma_N"])
def test_migrated_runs_are_reused_with_their_results(store_path, noise_std):
    records, reused, n, attempts = evaluate(store_path, problem(noise_std=noise_std))
    assert reused == set(range(5)) and n == 5 and attempts == {1}
    assert [r.status for r in records] == EXPECTED["status"]
    assert [r.distance for r in records] == EXPECTED["distances"]  # bit for bit
    for r, want in zip(records, EXPECTED["residuals"], strict=True):
        assert r.residuals.tolist() == want


def test_another_measure_reruns_migrated_runs_once_then_recompares_them(store_path):
    _, reused, n, attempts = evaluate(store_path, problem("rkhs", sigma_w=0.05))
    assert reused == set() and n == 5 and attempts == {2}  # no interfaces in format 1
    records, reused, n, _ = evaluate(store_path, problem("cpp"))  # interfaces stored now
    assert reused == set(range(5)) and n == 5
    assert [r.distance for r in records] == pytest.approx(EXPECTED["distances"], rel=1e-12)
