"""Issue 14, defects 13 and 14: sizes the machine cannot hold and odd input are one line
with exit status 2, before anything runs; nothing is written where it was not asked."""

from __future__ import annotations

import pytest
from _studies import edit, one_error_line

import fbia
from fbia.studies.cli import main


def test_deeply_nested_toml(study_file, capsys):
    study_file.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    assert main(["validate", "study.toml"]) == 2
    assert "TOML nested too deeply" in one_error_line(capsys)


@pytest.mark.parametrize(
    ("output", "message"),
    [('""', "a non-empty string"), ('"out\\u0000put"', "a control character")],
)
def test_a_bad_output_folder_in_the_study_file(study_file, capsys, output, message):
    study_file.write_text(edit('output = "out"', f"output = {output}"))
    assert main(["run", "study.toml"]) == 2
    line = one_error_line(capsys)
    assert "[study] output" in line and message in line


def test_an_empty_output_on_the_command_line_writes_nothing(study_file, capsys, tmp_path):
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["run", "study.toml", "--output", ""]) == 2
    assert "--output: needs a folder name" in one_error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_gp_smc_sizes_beyond_the_memory_are_refused_before_any_run(study_file, capsys, tmp_path):
    study_file.write_text(
        edit(
            'name = "levenberg_marquardt"\n'
            "options = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }",
            'name = "gp_smc"\noptions = { n_train = 16, n_particles = 100000000000 }',
        )
    )
    assert main(["run", "study.toml"]) == 2
    line = one_error_line(capsys)
    assert "gp_smc options: n_train = 16, n_particles = 100000000000 needs about" in line
    assert "lower n_train or n_particles" in line
    assert not (tmp_path / "out" / "runs").exists()


@pytest.mark.parametrize(
    ("model", "option", "value"),
    [("analytic_mound_2d", "n_points", 10**9), ("analytic_mound_3d", "n_rings", 10**6)],
)
def test_model_sizes_have_upper_bounds(model, option, value):
    with pytest.raises(fbia.ConfigError, match=option):
        fbia.forward_model(model, **{option: value})


@pytest.mark.parametrize("address", ["not a url", "tcp://", "http://10.0.0.5:8786", "tcp://h:port"])
def test_a_bad_scheduler_address_is_one_line(study_file, capsys, address):
    assert main(["run", "study.toml", "--address", address]) == 2
    assert "is not a Dask scheduler address" in one_error_line(capsys)
    study_file.write_text(edit('kind = "serial"', f'kind = "dask"\naddress = "{address}"'))
    assert main(["validate", "study.toml"]) == 2
    assert "[executor] address: " in one_error_line(capsys)


@pytest.mark.parametrize(
    "address", ["tcp://10.0.0.5:8786", "tls://node-1.cluster:8786", "[::1]:8786"]
)
def test_good_scheduler_addresses_pass(address):
    from fbia.execution.executors import check_scheduler_address

    assert check_scheduler_address(address, "--address") == address


def test_more_workers_than_the_memory_can_start_is_one_line(study_file, capsys):
    assert main(["run", "study.toml", "--workers", "100000000"]) == 2
    line = one_error_line(capsys)
    assert "100000000 worker processes needs about" in line and "lower workers" in line
