"""VTU output of an ALE FSI state for ParaView, written with meshio.

The file holds the *reference* mesh (P1 triangles in 2-D, tetrahedra in 3-D) with point data
``velocity`` (mm/s), ``pressure`` (Pa, 0 in the solid), ``displacement`` (mm; "Warp By Vector"
with it shows the deformed configuration), ``interface_force`` (the fluid's consistent nodal
force on the interface nodes, 0 elsewhere: g/s^2 per unit depth in 2-D, g mm/s^2 in 3-D) and
cell data ``subdomain`` (0 fluid, k for ``solid_k``, 1 for ``solid``).  Vectors have three
components (z = 0 in 2-D), as ParaView wants; the values are those at the mesh vertices (the
vertex dofs of the P2 fields).

>>> from fbia.plugins.ale_fsi.output import write_vtu
>>> path = write_vtu(solver, "state.vtu")          # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..fem.flow_cell import FLUID, mesh_arrays


def write_vtu(solver: Any, path: str | Path, extra: dict[str, np.ndarray] | None = None) -> Path:
    """Write the current state of an :class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver`;
    ``extra``: more point data by name, one value or vector per mesh vertex (e.g. the
    nutrient and the growth displacement of ``growth``)."""
    import meshio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = solver.mesh
    nv = mesh.nv
    pts, regions, kind = _cells(mesh)
    cells, subdomain = [], []
    for name, conn in regions.items():
        cells.append(conn)
        sid = 0 if name == FLUID else (int(name.split("_")[1]) if "_" in name else 1)
        subdomain.append(np.full(len(conn), sid, dtype=np.int32))
    v, d, p = solver.gfu.components

    def vertex_vector(gf: Any) -> NDArray[np.float64]:
        return np.column_stack([c.vec.FV().NumPy()[:nv] for c in gf.components])

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
        _xyz(pts),
        [(kind, np.vstack(cells))],
        point_data={
            "velocity": _xyz(vertex_vector(v)),
            "displacement": _xyz(vertex_vector(d)),
            "pressure": pressure,
            "interface_force": _xyz(force),
            **{name: (_xyz(a) if a.ndim == 2 else a) for name, a in (extra or {}).items()},
        },
        cell_data={"subdomain": [np.concatenate(subdomain)]},
    )
    meshio.write(path, out, file_format="vtu")
    return path


def _xyz(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Vectors padded with zeros to three components."""
    return np.c_[a, np.zeros((len(a), 3 - a.shape[1]))]


def _cells(mesh: Any) -> tuple[NDArray[np.float64], dict[str, NDArray[np.int64]], str]:
    """Vertex coordinates, 0-based cells by region name and the meshio cell type."""
    if mesh.dim == 2:
        pts, triangles, _ = mesh_arrays(mesh)
        return pts, triangles, "triangle"
    ngmesh = mesh.ngmesh
    elements = ngmesh.Elements3D().NumPy()
    regions: dict[str, NDArray[np.int64]] = {}
    for i, name in enumerate(ngmesh.GetRegionNames(dim=3), start=1):
        sel = elements["index"] == i
        if np.any(sel):
            conn = elements["nodes"][sel][:, :4].astype(np.int64) - 1
            regions[name] = np.vstack([regions[name], conn]) if name in regions else conn
    return np.array(ngmesh.Coordinates(), dtype=float, copy=True), regions, "tetra"
