"""``fbia init`` writes a commented template study that validates and runs as written
(issue 29 item 5)."""

from __future__ import annotations

import tomllib

import pytest
from _studies import one_error_line

from fbia.core.registry import list_plugins
from fbia.studies.cli import main

MODELS = sorted(e.name for e in list_plugins() if e.kind == "forward_model")
ITERATORS = sorted(e.name for e in list_plugins() if e.kind == "iterator")


@pytest.mark.parametrize("iterator", ITERATORS)
@pytest.mark.parametrize("model", MODELS)
def test_the_template_of_every_model_and_iterator_validates(tmp_path, capsys, model, iterator):
    path = tmp_path / "study.toml"
    assert main(["init", str(path), "--model", model, "--iterator", iterator]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {path}; next: fbia validate ")
    study = tomllib.loads(path.read_text())
    assert study["model"]["name"] == model and study["iterator"]["name"] == iterator
    assert main(["validate", str(path)]) == 0, capsys.readouterr().err
    # every parameter's bounds hold its truth and the initial value, inside the model's limits
    for p in study["parameters"]:
        low, high = p["bounds"]
        assert low < p["initial"] < high and low <= study["synthetic"]["truth"][p["name"]] <= high


def test_every_option_is_listed_with_its_default(tmp_path):
    from fbia.plugins.ale_fsi.options import AleFsiOptions

    path = tmp_path / "s.toml"
    assert main(["init", str(path), "--model", "ale_fsi"]) == 0
    text = path.read_text()
    for name in AleFsiOptions.model_fields:
        assert f"\n# {name} = " in text
    assert "\n# E = 400.0\n#     Young's modulus of the biofilm [Pa]\n" in text
    # uncommenting the [model.options] line and one option's line is a valid study
    edited = text.replace("# [model.options]", "[model.options]\n#", 1).replace(
        '\n# material = "svk"', '\nmaterial = "neo_hooke"', 1
    )
    path.write_text(edited)
    assert tomllib.loads(edited)["model"]["options"] == {"material": "neo_hooke"}
    assert main(["validate", str(path)]) == 0


def test_the_analytic_template_runs_to_the_truth(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["init", "--model", "analytic_mound_2d"]) == 0
    text = (tmp_path / "study.toml").read_text()
    (tmp_path / "study.toml").write_text(text.replace('kind = "processes"', 'kind = "serial"'))
    assert main(["run", "study.toml"]) == 0
    import fbia

    result = fbia.load_result(tmp_path / "output")
    assert result.success
    truth = tomllib.loads(text)["synthetic"]["truth"]
    for name, value in truth.items():
        assert result.x[name] == pytest.approx(value, rel=1e-3)


def test_bad_init_requests_are_one_line_and_exit_2(tmp_path, capsys):
    path = tmp_path / "study.toml"
    assert main(["init", str(path), "--model", "ale_fs"]) == 2
    assert one_error_line(capsys) == (
        "--model: unknown forward model 'ale_fs' (did you mean 'ale_fsi'?); valid: ale_fsi, "
        "analytic_mound_2d, analytic_mound_3d, cutfem_fpi, growth"
    )
    assert main(["init", str(path), "--model", "ale_fsi", "--iterator", "lm"]) == 2
    assert one_error_line(capsys).startswith("--iterator: unknown iterator 'lm'")
    assert not path.exists()
    path.write_text("# mine\n")
    assert main(["init", str(path), "--model", "ale_fsi"]) == 2
    assert one_error_line(capsys) == (
        f"{path}: exists already; give another FILE or --force to overwrite"
    )
    assert path.read_text() == "# mine\n"
    assert main(["init", str(path), "--model", "ale_fsi", "--force"]) == 0
