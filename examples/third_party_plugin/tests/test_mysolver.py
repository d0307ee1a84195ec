"""Tests of fbia-mysolver; they reuse fbia's conformance checks (fbia.testing).

``fbia.testing`` is a pytest plugin installed with fbia, so its fixtures (``fbia_registry``)
are available here without any conftest.py.
"""

from __future__ import annotations

import json
import math
import sys

import fbia
import pytest
from fbia.testing import check_forward_model, check_options

from fbia_mysolver import MySolverForwardModel
from fbia_mysolver.external_solver import deformed

PARAMS, COORDS = MySolverForwardModel.example_parameters()


def test_options_reject_unknown_keys():
    assert "timeout" in check_options(MySolverForwardModel)


def test_conforms_to_the_forward_model_protocol(tmp_path):
    solution = check_forward_model(
        MySolverForwardModel(), PARAMS, COORDS, tmp_path, failing_parameters={"E": 5.0, "nu": 0.3}
    )
    assert len(solution.interface({"inflow_rate": 100.0}).vertices) == 61


def test_crest_moves_by_the_closed_form_lean(tmp_path):
    # tau = 6e-3 * 100 / 0.7^2 Pa, G = 400 / 2.6 Pa: lean = 20 tau / G * 0.3 mm
    lean = 20.0 * (0.6 / 0.49) / (400.0 / 2.6) * 0.3
    gamma = MySolverForwardModel().solve(PARAMS, [{"inflow_rate": 100.0}], tmp_path)
    crest = gamma.interface({"inflow_rate": 100.0}).vertices[30]
    assert crest[0] == pytest.approx(1.0 + lean, rel=1e-12)
    assert lean == pytest.approx(0.04775, abs=1e-5)
    assert deformed(400.0, 0.3, 0.0, 5)[2] == pytest.approx((1.0, 0.3), rel=1e-12)


def test_is_registered_with_its_distribution(fbia_registry):
    entry = fbia_registry.get("forward_model", "mysolver")
    assert (entry.factory, entry.distribution) == (MySolverForwardModel, "fbia-mysolver")


def test_solver_failure_quotes_its_stderr(tmp_path):
    with pytest.raises(fbia.ForwardModelError, match=r"status 3; stderr: mesh distortion") as e:
        MySolverForwardModel().solve({"E": 5.0, "nu": 0.3}, COORDS, tmp_path)
    assert e.value.reason == "solver_failed"
    assert "mesh distortion" in (tmp_path / "mysolver.log").read_text()


def test_timeout_is_a_failed_run(tmp_path):
    slow = MySolverForwardModel(
        command=[sys.executable, "-c", "import time; time.sleep(30)"], timeout=0.5
    )
    with pytest.raises(fbia.ForwardModelError, match=r"timed out after 0.5 s") as e:
        slow.solve(PARAMS, COORDS, tmp_path)
    assert e.value.reason == "timeout"


def test_missing_output_is_a_failed_run(tmp_path):
    lazy = MySolverForwardModel(command=[sys.executable, "-c", "print('nothing to do')"])
    with pytest.raises(fbia.ForwardModelError, match=r"wrote no interface_000.csv") as e:
        lazy.solve(PARAMS, COORDS, tmp_path)
    assert e.value.reason == "no_output"


def test_unknown_executable_is_a_config_error_before_any_run():
    with pytest.raises(fbia.ConfigError, match=r"solver executable 'no-such-solver' not found"):
        MySolverForwardModel(command=["no-such-solver", "{input}"])


def test_input_file_carries_parameters_and_states(tmp_path):
    MySolverForwardModel(n_points=5).solve({"E": 300.0}, [{"inflow_rate": 10.0}], tmp_path)
    job = json.loads((tmp_path / "mysolver_input.json").read_text())
    assert job["parameters"] == {"E": 300.0, "nu": 0.3}
    assert job["states"] == [{"coordinate": {"inflow_rate": 10.0}, "output": "interface_000.csv"}]
    assert math.isclose(job["settings"]["n_points"], 5)
