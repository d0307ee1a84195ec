"""Study files: a valid file round-trips; every mistake is one ConfigError naming file and key."""

from __future__ import annotations

import hashlib
import json
import tomllib

import numpy as np
import pytest
from _models import PLUGIN, GridIterator, ToyMoundForwardModel, VerticalMeasure, toy_curve
from _studies import BAD_CASES, STUDY, TRUTH, write_study

import fbia
from fbia.core.registry import Registry
from fbia.execution.executors import ExecutorSpec
from fbia.studies.study import derived_seed
from fbia.studies.study_file import load_study


@pytest.fixture(scope="module")
def registry():
    return Registry.load(extra=[PLUGIN])


TOY_STUDY = """\
[study]
seed = 5

[model]
name = "toy_mound"
options = {{ {model_options} }}

[[parameters]]
name = "E"
bounds = [100.0, 800.0]

[[parameters]]
name = "nu"
bounds = [-0.8, 0.5]

[synthetic]
truth = {{ E = 450.0, nu = 0.15 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]
noise_std = 0.001

[measure]
name = "vertical"

[iterator]
name = "grid"
options = {{ n = 3 }}

[executor]
kind = "serial"
"""


def test_a_valid_study_round_trips(study_file):
    study = load_study("study.toml")
    raw_bytes = study_file.read_bytes()
    assert study.raw == tomllib.loads(STUDY)
    assert study.text == STUDY
    assert study.sha256 == hashlib.sha256(raw_bytes).hexdigest()
    assert (study.name, study.seed) == ("tiny", 3)
    assert study.output == study_file.parent.relative_to(study_file.parent) / "out"
    # the model and measure come from the registry with the file's options
    assert study.model_name == "analytic_mound_2d" and study.model.options.n_points == 41
    assert study.measure_name == "cpp"
    assert study.iterator_name == "levenberg_marquardt"
    assert study.iterator.options.x0 == {"E": 350.0, "nu": 0.25}
    assert study.iterator.options.max_iter == 30
    assert study.executor == ExecutorSpec("serial", None, False)
    # parameters with bounds, units, initial values and priors
    E, nu = study.parameters
    assert (E.name, E.unit, E.bounds, E.initial, E.prior.kind) == (
        "E",
        "Pa",
        (100.0, 800.0),
        300.0,
        "uniform",
    )
    assert nu.prior.spec() == {
        "distribution": "beta",
        "a": 3.3,
        "b": 1.7,
        "lower": -0.8,
        "upper": 0.45,
    }
    # the observation read from the data files, relative to the study file
    (obs,) = study.problem.observations
    expected = fbia.Interface.read(study_file.parent / "data" / "observed_100.csv")
    np.testing.assert_array_equal(obs.interface.vertices, expected.vertices)
    assert obs.coordinate == {"inflow_rate": 100.0}
    assert obs.noise_std == 0.0005 and len(obs.measurement_points) == 8
    assert study.problem.noise_std == 0.0005
    assert study.problem.names == ["E", "nu"]
    assert study.start_point() == {"E": 300.0, "nu": 0.2}
    assert study.start_point({"nu": 0.1}) == {"E": 300.0, "nu": 0.1}


def test_relative_paths_resolve_against_the_study_folder(tmp_path, monkeypatch):
    path = write_study(tmp_path / "deep" / "er")
    monkeypatch.chdir(tmp_path)
    study = load_study(path)
    assert study.output == tmp_path / "deep" / "er" / "out"
    assert len(study.problem.observations[0].interface) == 40


@pytest.mark.parametrize(("case", "text", "message"), BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_each_mistake_is_one_config_error_naming_file_and_key(study_file, case, text, message):
    study_file.write_text(text)
    with pytest.raises(fbia.ConfigError) as info:
        load_study("study.toml")
    got = str(info.value)
    assert "\n" not in got
    assert got.startswith(message), got


def test_missing_study_file_is_named(study_file):
    with pytest.raises(fbia.ConfigError, match=r"^nope\.toml: study file not found$"):
        load_study("nope.toml")


def test_unknown_plugin_errors_list_the_valid_names(study_file):
    study_file.write_text(STUDY.replace('name = "cpp"', 'name = "cpq"'))
    with pytest.raises(fbia.PluginError) as info:
        load_study("study.toml")
    valid = str(info.value).split("valid: ")[1].split(", ")
    assert {"cpp", "ray", "rkhs"} <= set(valid)


def test_x0_from_initial_values_and_seed_from_the_study(registry, tmp_path):
    text = TOY_STUDY.format(model_options="")
    (tmp_path / "toy.toml").write_text(text)
    study = load_study(tmp_path / "toy.toml", registry=registry, build=False)
    assert isinstance(study.iterator, GridIterator)
    assert study.iterator.options.seed == derived_seed(5, 1)
    assert derived_seed(5, 1) != derived_seed(5, 0) != derived_seed(6, 0)
    # the synthetic noise is seeded from the study seed: same seed, same data
    a = load_study(tmp_path / "toy.toml", registry=registry).problem.observations[0]
    b = load_study(tmp_path / "toy.toml", registry=registry).problem.observations[0]
    np.testing.assert_array_equal(a.interface.vertices, b.interface.vertices)
    exact = toy_curve(450.0, 0.15)
    noise = a.interface.vertices - exact
    assert 0.0 < np.abs(noise).max() < 0.006  # sigma = 0.001 mm, 21 vertices
    (tmp_path / "toy6.toml").write_text(text.replace("seed = 5", "seed = 6"))
    c = load_study(tmp_path / "toy6.toml", registry=registry).problem.observations[0]
    assert not np.array_equal(a.interface.vertices, c.interface.vertices)


def test_build_false_makes_no_forward_run(registry, tmp_path):
    (tmp_path / "toy.toml").write_text(TOY_STUDY.format(model_options="fail_above = 400.0"))
    study = load_study(tmp_path / "toy.toml", registry=registry, build=False)
    assert isinstance(study.model, ToyMoundForwardModel)
    assert isinstance(study.measure, VerticalMeasure)
    with pytest.raises(
        fbia.ConfigError,
        match=r"toy\.toml: \[synthetic\]: the forward model failed at the truth: .*"
        r"mesh distortion at E = 450\.0$",
    ):
        _ = study.problem


def test_study_run_through_the_api_writes_the_output_folder(registry, tmp_path):
    (tmp_path / "toy.toml").write_text(TOY_STUDY.format(model_options=""))
    study = load_study(tmp_path / "toy.toml", registry=registry)
    lines: list[str] = []
    result = fbia.run_study(study, echo=lines.append)
    out = tmp_path / "output"
    # the 3 x 3 grid over the bounds; the best point is the one of smallest D, computed here
    # from the closed form of the toy model
    grid = [(E, nu) for E in np.linspace(100.0, 800.0, 3) for nu in np.linspace(-0.8, 0.5, 3)]
    obs = study.problem.observations[0].interface.vertices[:, 1]
    dist = {g: np.linalg.norm(toy_curve(*g)[:, 1] - obs) for g in grid}
    best = min(dist, key=dist.get)
    assert result.x == {"E": best[0], "nu": best[1]}
    assert result.nfev == 9 and result.status == "grid_done"
    records = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert [r["index"] for r in records] == list(range(9))
    assert [(r["x"]["E"], r["x"]["nu"]) for r in records] == grid
    saved = json.loads((out / "result.json").read_text())
    assert saved["x"] == result.x and saved["provenance"]["seed"] == 5
    assert "grid: grid_done" in (out / "report.txt").read_text()
    assert (out / "interfaces" / "simulated_inflow_rate_100.csv").is_file()
    assert lines[-2].endswith(f"\noutput: {out}")
    assert lines[-1] == f"report: {out / 'report.md'} and report.html"
    page = (out / "report.md").read_text()
    assert page.startswith("# ") and "result: **grid_done**" in page
    assert "Not a result to use" not in page and "## Settings" in page


def test_executor_spec_workers_override():
    spec = ExecutorSpec("processes", 4)
    assert spec.with_workers(None) is spec
    assert spec.with_workers(1) == ExecutorSpec("serial", 1)
    assert ExecutorSpec("serial").with_workers(3) == ExecutorSpec("processes", 3)
    with pytest.raises(fbia.ConfigError, match="--workers must be at least 1, got 0"):
        spec.with_workers(0)


def test_synthetic_study_makes_observations_at_the_truth(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = (
        STUDY.split("[[observations]]")[0]
        + (
            "[synthetic]\ntruth = { E = 400.0, nu = 0.3 }\n"
            "coordinates = [ { inflow_rate = 100.0 } ]\npoints = 5\n\n[measure]"
        )
        + STUDY.split("[measure]")[1]
    )
    write_study(tmp_path, text)
    study = load_study("study.toml")
    (obs,) = study.problem.observations
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    exact = model.solve(TRUTH, [{"inflow_rate": 100.0}], tmp_path).interface({"inflow_rate": 100.0})
    np.testing.assert_array_equal(obs.interface.vertices, exact.vertices)  # noise_std 0
    assert len(obs.measurement_points) == 5
    assert "(synthetic)" in study.summary()


def test_synthetic_data_noise_is_not_the_likelihood_sigma(tmp_path, monkeypatch):
    """Paper B: sigma_n,obs (eq. 16) makes the data, sigma_N (eq. 5) is the likelihood's."""
    from fbia.core.likelihood import noise_levels

    monkeypatch.chdir(tmp_path)
    text = (
        STUDY.split("[[observations]]")[0]
        + (
            "[synthetic]\ntruth = { E = 400.0, nu = 0.3 }\n"
            "coordinates = [ { inflow_rate = 100.0 } ]\nnoise_std = 0.001\n\n"
            "[likelihood]\nnoise_std = 0.03\n\n[measure]"
        )
        + STUDY.split("[measure]")[1]
    )
    write_study(tmp_path, text.replace("[likelihood]\nnoise_std = 0.0005\n", ""))
    study = load_study("study.toml")
    assert noise_levels(study.problem) == [0.03]


@pytest.mark.parametrize(
    ("section", "table", "message"),
    [
        ("executor", {"workers": 0}, "[executor] workers: must be at least 1, got 0"),
        ("executor", {"workers": "2"}, "[executor] workers: expected an integer, got a string"),
        ("executor", {"timeout": -1}, "[executor] timeout: must be positive, got -1"),
        ("executor", {"isolate": "yes"}, "[executor] isolate: expected true or false, got 'yes'"),
        (
            "executor",
            {"kind": "dask", "cluster": "k8s"},
            "[executor] cluster: unknown cluster 'k8s'; valid: local, slurm, pbs",
        ),
        (
            "executor",
            {"address": "tcp://host:8786"},
            "[executor] address: address only for kind = \"dask\" (kind is 'processes')",
        ),
        (
            "executor",
            {"timeout": 5.0, "isolate": False},
            "[executor] isolate: a time-out needs isolated runs",
        ),
        ("study", {"seed": 1.5}, "[study] seed: expected an integer, got a number 1.5"),
        ("study", {"output": ""}, "[study] output: expected a non-empty string"),
        ("likelihood", {"noise_std": 0.0}, "[likelihood] noise_std: must be positive, got 0.0"),
        ("likelihood", {"sigma": 0.1}, "[likelihood]: unknown key 'sigma'; valid keys: noise_std"),
        ("synthetic", {"coordinates": []}, "[synthetic]: missing key 'truth'"),
        ("parameters", {"name": "E", "bounds": [1.0]}, "[parameters] bounds: expected [lower, "),
        ("parameters", {"name": "E", "unit": 3}, "[parameters] unit: expected a string, got an "),
        ("parameters", {"unit": "Pa"}, "[parameters]: missing key 'name'"),
        ("uncertain", {"name": "q", "initial": 3.0}, "[uncertain]: unknown key 'initial'; valid "),
        ("observations", {"noise_std": -1.0}, "[observations] noise_std: must be positive"),
        ("observations", {"interface": 3}, "[observations] interface: expected a non-empty "),
        ("model", {"name": "x", "options": 3}, "[model] options: expected a table, got an int"),
        (
            "synthetic",
            {"truth": {}, "coordinates": [], "noise": "bogus"},
            "[synthetic] noise: unknown noise 'bogus'; valid: normal, isotropic",
        ),
    ],
)
def test_section_schemas_give_one_located_line(section, table, message):
    from fbia.studies import study_schema

    model = {
        "executor": study_schema.ExecutorSection,
        "study": study_schema.StudySection,
        "likelihood": study_schema.LikelihoodSection,
        "synthetic": study_schema.SyntheticSection,
        "parameters": study_schema.ParameterSection,
        "uncertain": study_schema.UncertainSection,
        "observations": study_schema.ObservationSection,
        "model": study_schema.PluginSection,
    }[section]
    with pytest.raises(fbia.ConfigError) as info:
        study_schema.parse_section(model, table, f"study.toml: [{section}]")
    assert str(info.value).startswith(f"study.toml: {message}")
