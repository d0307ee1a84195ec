"""Results come back from their files as their types (fbia.load_result), and a gp_smc
posterior leaves files that ArviZ reads (issue 29 item 3)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _studies import edit

import fbia
from fbia.core.cli import main
from fbia.iterators.gp_smc_result import GpSmcResult
from fbia.iterators.lm_result import LMResult

BAYES = edit(
    "options = { x0 = { E = 350.0, nu = 0.25 }, max_iter = 30 }",
    "options = { n_train = 32, n_particles = 1000, n_rejuvenation = 5, zeta = 0.9, seed = 0, "
    'design = "sobol", n_check = 4 }',
).replace('name = "levenberg_marquardt"', 'name = "gp_smc"')


def _same_quantities(a: dict[str, float], b: dict[str, float]) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])), k


def test_an_lm_result_loads_back_as_it_was(study_file, capsys):
    study = fbia.load_study(study_file)
    result = fbia.run_study(study, echo=lambda line: None)
    for source in (study_file.parent / "out", study_file.parent / "out" / "result.json"):
        loaded = fbia.load_result(source)
        assert isinstance(loaded, LMResult)
        _same_quantities(loaded.quantities(), result.quantities())
        assert loaded.summary() == result.summary()
        np.testing.assert_array_equal(loaded.cov, result.cov)
        assert len(loaded.evaluations) == len(result.evaluations) == result.nfev
        np.testing.assert_array_equal(
            loaded.evaluations[-1].residuals, result.evaluations[-1].residuals
        )


def test_a_gp_smc_result_loads_back_and_its_posterior_is_an_arviz_netcdf(study_file, capsys):
    arviz = pytest.importorskip("arviz")
    study_file.write_text(BAYES)
    # 32 runs leave the surrogate far off at the posterior (RMSE ~ 80 in L): unreliable,
    # exit status 3, and its files are written all the same
    assert main(["run", "study.toml"]) == 3
    out = study_file.parent / "out"
    printed = capsys.readouterr().out.splitlines()
    assert any(line.startswith("wrote ") and line.endswith("posterior.nc") for line in printed)
    loaded = fbia.load_result(out)
    assert isinstance(loaded, GpSmcResult) and loaded.posterior is not None
    saved = json.loads((out / "result.json").read_text())
    assert loaded.x == saved["x"] and loaded.status == saved["status"] == "unreliable"
    post = loaded.posterior
    assert post.particles.shape == (1000, 2) and post.weights.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(post.weights @ post.particles[:, :2], post.mean)
    assert "posterior from 1000 particles" in loaded.summary()
    data = arviz.from_netcdf(out / "posterior.nc")
    assert set(data.posterior.data_vars) == {"E", "nu"}
    assert float(data.posterior["E"].mean()) == pytest.approx(post.mean[0], rel=0.02)
    assert {"lp", "log_prior"} <= set(data.sample_stats.data_vars)
    assert (out / "posterior.npz").is_file() and (out / "posterior.json").is_file()


def test_what_is_not_a_result_is_one_line(tmp_path):
    with pytest.raises(fbia.ConfigError, match="no result.json there"):
        fbia.load_result(tmp_path)
    (tmp_path / "result.json").write_text('{"x": 1}')
    with pytest.raises(fbia.ConfigError, match="not an fbia result"):
        fbia.load_result(tmp_path)
    (tmp_path / "result.json").write_text("{")
    with pytest.raises(fbia.ConfigError, match="not a readable result file"):
        fbia.load_result(tmp_path / "result.json")


def test_a_field_the_file_does_not_hold_is_none_and_a_wrong_type_is_one_line(tmp_path):
    from dataclasses import dataclass

    from fbia.core.result_io import from_dict

    @dataclass
    class Row:
        n: int
        state: dict  # a live object the JSON leaves out

    assert from_dict(Row, {"n": 3}) == Row(3, None)
    (tmp_path / "result.json").write_text(
        json.dumps({"status": "completed", "success": True, "message": "", "nfev": "many"})
    )
    with pytest.raises(fbia.ConfigError, match=r"cannot be read as a Result \(invalid literal"):
        fbia.load_result(tmp_path)
