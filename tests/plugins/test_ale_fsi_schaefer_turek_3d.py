"""The 3-D Schäfer-Turek benchmark 3D-1Z (steady flow past a cylinder, Re = 20) against the
published drag and lift coefficients.

Reference values: tests/data/fsi/schaefer_turek_1996_3d.json (Schäfer & Turek 1996 interval
c_D in [6.05, 6.25]; refined c_D = 6.18533, c_L = 0.009401 of Braack & Richter 2006).

Tolerance of the coarse test: 3 % on c_D.  Measured (benchmarks/bench_schaefer_turek_3d.py,
P2/P1, curved cylinder): channel h = 0.1 m, cylinder h = 0.03 m, 28 044 unknowns: c_D = 6.3186
(+2.15 %); cylinder h = 0.02 m, 36 959 unknowns: 6.2624 (+1.25 %); c_D falls towards the
reference as the cylinder mesh is refined, so the coarse value sits above it and 3 % leaves
0.85 % for meshing/BLAS differences between machines.  c_L (0.0094) is below the
discretisation error of the force on these meshes and is not asserted: it scatters by
+-0.005 from mesh to mesh up to 184k unknowns (0.0145, -0.0003, 0.0036, 0.0119, 0.0090,
0.0116; the table and the reason are in benchmarks/bench_schaefer_turek_3d.py).  The slow
test asserts the published c_D interval on a finer mesh (channel h = 0.07 m, cylinder
h = 0.015 m, 81 248 unknowns: c_D = 6.2326, +0.76 %; about 150 s and 1.5 GB).
"""

from __future__ import annotations

import json

import pytest
from _paths import TESTS

pytest.importorskip("ngsolve")


from fbia.core.errors import ConfigError  # noqa: E402
from fbia.plugins.ale_fsi import schaefer_turek_3d  # noqa: E402

DATA = json.loads((TESTS / "data" / "fsi" / "schaefer_turek_1996_3d.json").read_text())
REF = DATA["reference"]["braack_richter_2006"]
INTERVAL = DATA["reference"]["schaefer_turek_1996_interval"]
TOL_COARSE = 0.03


def test_reference_data_are_consistent():
    lo, hi = INTERVAL["c_D"]
    assert lo <= REF["c_D"] <= hi
    lo, hi = INTERVAL["c_L"]
    assert lo <= REF["c_L"] <= hi
    assert schaefer_turek_3d.U_MEAN == pytest.approx(DATA["flow"]["U_mean"])


def test_coarse_mesh_drag_within_tolerance():
    r = schaefer_turek_3d.solve(mesh_size=0.1, cylinder_mesh_size=0.03)
    assert r.c_drag == pytest.approx(REF["c_D"], rel=TOL_COARSE), r
    # c_D converges from above on these meshes (benchmark): the coarse value over-predicts
    assert r.c_drag > REF["c_D"]
    assert r.newton_iterations <= 8


@pytest.mark.slow
def test_fine_mesh_drag_in_published_interval():
    r = schaefer_turek_3d.solve(mesh_size=0.07, cylinder_mesh_size=0.015)
    lo, hi = INTERVAL["c_D"]
    assert lo <= r.c_drag <= hi, r


def test_bad_mesh_size_is_a_config_error():
    with pytest.raises(ConfigError, match="mesh sizes must be positive"):
        schaefer_turek_3d.build_mesh(0.0)
