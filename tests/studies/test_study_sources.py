"""A study as a base and variants (``[study] extends``) and ``--set`` changes (issue 48 item 2):
what is merged, what is refused with one line, what the result records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from _studies import STUDY, write_study

from fbia.core.errors import ConfigError
from fbia.studies.cli import main
from fbia.studies.study_file import load_study
from fbia.studies.study_sources import merge_tables, read_sources, with_override

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

VARIANT = """\
[study]
extends = "study.toml"
name = "tiny_rkhs"
output = "out_rkhs"

[measure]
name = "rkhs"
options = { sigma_w = 0.05 }
"""


def test_tables_merge_key_by_key_and_arrays_are_replaced_whole():
    base = {"a": {"x": 1, "y": {"p": 1, "q": 2}}, "arr": [{"n": 1}, {"n": 2}], "k": 1}
    variant = {"a": {"y": {"q": 3}, "z": 4}, "arr": [{"n": 9}]}
    merged = merge_tables(base, variant)
    assert merged == {"a": {"x": 1, "y": {"p": 1, "q": 3}, "z": 4}, "arr": [{"n": 9}], "k": 1}
    assert base["a"]["y"] == {"p": 1, "q": 2}  # neither input is changed


def test_the_measures_variants_read_as_the_files_they_replaced():
    """examples/paper_b/measures: study_ray.toml and study_rkhs.toml extend study_cpp.toml and
    differ from it in the lines that did before (study_cpp.toml merged with ../base_2d.toml,
    the tables as they were written out before the bases)."""
    cpp = read_sources(EXAMPLES / "paper_b/measures/study_cpp.toml").raw
    for name, measure in (("ray", {"name": "ray"}), ("rkhs", None)):
        merged = read_sources(EXAMPLES / f"paper_b/measures/study_{name}.toml").raw
        assert merged["study"]["name"] == f"paper_b_measures_{name}"
        assert "extends" not in merged["study"]
        if measure is not None:
            assert merged["measure"] == measure
        rest = {k: v for k, v in merged.items() if k not in ("study", "measure", "paper")}
        assert rest == {k: v for k, v in cpp.items() if k not in ("study", "measure", "paper")}
        assert merged["paper"]["values"] == cpp["paper"]["values"]


def test_a_variant_runs_and_its_result_records_every_source(study_file, capsys):
    Path("study_rkhs.toml").write_text(VARIANT)
    status = main(["run", "study_rkhs.toml", "--set", "iterator.options.max_iter=20"])
    assert status == 0
    record = json.loads(Path("out_rkhs/result.json").read_text())["provenance"]
    assert record["study_text"] == VARIANT  # the file's own text
    assert record["study_bases"] == [{"path": "study.toml", "text": STUDY}]
    assert record["study_overrides"] == ["iterator.options.max_iter=20"]
    study = load_study("study_rkhs.toml", overrides=["iterator.options.max_iter=20"])
    assert study.measure_name == "rkhs" and study.iterator.options.max_iter == 20
    assert record["study_sha256"] == study.sha256
    # the digest covers the bases and the changes: the same file read another way differs
    assert load_study("study_rkhs.toml").sha256 != study.sha256
    plain = load_study("study.toml")
    import hashlib

    assert plain.sha256 == hashlib.sha256(Path("study.toml").read_bytes()).hexdigest()


def test_a_base_only_file_is_refused_and_its_variants_run(study_file, capsys):
    """``[study] base_only = true``: the shared part of a family, no study by itself (fbia run
    and validate refuse it in one line, exit 2); a variant that extends it is a study, and
    does not inherit the setting."""
    base = STUDY.replace("[study]\n", "[study]\nbase_only = true\n", 1)
    assert base != STUDY
    Path("base.toml").write_text(base)
    with pytest.raises(ConfigError, match=r"base.toml: \[study\] base_only: a base that"):
        load_study("base.toml")
    for command in ("run", "validate"):
        assert main([command, "base.toml"]) == 2
        err = capsys.readouterr().err
        assert "not a study of its own" in err and "Traceback" not in err
    Path("variant.toml").write_text('[study]\nextends = "base.toml"\noutput = "out_v"\n')
    assert "base_only" not in read_sources(Path("variant.toml")).raw["study"]
    assert main(["validate", "variant.toml"]) == 0
    # a variant may itself be a base of further variants
    Path("mid.toml").write_text('[study]\nextends = "base.toml"\nbase_only = true\n')
    assert read_sources(Path("mid.toml")).raw["study"]["base_only"] is True
    with pytest.raises(ConfigError, match="not a study of its own"):
        load_study("mid.toml")


def test_relative_paths_of_a_base_are_read_from_the_extending_file(tmp_path):
    """The base in another folder names its data relative to itself; merged, the variant's
    folder reads them (the documented rule): a variant elsewhere must say where they are."""
    write_study(tmp_path / "family")
    (tmp_path / "family" / "v").mkdir()
    variant = tmp_path / "family" / "v" / "study.toml"
    variant.write_text('[study]\nextends = "../study.toml"\n')
    with pytest.raises(ConfigError, match="observed_100.csv"):
        load_study(variant)
    text = variant.read_text()
    text += "\n[[observations]]\ncoordinate = { inflow_rate = 100.0 }\n"
    text += 'interface = "../data/observed_100.csv"\npoints = "../data/points_100.csv"\n'
    text += "noise_std = 0.0005\n"
    variant.write_text(text)
    assert load_study(variant).observations[0].interface is not None


@pytest.mark.parametrize(
    "files, message",
    [
        (
            {"a.toml": '[study]\nextends = "b.toml"\n', "b.toml": '[study]\nextends = "a.toml"\n'},
            r"b.toml: \[study\] extends: the studies extend each other in a cycle: .*a.toml -> "
            r".*b.toml -> .*a.toml$",
        ),
        ({"a.toml": '[study]\nextends = "a.toml"\n'}, "in a cycle"),
        (
            {"a.toml": '[study]\nextends = "nope.toml"\n'},
            r"a.toml: \[study\] extends: 'nope.toml': .*nope.toml: study file not found",
        ),
        (
            {"a.toml": "[study]\nextends = 3\n"},
            r"a.toml: \[study\] extends: expected the path of a study file \(a string\)",
        ),
        (
            {"a.toml": '[study]\nextends = "b.toml"\n', "b.toml": "[study\n"},
            "'b.toml': .*b.toml: TOML syntax error",
        ),
        (
            {f"s{i}.toml": f'[study]\nextends = "s{i + 1}.toml"\n' for i in range(9)},
            "more than 8 files extend one another",
        ),
    ],
)
def test_a_chain_that_cannot_be_read_is_one_line(tmp_path, files, message):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    first = tmp_path / sorted(files, key=lambda n: (len(n), n))[0]
    with pytest.raises(ConfigError, match=message):
        read_sources(first)


@pytest.mark.parametrize(
    "change, value",
    [
        ("iterator.options.seed=3", 3),
        ("iterator.options.seed = 3", 3),
        ("measure.name=ray", "ray"),
        ('measure.name="ray"', "ray"),
        ("parameters.0.bounds=[100.0, 900.0]", [100.0, 900.0]),
        ("executor.cluster_options={ cores = 8 }", {"cores": 8}),
    ],
)
def test_a_change_is_a_toml_value_at_a_dotted_key(change, value):
    raw = {"iterator": {"options": {}}, "measure": {"name": "cpp"}, "parameters": [{"name": "E"}]}
    out = with_override(raw, change)
    key = change.partition("=")[0].strip().split(".")
    node = out
    for part in key:
        node = node[int(part)] if isinstance(node, list) else node[part]
    assert node == value
    assert raw["measure"] == {"name": "cpp"}  # the input is not changed


@pytest.mark.parametrize(
    "change, message",
    [
        ("seed=3", "expected section.key=value"),
        ("iterator.options.seed", "expected section.key=value"),
        ("iterator..seed=3", "expected section.key=value"),
        ("parameters.2.bounds=[1, 2]", "parameters is an array of 1: give an index 0..0"),
        ("parameters.E.bounds=[1, 2]", "parameters is an array of 1"),
        ("measure.name.x=1", "measure.name is a value, not a table"),
        ("measure.name=[1, 2", "not a TOML value: '\\[1, 2'"),
    ],
)
def test_a_change_that_cannot_be_made_is_one_line(change, message):
    raw = {"measure": {"name": "cpp"}, "parameters": [{"name": "E"}]}
    with pytest.raises(ConfigError, match=message) as err:
        with_override(raw, change)
    assert str(err.value).startswith(f"--set {change}")


def test_the_cli_refuses_a_bad_change_with_exit_2_and_names_it(study_file, capsys):
    assert main(["validate", "study.toml", "--set", "iterator.options.max_itre=3"]) == 2
    err = capsys.readouterr().err
    assert "unknown option 'max_itre'" in err and "Traceback" not in err
    assert "(the study as changed by --set iterator.options.max_itre=3)" in err
    assert main(["run", "study.toml", "--set", "nope"]) == 2
    assert "--set nope: expected section.key=value" in capsys.readouterr().err
    assert not Path("out").exists()  # refused before anything ran


def test_forward_takes_parameter_values_and_dotted_changes(study_file, capsys):
    status = main(["forward", "study.toml", "--set", "E=410", "--set", "measure.name=ray"])
    assert status == 0
    record = json.loads(Path("out/forward/result.json").read_text())
    assert record["x"]["E"] == 410.0
    assert record["provenance"]["study_overrides"] == ["measure.name=ray"]
