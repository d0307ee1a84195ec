"""The verdict on a least-squares optimum (iterators/lm/fit_quality.py, issue 43 item 1):
a parameter at a bound or residuals inconsistent with the stated noise make the status
``unreliable`` and ``fbia run`` exit 3 with the cause named; a right fit says success.

The cases are the built-in flow-cell study (examples/flow_cell/study.toml: the closed-form
mound, synthetic data with 1 um of noise, cpp measure, sigma_N = 1 um) with its truth moved
outside the bounds, with sigma_N stated 10x smaller than the data's noise, and as it is, over
several noise draws.
"""

from __future__ import annotations

import math
import re

import pytest
from _paths import ROOT
from scipy.stats import chi2

import fbia
from fbia.core.likelihood import P_MISFIT
from fbia.iterators.lm.fit_quality import FitQuality, bound_hits
from fbia.studies.cli import main

DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
# two of Paper A's eleven starts keep the tests short; the verdict is on the best optimum
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"


def _study(tmp_path, *, truth="{ E = 400.0, nu = 0.3 }", sigma_n="0.001", seed=1):
    text = re.sub(r"x0 = \[.*?\n\]\n", STARTS, DEMO, flags=re.S)
    text = text.replace("truth = { E = 400.0, nu = 0.3 }", f"truth = {truth}")
    text = text.replace("noise_std = 0.001         # sigma_N", f"noise_std = {sigma_n}  # sigma_N")
    text = text.replace("seed = 1 ", f"seed = {seed} ")
    assert STARTS in text and f"truth = {truth}" in text and f"seed = {seed} " in text
    path = tmp_path / "study.toml"
    path.write_text(text)
    return path


def _last_line(capsys) -> str:
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_truth_outside_the_bounds_is_at_a_bound_and_exits_3(tmp_path, capsys):
    """E = 3000 Pa with bounds [50, 1500]: the fit ends at E = 1500 with residuals ~3x the
    noise; it used to say converged and exit 0."""
    path = _study(tmp_path, truth="{ E = 3000.0, nu = 0.3 }")
    assert main(["run", str(path)]) == 3
    line = _last_line(capsys)
    assert "not trustworthy (status unreliable): at bound: E = 1500 (its upper bound)" in line
    assert "the stated noise" in line and "the noise level or the model is wrong" in line
    result = fbia.load_result(tmp_path / "output")
    assert result.status == "unreliable" and not result.success
    assert result.info["convergence"].startswith("converged")
    q = result.quality
    assert isinstance(q, FitQuality) and q.at_bound == ("E",) and q.bound_sides == ("upper",)
    assert q.misfit and q.noise_ratio > 2.0
    assert "E" not in result.stderr and "nu" in result.stderr  # no std. error at a bound
    assert "no std. error at a bound: E" in result.summary()
    qs = result.quantities()
    assert qs["n_at_bound"] == 1.0 and qs["p_chi2"] < P_MISFIT


def test_noise_stated_ten_times_too_small_exits_3(tmp_path, capsys):
    """Data with 1 um of noise, sigma_N stated as 0.1 um: residuals ~10x the stated noise."""
    path = _study(tmp_path, sigma_n="0.0001")
    assert main(["run", str(path)]) == 3
    line = _last_line(capsys)
    ratio = float(re.search(r"residuals ([0-9.]+)x the stated noise", line).group(1))
    assert 8.0 < ratio < 12.5, line
    assert "at bound" not in line
    result = fbia.load_result(tmp_path / "output")
    assert result.status == "unreliable" and result.quality.at_bound == ()


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_a_right_fit_says_success_over_noise_draws(tmp_path, capsys, seed):
    """The demo as it is, over five noise draws: no false alarm (the chi-square test flags a
    right fit with probability 1e-3)."""
    path = _study(tmp_path, seed=seed)
    assert main(["run", str(path)]) == 0
    result = fbia.load_result(tmp_path / "output")
    assert result.status.startswith("converged") and result.quality.trusted
    q = result.quality
    assert q.dof == 81 - 2 and q.p_value > P_MISFIT
    assert 0.7 < q.noise_ratio < 1.3  # the data's noise is the stated one
    assert set(result.stderr) == {"E", "nu"}


def test_chi_square_figures_and_bounds():
    q = FitQuality(chi2=120.0, dof=79, p_value=0.5)
    assert q.noise_ratio == pytest.approx(math.sqrt(120.0 / 79))
    # 79 degrees of freedom: chi2 = 120 lies just inside the 1e-3 tail's limit, 130 beyond it
    limit = chi2.isf(P_MISFIT, 79)
    assert 120.0 < limit < 130.0
    assert FitQuality(chi2=120.0, dof=79, p_value=float(chi2.sf(120.0, 79))).trusted
    late = FitQuality(chi2=130.0, dof=79, p_value=float(chi2.sf(130.0, 79)))
    assert late.misfit and "residuals 1.28x the stated noise" in late.causes[0]
    assert not FitQuality().misfit and FitQuality().noise_ratio is None
    import numpy as np

    hits = bound_hits(
        ["a", "b", "c"],
        np.array([1.0, 0.5 + 1e-12, 0.3]),
        np.array([0.0, 0.5, 0.0]),
        np.array([1.0, 2.0, math.inf]),
    )
    assert hits == (("a", "b"), (1.0, 0.5), ("upper", "lower"))
