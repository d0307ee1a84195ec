"""A small valid study file and its data, for tests/studies/test_study.py and
tests/studies/test_cli.py.

``write_study(folder)`` writes ``study.toml`` and ``data/`` (the exact analytic 2-D mound at
E = 400 Pa, nu = 0.3, inflow 100 mm^2/s, 41 vertices, with 8 measurement points, plus a 3-D
surface and a CSV with a NaN for the error cases).  ``BAD_CASES`` are edits of the file and
the one-line error each must give (``study.toml`` relative to the working directory).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import fbia

TRUTH = {"E": 400.0, "nu": 0.3}

STUDY = """\
[study]
name = "tiny"
seed = 3
output = "out"

[model]
name = "analytic_mound_2d"
options = { n_points = 41 }

[[parameters]]
name = "E"
unit = "Pa"
bounds = [100.0, 800.0]
initial = 300.0

[[parameters]]
name = "nu"
bounds = [-0.8, 0.45]
initial = 0.2
prior = { distribution = "beta", a = 3.3, b = 1.7, lower = -0.8, upper = 0.45 }

[[observations]]
coordinate = { inflow_rate = 100.0 }
interface = "data/observed_100.csv"
points = "data/points_100.csv"
noise_std = 0.0005

[measure]
name = "cpp"

[likelihood]
noise_std = 0.0005

[iterator]
name = "levenberg_marquardt"
options = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }

[executor]
kind = "serial"
"""


def write_study(folder: Path, text: str = STUDY) -> Path:
    """Write the study file and its data into ``folder``; returns the study file."""
    data = folder / "data"
    data.mkdir(parents=True, exist_ok=True)
    model = fbia.forward_model("analytic_mound_2d", n_points=41)
    (obs,) = fbia.synthetic_observations(
        model, TRUTH, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0, points=8
    )
    obs.interface.write(data / "observed_100.csv")
    obs.measurement_points.write(data / "points_100.csv")
    rows = (data / "observed_100.csv").read_text().splitlines()
    rows[3] = "0.7,nan,0"
    (data / "with_nan.csv").write_text("\n".join(rows) + "\n")
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    fbia.Interface.surface(v, [[0, 1, 2], [0, 1, 3], [1, 2, 3]]).write(data / "surface.vtu")
    path = folder / "study.toml"
    path.write_text(text)
    return path


def one_error_line(capsys) -> str:
    """The one line ``fbia: error: <message>`` the command line printed, without the prefix
    (and nothing else on stderr)."""
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("fbia: error: ")
    return lines[0].removeprefix("fbia: error: ")


def edit(old: str, new: str) -> str:
    assert old in STUDY, old
    return STUDY.replace(old, new, 1)


#: (id, study text, the start of the error line after "fbia: error: "; where the rest lists
#: what a plugin offers, only its start, so that a plugin's new option breaks nothing here)
BAD_CASES = [
    (
        "store-is-a-folder",
        edit('output = "out"', 'output = "out"\nstore = "data"'),
        "study.toml: [study] store: 'data' is a folder: name the store's file, e.g. 'runs.sqlite'",
    ),
    (
        "toml-syntax",
        edit("seed = 3", "seed = "),
        "study.toml: TOML syntax error: Invalid value (at line 3, column 8)",
    ),
    (
        "unknown-section",
        STUDY + "\n[solver]\ntol = 1\n",
        "study.toml: unknown section [solver]; valid sections: [study], [model], [parameters], "
        "[uncertain], [fixed], [observations], [synthetic], [measure], [likelihood], "
        "[iterator], [executor], [paper]",
    ),
    (
        "unknown-key",
        edit('unit = "Pa"', 'units = "Pa"'),
        "study.toml: [[parameters]] 'E': unknown key 'units'; valid keys: name, unit, bounds, "
        "initial, prior",
    ),
    (
        "bounds-order",
        edit("bounds = [100.0, 800.0]", "bounds = [800.0, 100.0]"),
        "study.toml: [[parameters]] 'E' bounds: lower bound 800 is not below upper bound 100",
    ),
    (
        "bounds-equal",
        edit("bounds = [100.0, 800.0]", "bounds = [100.0, 100.0]"),
        "study.toml: [[parameters]] 'E' bounds: lower bound 100 is not below upper bound 100",
    ),
    (
        "initial-outside",
        edit("initial = 300.0", "initial = 900.0"),
        "study.toml: [[parameters]] 'E' initial: initial guess 900 lies outside bounds [100, 800]",
    ),
    (
        "x0-outside",
        edit("nu = 0.25 }", "nu = 0.49 }"),
        "study.toml: [iterator.options] x0.nu: initial guess 0.49 lies outside bounds [-0.8, 0.45]",
    ),
    (
        "unknown-parameter",
        edit('name = "nu"', 'name = "poisson"'),
        "study.toml: [[parameters]] 'poisson' name: the forward model 'analytic_mound_2d' has "
        "no parameter 'poisson'; it knows: E, nu, ",
    ),
    (
        "unknown-model",
        edit('name = "analytic_mound_2d"', 'name = "ale_fsi2"'),
        "study.toml: [model] name: unknown forward model 'ale_fsi2' (did you mean 'ale_fsi'?); "
        "valid: ",
    ),
    (
        "unknown-measure",
        edit('name = "cpp"', 'name = "cpq"'),
        "study.toml: [measure] name: unknown measure 'cpq' (did you mean 'cpp'?); valid: ",
    ),
    (
        "unknown-model-option",
        edit("n_points = 41", "n_pionts = 41"),
        "study.toml: [model.options]: unknown option 'n_pionts'; valid options: ",
    ),
    (
        "bad-option-value",
        edit("n_points = 41", "n_points = 2"),
        "study.toml: [model.options]: option 'n_points': Input should be greater than or equal to ",
    ),
    (
        "unknown-iterator-option",
        edit("max_iter = 30", "max_iters = 30"),
        "study.toml: [iterator.options]: unknown option 'max_iters'; valid options: ",
    ),
    (
        "missing-data-file",
        edit("data/observed_100.csv", "data/observed_10.csv"),
        "study.toml: [[observations]] #1 interface: data/observed_10.csv: file not found",
    ),
    (
        "nan-in-data",
        edit("data/observed_100.csv", "data/with_nan.csv"),
        "study.toml: [[observations]] #1 interface: data/with_nan.csv: line 4: NaN or infinite "
        "value",
    ),
    (
        "wrong-dimension",
        edit("data/observed_100.csv", "data/surface.vtu"),
        "study.toml: [[observations]] #1 interface: 3-D data for the 2-D forward model "
        "'analytic_mound_2d'",
    ),
    (
        "unknown-executor",
        edit('kind = "serial"', 'kind = "threads"'),
        "study.toml: [executor] kind: unknown executor 'threads'; valid: serial, processes",
    ),
    (
        "no-observations",
        STUDY.split("[[observations]]")[0] + "[measure]" + STUDY.split("[measure]")[1],
        "study.toml: no observations: give [[observations]] (data files) or [synthetic]",
    ),
    (
        "fixed-and-varied",
        STUDY + "\n[fixed]\nE = 400.0\n",
        "study.toml: [fixed] E: 'E' is fixed here and also listed in [[parameters]]",
    ),
]
