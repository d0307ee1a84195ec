"""What "reproducible from the study file and its seed" means for a finite-element study
(docs/command_line.md, "Reproducibility"): run serially, the same study gives the same
numbers bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ngsolve")

import fbia  # noqa: E402

STUDY = Path(__file__).resolve().parents[1] / "examples" / "flow_cell" / "study_fsi.toml"


def _calibrate() -> fbia.Result:
    study = fbia.load_study(STUDY)  # a new model each time: nothing carried over
    options = study.iterator.options.model_dump(exclude_unset=True)
    options["x0"] = options["x0"][:1]
    return fbia.iterator("levenberg_marquardt", **options).run(study.problem)


def test_a_serial_fem_calibration_repeats_bit_for_bit() -> None:
    first, second = _calibrate(), _calibrate()
    assert first.nfev == second.nfev > 3 and first.x == second.x
    for a, b in zip(first.evaluations, second.evaluations, strict=True):
        assert a.x == b.x and a.ok and b.ok
        assert a.jacobian is not None and b.jacobian is not None  # J from the tangents
        assert np.array_equal(a.residuals, b.residuals)
        assert np.array_equal(a.jacobian, b.jacobian)
