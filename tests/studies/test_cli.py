"""The ``fbia`` command line: exit statuses, one-line errors, the files each command writes."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import meshio
import numpy as np
import pytest
from _models import PLUGIN, write_driver
from _paths import ROOT
from _studies import BAD_CASES, STUDY, TRUTH, edit, one_error_line

import fbia
from fbia.core.registry import Registry
from fbia.studies import study_file as study_module
from fbia.studies.cli import main
from fbia.studies.study_sources import read_sources

FBIA = Path(sys.executable).parent / "fbia"


@pytest.mark.parametrize(("case", "text", "message"), BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_validate_gives_status_2_and_one_line_per_mistake(study_file, capsys, case, text, message):
    study_file.write_text(text)
    assert main(["validate", "study.toml"]) == 2
    assert one_error_line(capsys).startswith(message)


@pytest.mark.parametrize("command", [["run"], ["forward"]])
@pytest.mark.parametrize("case", ["nan-in-data", "unknown-measure", "x0-outside"])
def test_run_and_forward_report_the_same_mistakes(study_file, capsys, command, case):
    text, message = next((t, m) for c, t, m in BAD_CASES if c == case)
    study_file.write_text(text)
    assert main([*command, "study.toml"]) == 2
    assert one_error_line(capsys).startswith(message)
    assert not (study_file.parent / "out").exists()  # nothing ran


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "nope.toml"], "nope.toml: study file not found"),
        (["run"], "run: the following arguments are required: FILE"),
        (["frobnicate"], "argument COMMAND: invalid choice: 'frobnicate'"),
        (["run", "study.toml", "--workers", "two"], "run: argument --workers: invalid int value"),
        (["forward", "study.toml", "--set", "E"], "--set: expected NAME=VALUE, got 'E'"),
        (["forward", "study.toml", "--set", "E=abc"], "--set: value of 'E' is not a number: 'abc'"),
        (
            ["forward", "study.toml", "--set", "G=1"],
            "--set: unknown name(s) 'G'; valid: E, nu",
        ),
        (["run", "study.toml", "--workers", "0"], "--workers must be at least 1, got 0"),
        (
            ["forward", "study.toml", "--set", "E=5000"],
            "--set: E = 5000 Pa lies outside its bounds [100, 800] Pa",
        ),
        (
            ["forward", "study.toml", "--set", "nu=-1.5"],
            "--set: nu = -1.5 lies outside its bounds [-0.8, 0.45]",
        ),
    ],
)
def test_bad_arguments_give_status_2_and_one_line(study_file, capsys, argv, message):
    assert main(argv) == 2
    assert one_error_line(capsys).startswith(message)


def test_a_real_subprocess_prints_one_line_and_no_traceback(study_file):
    study_file.write_text(edit("data/observed_100.csv", "data/with_nan.csv"))
    proc = subprocess.run(
        [str(FBIA), "validate", "study.toml"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr == (
        "fbia: error: study.toml: [[observations]] #1 interface: data/with_nan.csv: line 4: "
        "NaN or infinite value\n"
    )


def test_version_and_validate(study_file, capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"fbia {fbia.__version__}\n"
    assert main(["validate", "study.toml"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == "ok"
    assert out[0].startswith("study      tiny (study.toml, sha256 ")
    assert "model      analytic_mound_2d (n_points=41)" in out
    assert "executor   serial" in out


def test_plugins_lists_the_builtins_with_versions(capsys):
    assert main(["plugins", "--json"]) == 0
    rows = {(r["kind"], r["name"]): r for r in json.loads(capsys.readouterr().out)}
    builtins = {
        ("forward_model", "analytic_mound_2d"),
        ("forward_model", "analytic_mound_3d"),
        ("measure", "cpp"),
        ("measure", "ray"),
        ("measure", "rkhs"),
        ("iterator", "levenberg_marquardt"),
    }
    assert builtins <= set(rows)
    for key in builtins:
        assert rows[key]["distribution"] == "fbia"
        assert rows[key]["version"] == fbia.__version__
    assert rows[("measure", "cpp")]["class"] == "fbia.measures.cpp.CppMeasure"
    assert main(["plugins"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split() == ["name", "kind", "distribution", "version", "class"]
    assert any(line.split()[:4] == ["cpp", "measure", "fbia", fbia.__version__] for line in table)


def test_forward_writes_the_interfaces_and_prints_the_discrepancy_table(study_file, capsys):
    assert (
        main(["forward", "study.toml", "--set", "E=400", "--set", "nu=0.3", "--output", "f"]) == 0
    )
    out = capsys.readouterr().out
    folder = study_file.parent / "f"
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    exact = model.solve(TRUTH, [{"inflow_rate": 100.0}], folder).interface({"inflow_rate": 100.0})
    for stem in ("simulated_inflow_rate_100", "observed_inflow_rate_100"):
        csv = fbia.Interface.read(folder / "interfaces" / f"{stem}.csv")
        np.testing.assert_allclose(csv.vertices, exact.vertices, rtol=0, atol=1e-15)
        vtu = meshio.read(folder / "interfaces" / f"{stem}.vtu")  # for ParaView: line cells
        np.testing.assert_allclose(vtu.points[:, :2], exact.vertices, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(vtu.cells_dict["line"], exact.cells)
    assert (folder / "interfaces" / "points_inflow_rate_100.csv").is_file()
    assert (folder / "plots" / "interfaces.png").stat().st_size > 1000
    # the discrepancy table: at the truth the simulated interface is the observed one
    row = next(line.split() for line in out.splitlines() if line.startswith("inflow_rate=100"))
    assert row[1] == "cpp" and float(row[2]) < 1e-12 and row[3] == "41"
    assert "forward run of analytic_mound_2d at E = 400, nu = 0.3: ok" in out
    result = json.loads((folder / "result.json").read_text())
    assert result["status"] == "forward" and result["x"] == TRUTH
    assert len((folder / "evaluations.jsonl").read_text().splitlines()) == 1


def test_forward_keeps_the_model_field_files_and_names_them(study_file, capsys):
    study_file.write_text(edit("n_points = 41", "n_points = 41, write_fields = true"))
    assert main(["forward", "study.toml", "--output", "f"]) == 0
    out = capsys.readouterr().out
    field = study_file.parent / "f" / "run" / "interface_0.csv"  # the model's working folder
    assert f"field interface_0: {Path('f') / 'run' / 'interface_0.csv'}" in out
    simulated = fbia.Interface.read(
        study_file.parent / "f" / "interfaces" / "simulated_inflow_rate_100.csv"
    )
    np.testing.assert_array_equal(fbia.Interface.read(field).vertices, simulated.vertices)


def test_forward_default_point_is_initial_and_D_matches_the_measure(study_file, capsys):
    assert main(["forward", "study.toml"]) == 0
    out = capsys.readouterr().out
    assert "at E = 300, nu = 0.2: ok" in out
    study = fbia.load_study("study.toml")
    model, obs = study.problem.model, study.problem.observations[0]
    sim = model.solve({"E": 300.0, "nu": 0.2}, [obs.coordinate], Path(".")).interface(
        obs.coordinate
    )
    expected_d = study.problem.measure.distance(sim, obs)
    r = study.problem.measure.residuals(sim, obs)
    row = next(line.split() for line in out.splitlines() if line.startswith("inflow_rate=100"))
    assert float(row[2]) == pytest.approx(expected_d, rel=1e-5)
    assert float(row[4]) == pytest.approx(np.abs(r).max(), rel=1e-5)
    assert (study_file.parent / "out" / "forward" / "result.json").is_file()


def test_a_failed_forward_run_exits_1_with_one_line(study_file, capsys):
    study_file.write_text(
        edit("n_points = 41", "n_points = 41, failure_region = { E = [500.0, 900.0] }")
    )
    assert main(["forward", "study.toml", "--set", "E=600"]) == 1
    line = one_error_line(capsys)
    assert line.startswith("the forward run failed: ") and "mesh distortion" in line
    saved = json.loads((study_file.parent / "out" / "forward" / "result.json").read_text())
    assert saved["status"] == "failed" and saved["n_failed"] == 1


def test_run_writes_result_json_with_provenance(study_file, capsys):
    assert main(["run", "study.toml"]) == 0
    out = capsys.readouterr().out
    folder = study_file.parent / "out"
    result = json.loads((folder / "result.json").read_text())
    # exact data: Levenberg-Marquardt recovers the truth
    assert result["success"] and result["iterator"] == "levenberg_marquardt"
    assert result["x"]["E"] == pytest.approx(400.0, rel=1e-4)
    assert result["x"]["nu"] == pytest.approx(0.3, abs=1e-4)
    prov = result["provenance"]
    assert prov["fbia"] == fbia.__version__
    assert prov["python"] == platform.python_version()
    assert prov["numpy"] == np.__version__ and prov["scipy"]
    assert prov["study_text"] == STUDY
    assert prov["study_sha256"] == hashlib.sha256(STUDY.encode()).hexdigest()
    assert prov["seed"] == 3 and prov["executor"]["kind"] == "serial"
    assert prov["host"] and prov["started"] <= prov["finished"]
    assert {
        "forward_model:analytic_mound_2d",
        "measure:cpp",
        "iterator:levenberg_marquardt",
    } <= set(prov["plugins"])
    assert prov["plugins"]["measure:cpp"]["version"] == fbia.__version__
    # every evaluation was logged, one JSON line each
    lines = (folder / "evaluations.jsonl").read_text().splitlines()
    assert len(lines) == result["nfev"] == len(result["evaluations"])
    assert [json.loads(line)["index"] for line in lines] == list(range(len(lines)))
    report = (folder / "report.txt").read_text()
    assert report.strip() in out  # the report is also what the run printed at the end
    assert "discrepancy at x:" in report
    assert (folder / "interfaces" / "simulated_inflow_rate_100.csv").is_file()
    assert (folder / "plots" / "evaluations.png").is_file()


@pytest.mark.parametrize(
    ("case", "old", "new", "status", "says"),
    [
        # one step cannot reach the optimum: a result, but not converged
        (
            "not-converged",
            "max_iter = 30",
            "max_iter = 1",
            3,
            "fbia: the result is not trustworthy (status iteration_limit): ",
        ),
        # every run fails: no estimate at all
        (
            "all-failed",
            "n_points = 41 }",
            "n_points = 41, failure_region = { E = [0.0, 1000.0] } }",
            4,
            "fbia: no result (status ",
        ),
    ],
    ids=["not-converged", "all-failed"],
)
def test_run_exit_status_says_whether_the_result_can_be_trusted(
    study_file, capsys, recwarn, case, old, new, status, says
):
    study_file.write_text(edit(old, new))
    assert main(["run", "study.toml"]) == status
    # plots of a study without a successful run print no matplotlib warning (issue 31 item 6)
    assert not [w for w in recwarn if "No artists with labels" in str(w.message)]
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(says) and err[0].endswith(f"(exit status {status})")
    result = json.loads((study_file.parent / "out" / "result.json").read_text())
    assert not result["success"]  # the result is written all the same
    assert (result["x"] is None) == (status == 4)


def test_an_unreliable_success_is_not_trusted():
    from fbia.core.problem import Result
    from fbia.studies.cli import EXIT_NO_RESULT, EXIT_OK, EXIT_UNTRUSTED, run_exit_status

    assert run_exit_status(Result("completed", True, "", x={"E": 1.0})) == EXIT_OK
    assert run_exit_status(Result("completed", True, "")) == EXIT_OK  # Sobol: no x
    for status in ("unreliable", "unchecked"):
        assert run_exit_status(Result(status, True, "", x={"E": 1.0})) == EXIT_UNTRUSTED
    assert run_exit_status(Result("unreliable", False, "", x={"E": 1.0})) == EXIT_UNTRUSTED
    assert run_exit_status(Result("damping_limit", False, "")) == EXIT_NO_RESULT
    assert run_exit_status(Result("no_result", False, "")) == EXIT_NO_RESULT


def test_run_without_iterator_does_a_forward_run_and_says_so(study_file, capsys):
    study_file.write_text(
        STUDY.split("[iterator]")[0] + "[executor]" + STUDY.split("[executor]")[1]
    )
    assert main(["run", "study.toml", "--output", "o"]) == 0
    out = capsys.readouterr().out
    assert "the study has no [iterator]: one forward run at the start point" in out
    assert "discrepancy of the forward run:" in out
    assert (study_file.parent / "o" / "interfaces" / "simulated_inflow_rate_100.vtu").is_file()


def test_ctrl_c_exits_130_after_saving_what_was_computed(tmp_path, monkeypatch, capsys):
    registry = Registry.load(extra=[PLUGIN])
    monkeypatch.setattr(study_module, "default_registry", lambda: registry)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "toy.toml").write_text(
        '[model]\nname = "toy_mound"\noptions = { interrupt_above = 500.0 }\n'
        '[[parameters]]\nname = "E"\nbounds = [100.0, 800.0]\n'
        '[[parameters]]\nname = "nu"\nbounds = [-0.8, 0.5]\n'
        "[synthetic]\ntruth = { E = 400.0, nu = 0.3 }\ncoordinates = [{ inflow_rate = 100.0 }]\n"
        '[measure]\nname = "vertical"\n[iterator]\nname = "grid"\n[executor]\nkind = "serial"\n'
    )
    # the grid's rows are E = 100, 450, 800: the first run of the third row is "interrupted"
    assert main(["run", "toy.toml"]) == 130
    assert capsys.readouterr().err == "fbia: interrupted; what was computed is saved\n"
    folder = tmp_path / "output"
    lines = (folder / "evaluations.jsonl").read_text().splitlines()
    assert [json.loads(line)["x"]["E"] for line in lines] == [100.0] * 3 + [450.0] * 3
    result = json.loads((folder / "result.json").read_text())
    assert result["status"] == "interrupted" and not result["success"]
    assert result["nfev"] == 6 and result["x"]["E"] == 450.0
    assert result["provenance"]["finished"]


def test_an_unwritable_output_is_one_line_with_status_1(study_file, capsys):
    (study_file.parent / "taken").write_text("a file, not a folder")
    assert main(["forward", "study.toml", "--output", "taken"]) == 1
    assert "taken" in one_error_line(capsys)


def test_a_real_ctrl_c_exits_130_and_saves_the_finished_runs(tmp_path):
    # A real SIGINT to the process group, as a terminal sends it, during a run that would take
    # 30 s: exit 130 at once with one line and no traceback, the 6 finished runs saved.
    # (tests/execution/test_evaluator.py checks that Ctrl-C stops a process pool's workers.)
    write_driver(tmp_path)
    (tmp_path / "toy.toml").write_text(
        '[model]\nname = "toy_mound"\noptions = { slow_above = 500.0 }\n'
        '[[parameters]]\nname = "E"\nbounds = [100.0, 800.0]\n'
        '[[parameters]]\nname = "nu"\nbounds = [-0.8, 0.5]\n'
        "[synthetic]\ntruth = { E = 400.0, nu = 0.3 }\ncoordinates = [{ inflow_rate = 100.0 }]\n"
        '[measure]\nname = "vertical"\n[iterator]\nname = "grid"\n[executor]\nkind = "serial"\n'
    )
    log = tmp_path / "output" / "evaluations.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "drive.py", "run", "toy.toml"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 120.0
        while not (log.is_file() and len(log.read_text().splitlines()) >= 6):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        time.sleep(0.3)  # now in the first 30 s run of the grid's last row (E = 800 Pa)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert time.monotonic() - t0 < 10.0
    assert proc.returncode == 130
    assert err == "fbia: interrupted; what was computed is saved\n"
    assert len(log.read_text().splitlines()) == 6
    result = json.loads((tmp_path / "output" / "result.json").read_text())
    assert (result["status"], result["nfev"]) == ("interrupted", 6)
    assert result["x"]["E"] in (100.0, 450.0)


def test_plugins_options_lists_every_option_with_default_and_unit(capsys):
    assert main(["plugins", "--options", "ale_fsi"]) == 0
    out = capsys.readouterr().out.splitlines()
    from fbia.plugins.ale_fsi.options import AleFsiOptions

    assert out[0] == f"forward_model ale_fsi: {len(AleFsiOptions.model_fields)} options"
    rows = {line.split()[0]: line for line in out[3:]}
    assert set(rows) == set(AleFsiOptions.model_fields)
    assert rows["E"].split()[1:3] == ["400.0", "Pa"]
    assert rows["inflow_rate"].split()[1:3] == ["100.0", "mm^2/s"]
    assert main(["plugins", "--options", "ale_fsi", "--json"]) == 0
    described = json.loads(capsys.readouterr().out)["forward_model"]
    assert all(v["unit"] for v in described.values())  # every ale_fsi option has its unit
    assert described["nu"] == {
        "default": 0.3,
        "unit": "-",
        "description": "Poisson's ratio of the biofilm",
    }


def test_plugins_options_of_an_unknown_name_suggests_the_close_ones(capsys):
    assert main(["plugins", "--options", "ale_fs"]) == 2
    assert one_error_line(capsys) == "--options: no plugin named 'ale_fs'; did you mean ale_fsi?"


def test_validate_warns_of_units_that_look_wrong_and_still_says_ok(study_file, capsys):
    """Data in µm, noise in µm, E in kPa: valid to the schema, so warnings, not errors."""
    data = study_file.parent / "data"
    for name in ("observed_100.csv", "points_100.csv"):
        rows = (data / name).read_text().splitlines()
        scaled = [rows[0]]
        for row in rows[1:]:
            v = [float(c) for c in row.split(",")]
            k = 2 if len(v) >= 4 else len(v)  # points: x, y scaled, directions not
            scaled.append(",".join(str(c * 1000 if i < k else c) for i, c in enumerate(v)))
        (data / f"um_{name}").write_text("\n".join(scaled) + "\n")
    text = (
        STUDY.replace("data/observed_100.csv", "data/um_observed_100.csv")
        .replace("data/points_100.csv", "data/um_points_100.csv")
        .replace('unit = "Pa"\nbounds = [100.0, 800.0]\ninitial = 300.0',
                 'unit = "kPa"\nbounds = [0.1, 0.8]\ninitial = 0.3')
        .replace("x0 = { E = 350.0, nu = 0.25 }", "x0 = { E = 0.35, nu = 0.25 }")
    )  # fmt: skip
    study_file.write_text(text)
    assert main(["validate", "study.toml"]) == 0
    captured = capsys.readouterr()
    assert captured.out.rstrip().endswith("ok")
    warnings = [
        line.removeprefix("fbia: warning: study.toml: ") for line in captured.err.splitlines()
    ]
    assert len(warnings) == 2, warnings
    assert warnings[0].startswith("observation 1: the interface spans ")
    assert "are the data in another unit (µm, m)? fbia's unit is mm" in warnings[0]
    assert warnings[1] == (
        "parameter E: the study says kPa, analytic_mound_2d takes Pa: values are passed as "
        "they are, not converted"
    )
    # kPa values under the unit Pa: the bounds give it away
    study_file.write_text(
        STUDY.replace("bounds = [100.0, 800.0]\ninitial = 300.0", "bounds = [0.1, 0.8]").replace(
            "x0 = { E = 350.0, nu = 0.25 }", "x0 = { E = 0.35, nu = 0.25 }"
        )
    )
    assert main(["validate", "study.toml"]) == 0
    assert capsys.readouterr().err == (
        "fbia: warning: study.toml: parameter E: bounds [0.1, 0.8] Pa lie outside 1-1e+07 Pa, "
        "where biofilm moduli are reported: in kPa or MPa? fbia's unit is Pa\n"
    )
    # noise in µm on data in mm (as large as the data: an error, tests/studies/test_sanity.py)
    study_file.write_text(
        STUDY.replace("noise_std = 0.0005\n\n[measure]", "noise_std = 0.4\n\n[measure]")
    )
    assert main(["validate", "study.toml"]) == 0
    err = capsys.readouterr().err
    assert err == (
        "fbia: warning: study.toml: observation 1: noise_std = 0.4 mm is 50 % of the observed "
        "interfaces' extent (0.8 mm): in µm? fbia's unit is mm\n"
    )
    study_file.write_text(STUDY)
    assert main(["validate", "study.toml"]) == 0
    assert capsys.readouterr().err == ""  # the study of the tests is right


def test_the_json_schema_accepts_every_example_and_refuses_a_typo(capsys):
    jsonschema = pytest.importorskip("jsonschema")
    import tomllib

    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    root = ROOT / "examples"
    studies = [
        f
        for f in sorted(root.rglob("*.toml"))
        if "output" not in f.parts[-2] and "model" in read_sources(f).raw
    ]
    assert len(studies) > 30
    for f in studies:  # the file as an editor sees it (a variant too), and merged
        for table in (tomllib.loads(f.read_text()), read_sources(f).raw):
            errors = list(validator.iter_errors(table))
            assert not errors, f"{f}: {errors[0].message}"
    assert list(validator.iter_errors({"study": {"name": "no model, no base"}}))
    # a variant's tables are partial, and still checked for names and types
    variant = {"study": {"extends": "base.toml"}, "synthetic": {"noise_std": 0.01}}
    assert not list(validator.iter_errors(variant))
    assert list(validator.iter_errors({**variant, "synthetc": {}}))
    assert list(validator.iter_errors({**variant, "synthetic": {"noise_std": "high"}}))
    # so are a base's ([study] base_only = true): what its variants say is not required
    base = {"study": {"base_only": True}, "synthetic": {"noise_std": 0.01}}
    assert not list(validator.iter_errors(base))
    assert list(validator.iter_errors({**base, "study": {"base_only": False}}))
    assert list(validator.iter_errors({**base, "study": {"base_only": "yes"}}))
    whole = tomllib.loads(STUDY)
    assert list(validator.iter_errors({**whole, "synthetic": {"noise_std": 0.01}}))  # no truth
    assert not list(validator.iter_errors(tomllib.loads(STUDY)))
    typo = tomllib.loads(STUDY.replace("[executor]", "[executer]"))
    assert any("executer" in e.message for e in validator.iter_errors(typo))
    wrong = tomllib.loads(STUDY.replace("seed = 3", 'seed = "three"'))
    assert list(validator.iter_errors(wrong))


def test_validate_warns_of_a_truth_outside_the_bounds_and_of_model_options_in_another_unit(
    tmp_path, monkeypatch, capsys
):
    """Issue 43 item 2: the flow-cell demo with its synthetic truth at E = 3000 Pa (bounds
    [50, 1500]) and a model option E = 4e8 Pa (a unit slip): warnings from validate (the study
    is still valid), none for the demo."""
    monkeypatch.chdir(tmp_path)
    demo = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
    Path("demo.toml").write_text(demo)
    assert main(["validate", "demo.toml"]) == 0
    assert capsys.readouterr().err == ""
    slipped = demo.replace("truth = { E = 400.0, nu = 0.3 }", "truth = { E = 3000.0, nu = 0.3 }")
    slipped = slipped.replace("options = { n_points = 81 }", "options = { n_points = 81, E = 4e8 }")
    Path("study.toml").write_text(slipped)
    assert main(["validate", "study.toml"]) == 0
    warnings = [
        line.removeprefix("fbia: warning: study.toml: ")
        for line in capsys.readouterr().err.splitlines()
    ]
    assert warnings == [
        "model option E = 4e+08 Pa lies outside 1-1e+07 Pa, where biofilm moduli are reported: "
        "in another unit? fbia's unit is Pa",
        "[synthetic] truth E = 3000 lies outside [50, 1500], the range E may take: the "
        "calibration can only end at the bound",
    ], warnings
