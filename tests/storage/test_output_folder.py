"""Issue 14, defects 9 and 10: one writer per output folder, and ``--fresh`` deletes only
what fbia made."""

from __future__ import annotations

import pytest
from _studies import one_error_line

from fbia.core.errors import ConfigError
from fbia.storage.output_folder import OutputLock, clear_runs, is_fbia_store
from fbia.studies.cli import main


def test_forward_into_a_running_studys_folder_is_refused_and_changes_nothing(
    study_file, capsys, tmp_path
):
    live = tmp_path / "live"
    with OutputLock(live, "fbia run"):
        (live / "evaluations.jsonl").write_text("a live study's log\n")
        assert main(["forward", "study.toml", "--output", "live"]) == 2
        assert "in use by fbia run (pid" in one_error_line(capsys)
        assert (live / "evaluations.jsonl").read_text() == "a live study's log\n"
        assert not (live / "result.json").exists()


def test_forward_into_a_finished_studys_folder_is_refused(study_file, capsys):
    assert main(["run", "study.toml"]) == 0
    before = (study_file.parent / "out" / "result.json").read_bytes()
    capsys.readouterr()
    assert main(["forward", "study.toml", "--output", "out"]) == 2
    assert "holds a study (store.sqlite)" in one_error_line(capsys)
    assert (study_file.parent / "out" / "result.json").read_bytes() == before


def test_two_runs_on_one_folder_the_second_is_refused(study_file, capsys):
    with OutputLock(study_file.parent / "out", "fbia run"):
        assert main(["run", "study.toml"]) == 2
    assert "out: the output folder is in use" in one_error_line(capsys)


def test_fresh_deletes_only_fbia_run_folders_and_an_fbia_store(study_file, capsys, tmp_path):
    out = tmp_path / "out"
    assert main(["run", "study.toml"]) == 0
    assert is_fbia_store(out / "store.sqlite")
    (out / "runs" / "eval_000001").mkdir(parents=True, exist_ok=True)
    (out / "runs" / "eval_000002-2").mkdir()
    (out / "runs" / "my_notes").mkdir()
    (out / "runs" / "eval_results.txt").write_text("mine")
    assert main(["run", "study.toml", "--fresh"]) == 0
    left = sorted(p.name for p in (out / "runs").iterdir())
    assert left == ["eval_results.txt", "my_notes"]
    assert "starting over (--fresh)" in capsys.readouterr().out


def test_fresh_refuses_a_store_file_fbia_did_not_make(study_file, capsys, tmp_path):
    (tmp_path / "out").mkdir()
    precious = tmp_path / "out" / "store.sqlite"
    precious.write_text("someone's data")
    assert main(["run", "study.toml", "--fresh"]) == 2
    assert "--fresh deletes only an fbia study store" in one_error_line(capsys)
    assert precious.read_text() == "someone's data"


def test_clear_runs_leaves_symlinks_and_foreign_names(tmp_path):
    runs = tmp_path / "runs"
    (runs / "eval_000003").mkdir(parents=True)
    target = tmp_path / "elsewhere"
    (target / "keep").mkdir(parents=True)
    (runs / "eval_000004").symlink_to(target, target_is_directory=True)
    assert clear_runs(runs) == 1
    assert (target / "keep").is_dir() and (runs / "eval_000004").is_symlink()


def test_a_second_lock_names_the_holder(tmp_path):
    with OutputLock(tmp_path, "fbia run"), pytest.raises(ConfigError, match="in use by fbia run"):
        OutputLock(tmp_path, "fbia forward")
