"""Tampered and foreign result folders (issue 44 item 4): ``fbia.load_result`` and
``load_posterior`` give one ConfigError naming the file and the field, or load the data
right; never a traceback, a hang, a crash later in ``summary()``/``quantities()`` or wrong
data in silence.

The folders are built from two real small results: a Levenberg-Marquardt run of the flow-cell
demo with two starts through ``fbia run`` (as tests/iterators/lm/test_lm_fit_quality.py does)
and a gp_smc run of the closed-form mound (as tests/iterators/gp_smc do), its result.json and
posterior files.  Each case copies them and changes one thing.  No case can hang: a FIFO or a
device is refused from the opened file's type, without reading it.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _paths import ROOT

import fbia
from fbia.core.version import __version__
from fbia.iterators.gp_smc.posterior import load_posterior, save_posterior
from fbia.studies import result_io
from fbia.studies.cli import main

DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"
N_PARTICLES = 200
MAJOR, MINOR = (int(n) for n in __version__.split(".")[:2])
NEXT_MINOR = f"{MAJOR}.{MINOR + 1}.0"


@pytest.fixture(scope="module")
def lm_output(tmp_path_factory) -> Path:
    """The flow-cell demo with two starts, run through the command line (~3 s)."""
    folder = tmp_path_factory.mktemp("lm")
    study = folder / "study.toml"
    study.write_text(re.sub(r"x0 = \[.*?\n\]\n", STARTS, DEMO, flags=re.S))
    assert main(["run", str(study)]) == 0
    return folder / "output"


@pytest.fixture(scope="module")
def gp_output(tmp_path_factory) -> tuple[Path, Any]:
    """A small gp_smc result of the closed-form mound (~3 s), saved as ``fbia run`` does:
    result.json, posterior.npz and posterior.json; and the result itself."""
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    truth = {"E": 400.0, "nu": 0.3, "inflow_rate": 100.0}
    problem = fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=fbia.synthetic_observations(model, truth, [{}], noise_std=0.0, seed=0),
        noise_std=0.03,
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
        fixed={"inflow_rate": 100.0},
    )
    options = {"n_particles": N_PARTICLES, "n_rejuvenation": 2, "zeta": 0.9, "seed": 0}
    result = fbia.iterator("gp_smc", n_train=24, design="sobol", **options).run(problem)
    assert result.posterior is not None
    folder = tmp_path_factory.mktemp("gp")
    result.save(folder / "result.json")
    save_posterior(result, folder)
    return folder, result


# -- how a folder is tampered with ------------------------------------------------------------
Edit = Callable[[Path], None]


def _json(name: str, change: Callable[[dict[str, Any]], Any]) -> Edit:
    """Change the JSON of the file ``name``; ``change`` edits it in place."""

    def edit(folder: Path) -> None:
        data = json.loads((folder / name).read_text())
        change(data)
        (folder / name).write_text(json.dumps(data))

    return edit


def _text(name: str, old: str, new: str) -> Edit:
    """Replace the first match of the regular expression ``old`` in the file ``name``."""

    def edit(folder: Path) -> None:
        text = (folder / name).read_text()
        changed = re.sub(old, new, text, count=1)
        assert changed != text, old
        (folder / name).write_text(changed)

    return edit


def _replace(name: str, make: Callable[[Path], None]) -> Edit:
    def edit(folder: Path) -> None:
        (folder / name).unlink()
        make(folder / name)

    return edit


def _npz(change: Callable[[dict[str, Any]], Any]) -> Edit:
    def edit(folder: Path) -> None:
        with np.load(folder / "posterior.npz") as data:
            arrays = {k: data[k] for k in data.files}
        change(arrays)
        np.savez_compressed(folder / "posterior.npz", **arrays)

    return edit


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """Set the dotted ``path`` (``a.b.0.c``: list items by index) to ``value``."""

    def change(data: dict[str, Any]) -> None:
        *head, last = path.split(".")
        for key in head:
            data = data[int(key)] if isinstance(data, list) else data[key]
        if value is _DELETE:
            del data[last]
        elif isinstance(data, list):
            data[int(last)] = value
        else:
            data[last] = value

    return change


_DELETE = object()
FIFO = _replace("result.json", os.mkfifo)
DEV_ZERO = _replace("result.json", lambda p: p.symlink_to("/dev/zero"))
DEEP = "[" * 100_000 + "]" * 100_000  # beyond Python's recursion limit
NESTED = json.loads("[" * 150 + "]" * 150)  # parses, but deeper than MAX_DEPTH


def _latin_1(path: Path) -> None:
    """An e acute written as Latin-1 into the first message."""
    path.write_bytes(path.read_bytes().replace(b'"message": "', b'"message": "\xe9', 1))


def _weights(n: int) -> Callable[[dict[str, Any]], None]:
    def change(data: dict[str, Any]) -> None:
        post = data["info"]["posterior"]
        post["weights"] = post["weights"][:n]

    return change


def _columns(data: dict[str, Any]) -> None:
    post = data["info"]["posterior"]
    post["particles"] = [[*row, 1.0] for row in post["particles"]]


# (id, which result, the edit, the ConfigError's message after the file's name)
REFUSED: list[tuple[str, str, Edit, str]] = [
    # the file itself
    ("fifo", "lm", FIFO, r"not a regular file \(a FIFO\): not read"),
    ("symlink_to_dev_zero", "lm", DEV_ZERO, r"not a regular file \(a device\): not read"),
    ("a_folder", "lm", _replace("result.json", Path.mkdir), r"not a regular file \(a folder\)"),
    ("latin_1", "lm", lambda f: _latin_1(f / "result.json"), r"not UTF-8 text \(byte \d+\)"),
    ("not_json", "lm", _text("result.json", r"\}\s*$", ""), r"not JSON \(Expecting"),
    ("a_list", "lm", _replace("result.json", lambda p: p.write_text("[1]")), "not a JSON object"),
    (
        "recursion",
        "lm",
        _text("result.json", r'"history": \[', '"history": [' + DEEP + ","),
        "nested more than 100 levels deep",
    ),
    ("nested", "lm", _json("result.json", _set("info.deep", NESTED)), r"info\.deep\[0\]"),
    # numbers that are none
    ("nfev_1e400", "lm", _text("result.json", r'"nfev": \d+', '"nfev": 1e400'), "nfev is inf"),
    (
        "nan_literal",
        "lm",
        _text("result.json", r'"err_res": [^,]+', '"err_res": NaN'),
        "err_res is nan",
    ),
    ("huge_int", "lm", _json("result.json", _set("nfev", 10**30)), "nfev is 1000000000000000000"),
    ("nfev_string", "lm", _json("result.json", _set("nfev", "52")), r'nfev is "52", not a whole'),
    ("negative_nfev", "lm", _json("result.json", _set("nfev", -1)), "nfev is -1, a negative count"),
    # booleans that are none
    (
        "success_false_string",
        "lm",
        _json("result.json", _set("success", "false")),
        r'success is "false", not true or false',
    ),
    (
        "success_zero",
        "lm",
        _json("result.json", _set("success", 0)),
        "success is 0, not true or false",
    ),
    (
        "start_success_string",
        "lm",
        _json("result.json", _set("starts.1.success", "true")),
        r'starts\[1\]\.success is "true", not true or false',
    ),
    # versions and formats
    (
        "newer_fbia",
        "lm",
        _json("result.json", _set("provenance.fbia", "9.9.9")),
        r"provenance\.fbia is 9\.9\.9: written by a later fbia than this one "
        rf"\({re.escape(__version__)}\)"
        r".*load it with fbia 9\.9 or later",
    ),
    (
        "newer_minor",
        "lm",
        _json("result.json", _set("provenance.fbia", NEXT_MINOR)),
        rf"provenance\.fbia is {re.escape(NEXT_MINOR)}: written by a later fbia",
    ),
    (
        "no_version",
        "lm",
        _json("result.json", _set("provenance.fbia", 5)),
        "provenance.fbia is 5, not a version",
    ),
    # another iterator's data under a label
    (
        "gp_labelled_lm",
        "gp",
        _json("result.json", _set("iterator", "levenberg_marquardt")),
        r'iterator is "levenberg_marquardt", but the file has no starts, err_res of a LMResult',
    ),
    (
        "lm_labelled_gp",
        "lm",
        _json("result.json", _set("iterator", "gp_smc")),
        r'iterator is "gp_smc", but the file has no n_x, posterior of a GpSmcResult',
    ),
    (
        "lm_labelled_sobol",
        "lm",
        _json("result.json", _set("iterator", "sobol_indices")),
        "has no quantity, indices of a SobolIndicesResult",
    ),
    (
        "no_success",
        "lm",
        _json("result.json", _set("success", _DELETE)),
        "success is missing: not a result as fbia writes it",
    ),
    # an optimum that is none
    (
        "nan_optimum",
        "lm",
        _json("result.json", _set("x.E", "nan")),
        "x.E is nan in a result whose success is true",
    ),
    ("inf_optimum", "lm", _json("result.json", _set("x.nu", "-inf")), "x.nu is -inf in a result"),
    (
        "x_a_list",
        "lm",
        _json("result.json", _set("x", [1.0, 2.0])),
        r"x is \[1.0, 2.0\], not an object",
    ),
    ("x_a_word", "lm", _json("result.json", _set("x.E", "abc")), r'x\.E is "abc", not a number'),
    ("x_off_names", "lm", _json("result.json", _set("names", ["E"])), r"x is over \['E', 'nu'\]"),
    # fields of the wrong type or shape (which crashed summary() or quantities() later)
    ("info_a_list", "lm", _json("result.json", _set("info", [])), r"info is \[\], not an object"),
    (
        "cov_shape",
        "lm",
        _json("result.json", _set("cov", [[1.0, 2.0]])),
        r"cov has shape \(1, 2\), not \(2, 2\)",
    ),
    (
        "cov_ragged",
        "lm",
        _json("result.json", _set("cov", [[1.0], [1.0, 2.0]])),
        "cov is not rectangular",
    ),
    (
        "corr_words",
        "lm",
        _json("result.json", _set("corr", [["a", "b"], ["c", "d"]])),
        "corr is not an array of numbers",
    ),
    (
        "start_without_best",
        "lm",
        _json("result.json", _set("starts.0.best", _DELETE)),
        r"starts\[0\]\.best is missing",
    ),
    (
        "start_x_off_names",
        "lm",
        _json("result.json", _set("starts.1.x", {"E": 1.0})),
        r"starts\[1\]\.x is over \['E'\]",
    ),
    (
        "quality_at_bound",
        "lm",
        _json("result.json", _set("quality.at_bound", "E")),
        r'quality\.at_bound is "E", not a list',
    ),
    (
        "evaluation_x",
        "lm",
        _json("result.json", _set("evaluations.3.x", "abc")),
        r'evaluations\[3\]\.x is "abc", not an object',
    ),
    (
        "stderr_words",
        "lm",
        _json("result.json", _set("stderr.E", "big")),
        r'stderr\.E is "big", not a number',
    ),
    (
        "a_line_break_in_a_key",
        "lm",
        _json("result.json", _set("stderr", {"E\nfoo": "big"})),
        r'stderr\.E\\nfoo is "big", not a number',
    ),
    (
        "jacobian_sources",
        "lm",
        _json("result.json", _set("info.jacobians", [1])),
        r"holds data its summary\(\) fails on \(AttributeError",
    ),
    # a posterior in result.json that does not fit its particles
    (
        "five_weights",
        "gp",
        _json("result.json", _weights(5)),
        rf"info\.posterior\.weights has shape \(5,\), not \({N_PARTICLES},\): one per particle",
    ),
    (
        "a_column_more",
        "gp",
        _json("result.json", _columns),
        rf"info\.posterior\.particles has shape \({N_PARTICLES}, 3\), not \(N, 2\)",
    ),
    (
        "nan_weight",
        "gp",
        _json("result.json", _set("info.posterior.weights.0", "nan")),
        "info.posterior.weights are not non-negative numbers summing to 1",
    ),
    (
        "interval_missing",
        "gp",
        _json("result.json", _set("info.posterior.credible_intervals.nu", _DELETE)),
        r"info\.posterior\.credible_intervals\.nu is not 3 numbers",
    ),  # fmt: skip
    (
        "mean_all_short",
        "gp",
        _json("result.json", _set("info.posterior.mean_all", [1.0])),
        r"info\.posterior\.mean_all has shape \(1,\), not \(2,\)",
    ),
    (
        "train_mask_ints",
        "gp",
        _json("result.json", _set("info.design.train_mask", [1, 0])),
        r"info\.design\.train_mask is not an array of true/false",
    ),
    (
        "design_short",
        "gp",
        _json("result.json", _set("info.design.status", ["ok"])),
        r"info\.design\.status has shape \(1,\)",
    ),
    (
        "n_x_string",
        "gp",
        _json("result.json", _set("info.n_x", "2")),
        r'info\.n_x is "2", not a whole number',
    ),
]

# (id, the edit, the file named in the ConfigError, its message)
REFUSED_POSTERIORS: list[tuple[str, Edit, str, str]] = [
    ("npz_fifo", _replace("posterior.npz", os.mkfifo), "posterior.npz", "not a regular file"),
    (
        "npz_dev_zero",
        _replace("posterior.npz", lambda p: p.symlink_to("/dev/zero")),
        "posterior.npz",
        "not a regular file",
    ),
    (
        "npz_not_zip",
        _replace("posterior.npz", lambda p: p.write_bytes(b"PK\x03\x04 no zip")),
        "posterior.npz",
        "not a posterior.npz of fbia",
    ),
    (
        "npz_pickled",
        _npz(_set("names", np.array([{"E": 1}], dtype=object))),
        "posterior.npz",
        r"not a posterior.npz of fbia \(Object arrays cannot be loaded",
    ),
    (
        "npz_five_weights",
        _npz(lambda a: a.update(weights=a["weights"][:5])),
        "posterior.npz",
        rf"weights has shape \(5,\), not \({N_PARTICLES},\): one per particle",
    ),
    (
        "npz_names_columns",
        _npz(lambda a: a.update(names=np.array(["E", "nu", "G"]))),
        "posterior.npz",
        r"particles has shape \(\d+, 2\), not \(N, 3\)",
    ),
    (
        "npz_format",
        _npz(lambda a: a.update(format=np.array("fbia-posterior-9"))),
        "posterior.npz",
        "format is 'fbia-posterior-9', not 'fbia-posterior-1'",
    ),
    (
        "npz_no_log_prior",
        _npz(lambda a: a.pop("log_prior")),
        "posterior.npz",
        "has no array log_prior",
    ),
    (
        "npz_foreign_array",
        _npz(lambda a: a.update(extra=np.zeros(2))),
        "posterior.npz",
        "has an array extra, which fbia does not write",
    ),
    (
        "npz_n_x_float",
        _npz(lambda a: a.update(n_x=np.array(2.0))),
        "posterior.npz",
        "n_x holds float64 values, not an integer",
    ),
    (
        "npz_nan_particle",
        _npz(lambda a: a["particles"].__setitem__((0, 0), np.nan)),
        "posterior.npz",
        "particles holds NaN or infinite values",
    ),
    ("json_fifo", _replace("posterior.json", os.mkfifo), "posterior.json", "not a regular file"),
    (
        "json_format",
        _json("posterior.json", _set("format", "fbia-posterior-9")),
        "posterior.json",
        "format is 'fbia-posterior-9', not posterior.npz's 'fbia-posterior-1'",
    ),
    (
        "json_names",
        _json("posterior.json", _set("names", ["E", "G"])),
        "posterior.json",
        r"names is \['E', 'G'\], not posterior.npz's \['E', 'nu'\]",
    ),
    (
        "json_nan",
        _text("posterior.json", r'"seconds": [^,}\s]+', '"seconds": NaN'),
        "posterior.json",
        "not JSON \\(NaN is not JSON as fbia writes it",
    ),
    (
        "json_deep",
        _replace("posterior.json", lambda p: p.write_text(DEEP)),
        "posterior.json",
        "nested too deeply",
    ),
]


def _folder(tmp_path: Path, source: Path, edit: Edit) -> Path:
    folder = tmp_path / "tampered"
    folder.mkdir()
    for name in ("result.json", "posterior.npz", "posterior.json"):
        if (source / name).is_file():
            shutil.copy(source / name, folder / name)
    edit(folder)
    return folder


def _source(which: str, lm_output: Path, gp_output: tuple[Path, Any]) -> Path:
    return lm_output if which == "lm" else gp_output[0]


def _views(result: Any) -> None:
    """What a loaded result must give without raising."""
    assert result.summary() and isinstance(result.quantities(), dict)
    result.to_records()
    assert result._repr_html_().startswith('<div class="fbia-result">')


def _one_line(exc: pytest.ExceptionInfo, path: Path, message: str) -> None:
    text = str(exc.value)
    assert "\n" not in text
    assert text.startswith(f"{path}: "), text
    assert re.search(message, text[len(str(path)) + 2 :]), text


@pytest.mark.parametrize(
    ("which", "edit", "message"),
    [pytest.param(w, e, m, id=i) for i, w, e, m in REFUSED],
)
def test_a_tampered_result_is_one_config_error_naming_the_field(
    tmp_path, lm_output, gp_output, which, edit, message
):
    folder = _folder(tmp_path, _source(which, lm_output, gp_output), edit)
    with pytest.raises(fbia.ConfigError) as exc:
        fbia.load_result(folder)
    _one_line(exc, folder / "result.json", message)


@pytest.mark.parametrize(
    ("edit", "name", "message"),
    [pytest.param(e, n, m, id=i) for i, e, n, m in REFUSED_POSTERIORS],
)
def test_tampered_posterior_files_are_one_config_error_naming_the_array(
    tmp_path, gp_output, edit, name, message
):
    folder = _folder(tmp_path, gp_output[0], edit)
    with pytest.raises(fbia.ConfigError) as exc:
        load_posterior(folder)
    _one_line(exc, folder / name, message)


def test_a_file_larger_than_the_bound_is_not_read(tmp_path, lm_output, monkeypatch):
    folder = _folder(tmp_path, lm_output, lambda folder: None)
    monkeypatch.setattr(result_io, "MAX_RESULT_BYTES", 1000)
    with pytest.raises(fbia.ConfigError) as exc:
        fbia.load_result(folder)
    _one_line(exc, folder / "result.json", "larger than 1000 bytes: not a file fbia writes")


def _same(a: Any, b: Any) -> bool:
    """Equal, NaN equal to NaN (the quantities of a result)."""
    return a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


def test_the_untampered_results_load_as_they_were(tmp_path, lm_output, gp_output):
    """The LM result re-serialises to its file, field for field; the gp_smc result has the
    run's summary, quantities, arrays and posterior files."""
    lm = fbia.load_result(lm_output)
    saved = json.loads((lm_output / "result.json").read_text())
    assert json.loads(json.dumps(lm.to_dict(), default=str)) == saved
    assert lm.success and lm.status == saved["status"] and lm.quality is not None
    _views(lm)
    folder, run = gp_output
    gp = fbia.load_result(folder)
    assert type(gp) is type(run) and gp.summary() == run.summary()
    q, q_run = gp.quantities(), run.quantities()
    assert q.keys() == q_run.keys() and all(_same(q[k], q_run[k]) for k in q)
    for key in ("particles", "weights", "log_likelihood", "cov_all", "map"):
        np.testing.assert_array_equal(getattr(gp.posterior, key), getattr(run.posterior, key))
    np.testing.assert_array_equal(gp.design.train_mask, run.design.train_mask)
    _views(gp)
    post = load_posterior(folder)
    assert post["names"] == run.posterior.names and int(post["n_x"]) == run.posterior.n_x
    np.testing.assert_array_equal(post["weights"], run.posterior.weights)
    assert post["meta"]["format"] == "fbia-posterior-1"


# (id, which result, the edit, a check of what loaded)
LOADED: list[tuple[str, str, Edit, Callable[[Any], bool]]] = [
    (
        "older_fbia",
        "lm",
        _json("result.json", _set("provenance.fbia", "0.1.0")),
        lambda r: r.provenance["fbia"] == "0.1.0",
    ),
    (
        "dev_version",
        "lm",
        _json("result.json", _set("provenance.fbia", "0.2.0.dev3")),
        lambda r: r.success,
    ),
    (
        "lm_before_quality",
        "lm",
        _json("result.json", _set("quality", _DELETE)),
        lambda r: r.quality is None and "fit against the stated noise" not in r.summary(),
    ),
    (
        "gp_before_model_check",
        "gp",
        _json("result.json", _set("info.model_check", _DELETE)),
        lambda r: r.model_check is None and r.posterior is not None,
    ),
    (
        "saved_from_python",
        "lm",
        _json("result.json", _set("provenance", {})),
        lambda r: r.provenance == {},
    ),
    (
        "an_unknown_field",
        "lm",
        _json("result.json", _set("comment", "added by hand")),
        lambda r: not hasattr(r, "comment"),
    ),
    (
        "nan_optimum_of_a_failure",
        "lm",
        _json("result.json", lambda d: d.update(success=False, x={"E": "nan", "nu": 0.3})),
        lambda r: math.isnan(r.x["E"]) and not r.success,
    ),  # fmt: skip
    (
        "an_uninstalled_iterator",
        "lm",
        _json("result.json", _set("iterator", "not_installed")),
        lambda r: type(r) is fbia.Result and r.nfev > 0,
    ),
    ("a_link_to_the_file", "lm", lambda f: _link(f / "result.json"), lambda r: r.success),
]


def _link(path: Path) -> None:
    target = path.with_name("elsewhere.json")
    path.rename(target)
    path.symlink_to(target)


@pytest.mark.parametrize(
    ("which", "edit", "check"),
    [pytest.param(w, e, c, id=i) for i, w, e, c in LOADED],
)
def test_what_fbia_could_have_written_loads_and_its_views_compute(
    tmp_path, lm_output, gp_output, which, edit, check
):
    folder = _folder(tmp_path, _source(which, lm_output, gp_output), edit)
    result = fbia.load_result(folder)
    assert check(result)
    _views(result)


def test_a_surrogate_convergence_result_loads_with_its_table(tmp_path):
    """Its result.json holds the names, points and L of its design (the table's columns; the
    rows' GP states stay out, None when read back)."""
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    truth = {"E": 400.0, "nu": 0.3}
    problem = fbia.InverseProblem(
        model=model,
        measure=fbia.measure("cpp"),
        observations=fbia.synthetic_observations(model, truth, [{"inflow_rate": 100.0}], 0.0, 0),
        noise_std=0.01,
        parameters=[fbia.Parameter("E", bounds=(100.0, 800.0)), fbia.Parameter("nu", (-0.8, 0.5))],
    )
    it = fbia.iterator("surrogate_convergence", n_train=[10, 20], n_test=10, seed=0)
    result = it.run(problem)
    loaded = fbia.load_result(result.save(tmp_path / "result.json"))
    assert loaded.summary() == result.summary() and "nu" in loaded.table()
    np.testing.assert_array_equal(loaded.points, result.points)
    assert [r.state for r in loaded.rows] == [None, None]
    _views(loaded)
