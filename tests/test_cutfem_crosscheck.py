r"""Cross-check of ``cutfem_fpi`` against the independent ``ale_fsi`` (fitted, moving fluid mesh).

Same flow cell, neo-Hooke skeleton/solid with the same E and nu, 100 mm^2/s.  As the
permeability K -> 0 the channel flow sees what ``ale_fsi`` imposes: eq. 14c gives an
impermeable interface and eq. 14d, with the interface permeability of eq. 15 vanishing like
sqrt(K), no slip.  The biofilms still differ as materials.  In the steady state the pore
pressure p is the Darcy solution with the fluid's normal stress on the interface (eq. 14b),
whatever K, and the mixture carries it: the weak forms of the two solids differ by

    int p div(v) dx

(a drained porous skeleton does not feel the mean fluid pressure, a solid is compressed by
it), plus the volumetric stiffness of psi_vol + psi_pen (eq. 13).  Both act through the
volume change only, which vanishes for an incompressible skeleton.  Hence: at nu = 0.3 the
interfaces approach each other as K falls and then stay ~12 % of the displacement apart
(9.4 um of 75 um on the default meshes); at nu = 0.49 they come within ~2.5 % (1.8 um), the
rest being discretisation and the remaining compressibility.  (Default-mesh figures:
``benchmarks/bench_cutfem_fpi.py ale``.)
"""

from __future__ import annotations

import pytest

pytest.importorskip("xfem")

import shapely  # noqa: E402

import fbia  # noqa: E402
from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel  # noqa: E402

LEVEL = {"inflow_rate": 100.0}


def _distances(nu: float, tmp_path) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    """Hausdorff distance (mm) to ale_fsi at K = 1e-4 and 1e-6 mm^2, and the displacement (mm),
    on the default cutfem_fpi meshes and an ale_fsi mesh of the same interface resolution
    (coarser meshes put several um of discretisation error on either side)."""
    ale = fbia.forward_model(
        "ale_fsi", material="neo_hooke", E=300.0, nu=nu, mesh_size=0.12, interface_mesh_size=0.04
    )
    ref = shapely.LineString(ale.solve({}, [LEVEL], tmp_path).interface(LEVEL).vertices)
    cut = CutFemFpiForwardModel(E=300.0, nu=nu, coupling_tol=1e-7, threads=1)
    out = []
    for K in (1e-4, 1e-6):
        sol = cut.solve({"K": K, "phi0": 0.25}, [LEVEL], tmp_path)
        out.append(
            shapely.hausdorff_distance(ref, shapely.LineString(sol.interface(LEVEL).vertices))
        )
    return out[0], out[1], sol.diagnostics["max_displacement"][0]


def test_small_permeability_approaches_ale_fsi_for_an_incompressible_skeleton(tmp_path) -> None:  # type: ignore[no-untyped-def]
    far, near, disp = _distances(0.49, tmp_path)
    assert near < 0.5 * far  # closer as the pore flow vanishes
    assert near / disp < 0.04  # the materials agree: 1.8 um of 72 um


@pytest.mark.slow
def test_drained_skeleton_differs_from_a_compressible_solid(tmp_path) -> None:  # type: ignore[no-untyped-def]
    far, near, disp = _distances(0.3, tmp_path)
    assert near < far
    assert 0.08 < near / disp < 0.2  # int p div(v): 9.4 um of 75 um
