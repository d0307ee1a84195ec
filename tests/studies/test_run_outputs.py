"""What a session writes beside its result (issue 48 item 1: the extras return what they make,
a new ``RunOutputs`` after each file): a file that fails is a warning in ``result.json``, never
fatal; a session stopped during them writes its result with what they had made."""

from __future__ import annotations

import json
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
