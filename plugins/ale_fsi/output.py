"""VTU output of an ALE FSI state for ParaView, written with meshio.

The file holds the *reference* mesh (P1 triangles) with point data ``velocity`` (mm/s),
``pressure`` (Pa, 0 in the solid), ``displacement`` (mm; "Warp By Vector" with it shows the
deformed configuration), ``interface_force`` (g/s^2 per unit depth: the fluid's consistent
nodal force on the interface nodes, 0 elsewhere) and cell data ``subdomain`` (0 fluid,
k for ``solid_k``, 1 for ``solid``).

>>> from fbia.plugins.ale_fsi.output import write_vtu
>>> path = write_vtu(solver, "state.vtu")          # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .geometry import FLUID, mesh_arrays


def write_vtu(solver: Any, path: str | Path, extra: dict[str, np.ndarray] | None = None) -> Path:
    """Write the current state of an :class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver`;
    ``extra``: more point data by name, one value or 2-vector per mesh vertex (e.g. the
    nutrient and the growth displacement of ``growth``)."""
    import meshio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = solver.mesh
    nv = mesh.nv
    pts, regions, _ = mesh_arrays(mesh)
    cells, subdomain = [], []
    for name, conn in regions.items():
        cells.append(conn)
        sid = 0 if name == FLUID else (int(name.split("_")[1]) if "_" in name else 1)
        subdomain.append(np.full(len(conn), sid, dtype=np.int32))
    tris = np.vstack(cells)
    v, d, p = solver.gfu.components

    def vertex_vector(gf: Any) -> np.ndarray:
        return np.c_[gf.components[0].vec.FV().NumPy()[:nv], gf.components[1].vec.FV().NumPy()[:nv]]

    pressure = np.zeros(nv)
    pvals = p.vec.FV().NumPy()
    pressure[: min(nv, len(pvals))] = pvals[:nv]
    solid = np.zeros(nv, dtype=bool)
    for name, conn in regions.items():
        if name != FLUID:
            solid[np.unique(conn)] = True
    fluid = np.zeros(nv, dtype=bool)
    fluid[np.unique(regions[FLUID])] = True
    pressure[solid & ~fluid] = 0.0
    from .postprocess import AleFsiPostprocess

    force = AleFsiPostprocess(solver).interface_nodal_forces()
    out = meshio.Mesh(
        np.c_[pts, np.zeros(nv)],
        [("triangle", tris)],
        point_data={
            "velocity": np.c_[vertex_vector(v), np.zeros(nv)],
            "displacement": np.c_[vertex_vector(d), np.zeros(nv)],
            "pressure": pressure,
            "interface_force": np.c_[force, np.zeros(nv)],
            **{
                name: (np.c_[a, np.zeros(nv)] if a.ndim == 2 else a)
                for name, a in (extra or {}).items()
            },
        },
        cell_data={"subdomain": [np.concatenate(subdomain)]},
    )
    meshio.write(path, out, file_format="vtu")
    return path
