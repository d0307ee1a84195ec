"""The quick sizes of Paper A's examples (examples/paper_a/*/quick.toml), ``make test-slow``.

Each runs its study file as ``fbia run`` does, into a temporary folder, and asserts the
pattern the paper reports, not its digits (the full studies with the published numbers are
``make reproduce``; their reports say where fbia's numbers differ and why).
"""

from __future__ import annotations

from pathlib import Path

import pytest

import fbia

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "paper_a"

pytestmark = pytest.mark.slow


def _run(name: str, tmp_path: Path) -> fbia.Result:
    study = fbia.load_study(EXAMPLES / name / "quick.toml")
    return fbia.run_study(study, output=tmp_path / "out", echo=lambda line: None)


def test_homogeneous_example_pattern(tmp_path: Path) -> None:
    """Paper A, homogeneous example, noise-free (Table 2 row 0, Figs. 4-5): the starts recover
    E = 400 Pa, nu = 0.3; the olive start stalls in the valley of negative nu (many more
    iterations)."""
    result = _run("homogeneous", tmp_path)
    q = result.quantities()
    for color in ("red", "brown"):
        assert q[f"start.{color}.converged"] == 1.0
        assert q[f"start.{color}.E"] == pytest.approx(400.0, rel=1e-3)
        assert q[f"start.{color}.nu"] == pytest.approx(0.3, abs=1e-3)
        assert q[f"start.{color}.err_res"] < 1e-6
    assert q["start.olive.iterations"] > 3 * q["start.red.iterations"]


def test_heterogeneous_example_pattern(tmp_path: Path) -> None:
    """Paper A, heterogeneous example, noise-free (Table 3, Fig. 11): the start that
    underestimates E (blue, 300 Pa) recovers the six parameters of the three layers.  The one
    that overestimates it (green, 600 Pa) converged in the paper; in fbia's model its path takes
    nu_1 to the bound 0.499, where Paper A's algorithm (declined steps, mu doubled and kept, as
    in QUEENS) ends at the damping limit without result -- the README's measured finding, on
    this coarse mesh as on the default one."""
    result = _run("heterogeneous", tmp_path)
    q = result.quantities()
    truth = {"E_1": 500.0, "nu_1": 0.2, "E_2": 200.0, "nu_2": 0.1, "E_3": 1000.0, "nu_3": 0.3}
    assert q["start.blue.converged"] == 1.0
    for name, value in truth.items():
        if name.startswith("E"):
            assert q[f"start.blue.{name}"] == pytest.approx(value, rel=1e-3)
        else:
            assert q[f"start.blue.{name}"] == pytest.approx(value, abs=1e-3)
    green = next(s for s in result.starts if s["label"] == "green")
    assert green["status"] == "damping_limit" and green["x"] is None
    last = [h["x"] for h in result.history if h["chain"] == green["start"] - 1 and h["accepted"]][
        -1
    ]
    assert last["nu_1"] == pytest.approx(0.499, abs=2e-3)


def test_poroelastic_example_pattern(tmp_path: Path) -> None:
    """Paper A, poroelastic example (Table 5, Fig. 18): the blue and green starts recover
    E = 300 Pa, phi0 = 0.25.  (That green needs more steps than blue, as in the paper, holds
    on these coarse meshes but not on the default ones: not asserted; see the README.)"""
    pytest.importorskip("xfem")
    q = _run("poroelastic", tmp_path).quantities()
    for color in ("blue", "green"):
        assert q[f"start.{color}.converged"] == 1.0
        assert q[f"start.{color}.E"] == pytest.approx(300.0, rel=1e-3)
        assert q[f"start.{color}.phi0"] == pytest.approx(0.25, abs=1e-3)
        assert q[f"start.{color}.iterations"] <= 27  # the paper's longest path
