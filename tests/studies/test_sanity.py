"""Unit sanity (issue 43 item 2, studies/sanity.py): what no study can mean is one error line
and exit status 2 from ``fbia validate`` and ``fbia run`` before anything runs; what an unusual
experiment may mean is a warning, and the study runs.

The cases are the built-in flow-cell study (examples/flow_cell/study.toml: the closed-form mound
in a 2 mm x 1 mm channel, synthetic data, sigma_N = 1 um) with one number in another unit, or
with its synthetic data replaced by the same mound's interface from a file (0.8 mm across).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from _paths import ROOT
from _studies import one_error_line

import fbia
from fbia.studies.cli import main

DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
# two of Paper A's eleven starts keep the runs short
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"
SYNTHETIC = re.compile(r"\[synthetic\]\n.*?noise_std = 0\.001 +# mm\n", re.S)


def _demo(old: str = "", new: str = "") -> str:
    """The demo with two starts and ``old`` replaced by ``new`` (once, and it must be there)."""
    text = re.sub(r"x0 = \[.*?\n\]\n", STARTS, DEMO, flags=re.S)
    assert STARTS in text and old in text, old
    return text.replace(old, new, 1)


def _from_file(folder: Path, scale: float = 1.0, noise: str = "0.001") -> str:
    """The demo observing the mound's interface from a file, its coordinates times ``scale``
    (1e3: in µm), with the observation's own ``noise`` [mm]."""
    model = fbia.forward_model("analytic_mound_2d", n_points=81)
    truth, coordinates = {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}]
    (obs,) = fbia.synthetic_observations(model, truth, coordinates, noise_std=0.0, seed=0)
    (folder / "data").mkdir(exist_ok=True)
    vertices, cells = obs.interface.vertices * scale, obs.interface.cells
    fbia.Interface(vertices, cells).write(folder / "data" / "observed.csv")
    text = _demo()
    observation = (
        "[[observations]]\ncoordinate = { inflow_rate = 100.0 }\n"
        f'interface = "data/observed.csv"\nnoise_std = {noise}\n'
    )
    assert SYNTHETIC.search(text)
    return SYNTHETIC.sub(observation, text)


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _ale_fsi(options: str) -> str:
    pytest.importorskip("ngsolve")
    return _demo('name = "analytic_mound_2d"\noptions = { n_points = 81 }', (
        f'name = "ale_fsi"\noptions = {{ {options} }}'
    ))  # fmt: skip


ERRORS = [
    (
        "likelihood-noise",
        lambda f: _demo("noise_std = 0.001         # sigma_N", "noise_std = 5.0  # sigma_N"),
        "study.toml: [likelihood]: noise_std = 5 mm is at least the model's channel (2 mm), "
        "which holds every interface: no data point says where the interface is",
    ),
    (
        "synthetic-noise",
        lambda f: _demo("noise_std = 0.001                           # mm", "noise_std = 2.0"),
        "study.toml: [synthetic]: noise_std = 2 mm is at least the model's channel (2 mm)",
    ),
    (
        "observation-noise",
        lambda f: _from_file(f, noise="1.0"),
        "study.toml: [[observations]] #1: noise_std = 1 mm is at least the observed "
        "interfaces' extent (0.8",
    ),
    (
        "data-in-nm",
        lambda f: _from_file(f, scale=1e6),
        "study.toml: [[observations]] #1: the observed interface spans 8e+05 mm, more than "
        "1000 times the model's channel (2 mm): no interface of the model can lie along it",
    ),
    (
        "data-in-m",
        lambda f: _from_file(f, scale=1e-3),
        "study.toml: [[observations]] #1: the observed interface spans 0.0008 mm, less than "
        "1/1000 of the smallest side of the model's channel (1 mm): are the data in m?",
    ),
    (
        "ale-fsi-outline-10-m",
        lambda f: _ale_fsi("outline = [[0.5, 0.0], [5000.0, 10000.0], [9999.0, 0.0]]"),
        "study.toml: [model.options]: option outline holds 5000 mm, more than 1000 times the "
        "model's channel (2 mm): in µm? fbia's unit is mm",
    ),
    (
        "ale-fsi-dome-10-m",
        lambda f: _ale_fsi('geometry = "dome_3d", dome_radius = 10000.0'),
        "study.toml: [model.options]: option dome_radius = 10000 mm is more than 1000 times "
        "the model's channel (2 mm)",
    ),
    (
        "ale-fsi-probe-10-m",
        lambda f: _ale_fsi("probes = [[1.0, 10000.0]]"),
        "study.toml: [model.options]: option probes holds 10000 mm,",
    ),
]


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize(("case", "text", "message"), ERRORS, ids=[c[0] for c in ERRORS])
def test_a_unit_no_study_can_mean_is_one_error_line_and_exit_2(
    folder, capsys, command, case, text, message
):
    Path("study.toml").write_text(text(folder))
    assert main([command, "study.toml"]) == 2
    line = one_error_line(capsys)
    assert line.startswith(message), line
    assert "fbia's unit is mm" in line
    assert not (folder / "output").exists()  # nothing ran, no store


@pytest.mark.parametrize("command", ["validate", "run"])
def test_the_analytic_model_checks_its_lengths_against_its_channel_itself(folder, capsys, command):
    """What the analytic mound's options catch when they are read needs no rule of its own."""
    text = _demo("options = { n_points = 81 }", "options = { n_points = 81, width = 1e4 }")
    Path("study.toml").write_text(text)
    assert main([command, "study.toml"]) == 2
    assert one_error_line(capsys) == (
        "study.toml: [model.options]: footprint [-4999.0, 5001.0] mm leaves the channel [0, 2.0] mm"
    )
    assert not (folder / "output").exists()


def test_the_demo_gives_no_warning_and_no_error(folder, capsys):
    Path("study.toml").write_text(DEMO)
    assert main(["validate", "study.toml"]) == 0
    assert capsys.readouterr().err == ""
    Path("study.toml").write_text(_demo())
    assert main(["run", "study.toml"]) == 0
    assert capsys.readouterr().err == ""


KEPT = [
    (  # 1 um written as 0.5 mm: a broad likelihood, not a blind one
        "likelihood-noise-25-%",
        lambda f: _demo("noise_std = 0.001         # sigma_N", "noise_std = 0.5  # sigma_N"),
        "[likelihood]: noise_std = 0.5 mm is 25 % of the model's channel (2 mm), which holds "
        "every interface: in µm? fbia's unit is mm",
    ),
    (
        "observation-noise-50-%",
        lambda f: _from_file(f, noise="0.4"),
        "observation 1: noise_std = 0.4 mm is 50 % of the observed interfaces' extent (0.8",
    ),
    (  # 400 times the channel: a model of a larger cell would take them
        "data-in-um",
        lambda f: _from_file(f, scale=1e3),
        "observation 1: the interface spans 800",
    ),
    (  # a microchannel may be 50 um high and 60 mm long
        "channel-10-m-high",
        lambda f: _demo(
            "options = { n_points = 81 }", "options = { n_points = 81, channel_height = 1e4 }"
        ),
        "model option channel_height = 10000 mm is more than 1000 times the channel's smallest "
        "side (2 mm): in another unit (µm, m)? fbia's unit is mm",
    ),
    (
        "modulus-option-in-mPa",
        lambda f: _demo("options = { n_points = 81 }", "options = { n_points = 81, E = 4e8 }"),
        "model option E = 4e+08 Pa lies outside 1-1e+07 Pa",
    ),
    (
        "truth-outside-bounds",
        lambda f: _demo("truth = { E = 400.0, nu = 0.3 }", "truth = { E = 3000.0, nu = 0.3 }"),
        "[synthetic] truth E = 3000 lies outside [50, 1500]",
    ),
]


@pytest.mark.parametrize(("case", "text", "warning"), KEPT, ids=[c[0] for c in KEPT])
def test_a_unit_an_unusual_study_may_mean_warns_and_the_study_runs(
    folder, capsys, case, text, warning
):
    Path("study.toml").write_text(text(folder))
    assert main(["validate", "study.toml"]) == 0
    captured = capsys.readouterr()
    assert captured.out.rstrip().endswith("ok")
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fbia: warning: study.toml: {warning}"), lines
    status = main(["run", "study.toml"])
    assert status in (0, 3), status  # a result, trusted or not
    err = capsys.readouterr().err
    assert err.startswith(f"fbia: warning: study.toml: {warning}"), err
    assert (folder / "output" / "result.json").is_file()


@pytest.mark.parametrize("options", ["mesh_size = 1e99", "interface_mesh_size = 1e4"])
def test_element_sizes_are_no_lengths_of_the_geometry(folder, capsys, options):
    """A huge element size may mean "no limit" (netgen's own default is 1e99): no error."""
    Path("study.toml").write_text(_ale_fsi(options))
    assert main(["validate", "study.toml"]) == 0
    assert capsys.readouterr().err == ""
