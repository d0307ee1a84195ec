"""VTU output of a ``cutfem_fpi`` state for ParaView, written with meshio.

Two files per coordinate ``k``:

* ``cutfem_fpi_flow_{k:03d}.vtu`` -- the background mesh with point data ``velocity`` (mm/s,
  0 inside the biofilm), ``pressure`` (Pa, channel fluid), ``pore_pressure`` (Pa, biofilm),
  ``level_set`` (mm, negative in the biofilm) and ``porosity`` (-);
* ``cutfem_fpi_skeleton_{k:03d}.vtu`` -- the biofilm's reference mesh with ``displacement``
  (mm; "Warp By Vector" shows the deformed biofilm), ``porosity`` and ``pore_pressure`` (the
  one the skeleton is loaded with; with ``pore_pressure_transfer = "interface"`` rebuilt from
  the interface values, the better field when K << h^2).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def _vertex_values(mesh: Any, cf: Any) -> np.ndarray:
    pts = np.array([v.point for v in mesh.vertices])
    vals = np.asarray(cf(mesh(pts[:, 0], pts[:, 1])))
    return vals.reshape(len(pts), -1)


def _triangles(mesh: Any) -> np.ndarray:
    import ngsolve as ngs

    return np.array([[v.nr for v in el.vertices] for el in mesh.Elements(ngs.VOL)])


def write_vtu(solver: Any, workdir: Path, index: int) -> dict[str, Path]:
    """Write the current state of a :class:`~fbia.plugins.cutfem_fpi.coupled.PoroFsiSolver`."""
    import meshio

    workdir.mkdir(parents=True, exist_ok=True)
    flow = solver.flow
    bg = solver.bg
    pts = np.array([v.point for v in bg.vertices])
    z = np.zeros((len(pts), 1))
    lset = _vertex_values(bg, flow.lsetp1)[:, 0]
    fluid = lset > 0
    vel = _vertex_values(bg, flow.velocity) * fluid[:, None]
    data = {
        "velocity": np.c_[vel, z],
        "pressure": _vertex_values(bg, flow.pressure)[:, 0] * fluid,
        "pore_pressure": _vertex_values(bg, flow.pore_pressure)[:, 0] * ~fluid,
        "level_set": lset,
        "porosity": _vertex_values(bg, solver.phi_bg)[:, 0] * ~fluid,
    }
    f_path = workdir / f"cutfem_fpi_flow_{index:03d}.vtu"
    meshio.write(
        f_path, meshio.Mesh(np.c_[pts, z], [("triangle", _triangles(bg))], point_data=data)
    )
    sk = solver.skeleton
    spts = np.array([v.point for v in sk.mesh.vertices])
    zs = np.zeros((len(spts), 1))
    sdata = {
        "displacement": np.c_[_vertex_values(sk.mesh, sk.displacement), zs],
        "porosity": _vertex_values(sk.mesh, sk.porosity)[:, 0],
        "pore_pressure": _vertex_values(sk.mesh, sk.pressure)[:, 0],
    }
    s_path = workdir / f"cutfem_fpi_skeleton_{index:03d}.vtu"
    meshio.write(
        s_path,
        meshio.Mesh(np.c_[spts, zs], [("triangle", _triangles(sk.mesh))], point_data=sdata),
    )
    return {f"vtu_flow_{index}": f_path, f"vtu_skeleton_{index}": s_path}
