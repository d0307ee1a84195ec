"""What a session writes beside its result (issue 48 item 1: the extras return what they make,
a new ``RunOutputs`` after each file): a file that fails is a warning in ``result.json``, never
fatal; a session stopped during them writes its result with what they had made."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from fbia.iterators.levenberg_marquardt import LevenbergMarquardtIterator
from fbia.studies.runner import run_study
from fbia.studies.study_file import load_study


def _quiet(line: str) -> None:
    pass


def _record(out: Path) -> dict:
    return json.loads((out / "result.json").read_text())["provenance"]


def test_a_plot_that_fails_is_a_warning_in_the_run_record(study_file, monkeypatch):
    def failing(self, result, problem, folder):
        raise RuntimeError("no display")

    monkeypatch.setattr(LevenbergMarquardtIterator, "write_plots", failing)
    result = run_study(load_study("study.toml"), echo=_quiet)
    assert result.success  # the result stands
    record = _record(Path("out"))
    assert record["warnings"] == ["the iterator's plots failed: RuntimeError: no display"]
    assert "interfaces" in record["files"] and "evaluations plot" in record["files"]
    assert "iterator plots" not in record["files"]
    assert record["discrepancy"] and result.provenance == record  # the result has its record


def test_a_stop_during_the_extras_keeps_what_they_had_made(study_file, monkeypatch):
    def stopped(self, result, problem, folder):
        raise KeyboardInterrupt

    monkeypatch.setattr(LevenbergMarquardtIterator, "write_plots", stopped)
    with pytest.raises(KeyboardInterrupt):
        run_study(load_study("study.toml"), echo=_quiet)
    saved = json.loads(Path("out/result.json").read_text())
    assert saved["status"].startswith("converged")  # the iterator's result, not a partial one
    record = saved["provenance"]
    # the interfaces at x were written before the plots: the record names them
    assert record["discrepancy"] and "interfaces" in record["files"]
    assert all(Path(p).is_file() for p in record["files"]["interfaces"])
    assert "evaluations plot" not in record["files"]  # after the stop: never made


def _solves_here(monkeypatch) -> list[int]:
    """The model's solves in this process (one entry each), counted from now on."""
    from fbia.plugins.analytic.mound_2d import AnalyticMound2DForwardModel

    solves: list[int] = []
    solve = AnalyticMound2DForwardModel.solve

    def counted(self, *args, **kwargs):
        solves.append(1)
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(AnalyticMound2DForwardModel, "solve", counted)
    return solves


def _x_off_every_run(monkeypatch) -> None:
    """LM's result with its x moved off every run (as a posterior mean is)."""
    finish = LevenbergMarquardtIterator.steps

    def moved(self, problem, evaluator):
        result = yield from finish(self, problem, evaluator)
        return replace(result, x={k: v * (1 + 1e-6) for k, v in result.x.items()})

    monkeypatch.setattr(LevenbergMarquardtIterator, "steps", moved)


def test_the_interfaces_at_x_are_the_stored_run_not_a_repeat(study_file, monkeypatch):
    """The interfaces and the discrepancy at the result's x come from the stored run at x
    (issue 47: a repeat in the study's process was a cold start of a 3-D model, ~20 s, when
    workers made the runs): no forward run beyond the iterator's, and the simulated interface
    written is the one the store holds for x, bit for bit."""
    import fbia
    from fbia.storage.store import StudyStore

    solves = _solves_here(monkeypatch)
    study = load_study("study.toml")
    result = run_study(study, echo=_quiet)
    assert result.success and len(solves) == result.nfev
    record = _record(Path("out"))
    (written,) = [p for p in record["files"]["interfaces"] if "simulated" in p and ".csv" in p]

    with StudyStore(Path("out/store.sqlite")) as store:
        store.bind(study.problem)
        stored = store.solution(store.key(result.x))
    assert stored is not None
    (coordinate,) = study.problem.coordinates()
    got = fbia.Interface.read(written)
    assert got.vertices.tobytes() == stored.interface(coordinate).vertices.tobytes()


def test_a_result_x_that_was_not_run_is_run_once_more(study_file, monkeypatch):
    """A result's x that no run was made at (a posterior mean, an x moved after the runs) is
    run once more for its interfaces, as before."""
    solves = _solves_here(monkeypatch)
    _x_off_every_run(monkeypatch)
    result = run_study(load_study("study.toml"), echo=_quiet)
    assert len(solves) == result.nfev + 1
    record = _record(Path("out"))
    assert record["discrepancy"] and any("simulated" in p for p in record["files"]["interfaces"])


def test_with_worker_processes_that_run_is_made_by_a_worker(study_file, monkeypatch):
    """With worker processes, the run at a result's x that no run was made at goes to a worker
    (warm: it has run the study's batches; issue 47), not to the study's own process, where
    the model would make its first, cold run (a 3-D ale_fsi run: ~20 s against ~3 s)."""
    here = _solves_here(monkeypatch)
    _x_off_every_run(monkeypatch)
    text = (
        Path("study.toml").read_text().replace('kind = "serial"', 'kind = "processes"\nworkers = 1')
    )
    Path("study.toml").write_text(text)
    result = run_study(load_study("study.toml"), echo=_quiet)
    assert result.nfev > 0 and here == []  # every run, the last one included, on the worker
    record = _record(Path("out"))
    assert record["discrepancy"] and any("simulated" in p for p in record["files"]["interfaces"])
    assert record["executor"]["kind"] == "processes"
