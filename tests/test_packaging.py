"""Issue 29 item 8: the core installs and works without the heavy stacks (a plugin author
runs fbia.testing's checks without NGSolve, GPy, scikit-image or Dask), a part whose extra
is missing is one line naming the extra, and the wheel holds every sub-package.

A core-only environment is simulated in a subprocess: an import hook makes every module of
the extras unimportable (as if never installed), before fbia is imported."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from fbia.core.extras import EXTRA_OF_MODULE

ROOT = Path(__file__).resolve().parents[1]

BLOCK = f"""
import sys

class _NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {sorted(EXTRA_OF_MODULE)!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, _NotInstalled())
"""


def _core_only(code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", BLOCK + code],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )


def test_the_core_and_the_conformance_kit_work_without_the_extras(tmp_path):
    done = _core_only(
        """
import fbia, fbia.testing
from fbia.core.registry import list_plugins
from fbia.testing import check_forward_model, check_measure, check_options
from fbia.plugins.analytic.mound_2d import AnalyticMound2DForwardModel
from pathlib import Path

names = sorted(e.name for e in list_plugins())
check_options(AnalyticMound2DForwardModel)
check_forward_model(AnalyticMound2DForwardModel(), {"E": 400.0, "nu": 0.3},
                    [{"inflow_rate": 100.0}], Path("."))
check_measure(fbia.measure("cpp"), dims=(2,), mesh_dependent=True)
model = fbia.forward_model("analytic_mound_2d", n_points=41)
obs = fbia.synthetic_observations(model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}],
                                  noise_std=0.0, seed=0)
problem = fbia.InverseProblem(model=model, measure=fbia.measure("ray"), observations=obs,
    parameters=[fbia.Parameter("E", (100.0, 800.0)), fbia.Parameter("nu", (-0.8, 0.5))])
result = fbia.iterator("levenberg_marquardt", x0={"E": 300.0, "nu": 0.2}).run(problem)
print("plugins", " ".join(names))
print("lm", result.success, round(result.x["E"], 3))
heavy = [m for m in sys.modules if m.split(".")[0] in ("ngsolve", "GPy", "numba", "skimage")]
print("heavy", heavy)
""",
        tmp_path,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert "plugins ale_fsi analytic_mound_2d analytic_mound_3d cpp cutfem_fpi" in lines[0]
    assert lines[1] == "lm True 400.0"
    assert lines[2] == "heavy []"


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            'fbia.forward_model("ale_fsi")',
            "forward_model 'ale_fsi': needs ngsolve, netgen, which is not installed: "
            "pip install 'fbia[fem]'",
        ),
        (
            'fbia.forward_model("cutfem_fpi")',
            "forward_model 'cutfem_fpi': needs ngsolve, netgen, xfem, which is not installed: "
            "pip install 'fbia[fem]'",
        ),
        (
            'fbia.iterator("gp_smc")',
            "iterator 'gp_smc': needs GPy, numba, which is not installed: "
            "pip install 'fbia[bayes]'",
        ),
        (
            "fbia.segment_oct(__import__('numpy').ones((4, 4, 4)), (0.01, 0.01, 0.01))",
            "OCT segmentation: needs skimage, which is not installed: pip install 'fbia[oct]'",
        ),
        (
            "fbia.DaskEvaluator()",
            "the dask executor: needs distributed, which is not installed: "
            "pip install 'fbia[dask]'",
        ),
    ],
)
def test_a_part_whose_extra_is_missing_is_one_line_naming_it(tmp_path, call, message):
    done = _core_only(
        f"""
import fbia
try:
    {call}
except fbia.ConfigError as err:
    print(err)
""",
        tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == message


def test_a_study_with_a_missing_extra_is_refused_at_validate(tmp_path):
    (tmp_path / "study.toml").write_text(
        '[model]\nname = "ale_fsi"\n[[parameters]]\nname = "E"\nbounds = [100.0, 800.0]\n'
        "[synthetic]\ntruth = { E = 400.0 }\ncoordinates = [ { inflow_rate = 100.0 } ]\n"
        '[measure]\nname = "ray"\n'
    )
    done = _core_only(
        "from fbia.studies.cli import main\nraise SystemExit(main(['validate', 'study.toml']))",
        tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "fbia: error: study.toml: [model.options] 'ale_fsi': needs ngsolve, netgen, which is not "
        "installed: pip install 'fbia[fem]'"
    )


def test_the_wheel_holds_every_sub_package_and_module(tmp_path):
    """Built from this checkout (no dependencies, no network): every .py file of the code
    folders is in the wheel under fbia/."""
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp_path), str(ROOT)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    (wheel,) = tmp_path.glob("fbia-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {"fbia/__init__.py", "fbia/pytest_plugin.py"}
    for folder in ("core", "plugins", "measures", "iterators", "testing"):
        for path in (ROOT / folder).rglob("*.py"):
            expected.add(f"fbia/{path.relative_to(ROOT).as_posix()}")
    assert sorted(expected - names) == []


def test_fbia_plugins_says_which_modules_a_plugin_misses(tmp_path):
    done = _core_only(
        "from fbia.studies.cli import main\nraise SystemExit(main(['plugins']))", tmp_path
    )
    assert done.returncode == 0, done.stderr
    rows = {line.split()[0]: line for line in done.stdout.splitlines()[2:]}
    assert rows["ale_fsi"].rstrip().endswith("ngsolve, netgen")
    assert rows["gp_smc"].rstrip().endswith("GPy, numba")
    assert rows["levenberg_marquardt"].rstrip().endswith("LevenbergMarquardtIterator")
