"""A user's 3-D tetrahedral mesh for the ALE FSI model: read (gmsh, VTU, netgen .vol) and write.

The names are those of the 2-D convention (:mod:`fbia.plugins.fem.flow_cell`): tetrahedra
in regions ``fluid`` and ``solid`` or ``solid_1..n`` (subdomains with parameters ``E_k``,
``nu_k``), boundary triangles in ``inflow``, ``outflow``, ``walls``, ``interface``,
``solid_fixed`` (and optionally ``symmetry``, ``obstacle``, ``internal``):

* gmsh ``.msh`` -- physical groups (volumes for regions, surfaces for boundaries);
* any other meshio format (VTU, XDMF, ...) -- meshio ``cell_sets``;
* netgen ``.vol`` -- netgen's material and boundary-condition names.

As in :mod:`~fbia.plugins.ale_fsi.geometry3d`, fluid tetrahedra whose four vertices lie on
faces with a prescribed velocity are split at their centroid (Taylor-Hood stability:
Boffi 1997), and elements have straight sides (quadratic cells are read by their corners).
:func:`write_mesh_3d` writes a mesh in this convention (gmsh 2.2), so a built mesh reads back
as a user's would.

>>> from fbia.plugins.ale_fsi.mesh_file3d import is_3d_mesh_file, read_mesh_3d
>>> mesh = read_mesh_3d("colony.msh")                          # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ..fem.flow_cell import (
    FLUID,
    REQUIRED_BOUNDARIES,
    SOLID,
    check_mesh,
    read_with_meshio,
    write_named_gmsh,
)
from .geometry3d import connectivity_by_region, mesh_from_arrays_3d, split_locked_tets

if TYPE_CHECKING:
    import ngsolve

__all__ = ["is_3d_mesh_file", "read_mesh_3d", "read_mesh_names_3d", "write_mesh_3d"]

_TETS = ("tetra", "tetra10")
_TRIS = ("triangle", "triangle6", "triangle7")
Cells = dict[str, NDArray[np.int64]]


def is_3d_mesh_file(path: str | Path) -> bool:
    """Whether a mesh file holds a 3-D mesh (netgen ``.vol`` of dimension 3, or tetrahedra)."""
    path = Path(path)
    if path.suffix.lower() == ".vol":
        return _read_vol(path)[0].shape[1] == 3
    return any(b.type in _TETS for b in read_with_meshio(path).cells)


def read_mesh_3d(path: str | Path) -> ngsolve.Mesh:
    """Read a named 3-D mesh (module docstring); a :class:`ConfigError` names the file and
    the names it lacks."""
    path = Path(path)
    where = str(path)
    points, regions, boundaries = _read(path)
    _check_names(regions, boundaries, where)
    locked = np.vstack([c for n, c in boundaries.items() if n not in ("outflow", "internal")])
    points, regions[FLUID] = split_locked_tets(points, regions[FLUID], locked)
    mesh = mesh_from_arrays_3d(points, regions, boundaries)
    check_mesh(mesh, where)
    return mesh


def read_mesh_names_3d(path: str | Path) -> list[str]:
    """Names of the regions and boundaries of a 3-D mesh file, after the checks that need no
    NGSolve mesh (``fbia validate``): finite coordinates, tetrahedra of positive volume, the
    named regions and boundaries of the module docstring."""
    _, regions, boundaries = _read(Path(path))
    _check_names(regions, boundaries, str(path))
    return [*regions, *boundaries]


def write_mesh_3d(mesh: ngsolve.Mesh, path: str | Path) -> Path:
    """Write a named 3-D mesh as gmsh 2.2 (physical groups = region/boundary names)."""
    ngmesh = mesh.ngmesh
    pts = np.array(ngmesh.Coordinates(), dtype=float, copy=True)
    regions = connectivity_by_region(ngmesh.Elements3D().NumPy(), ngmesh.GetRegionNames(dim=3), 4)
    boundaries = connectivity_by_region(
        ngmesh.Elements2D().NumPy(), ngmesh.GetRegionNames(dim=2), 3
    )
    return write_named_gmsh(path, pts, [("triangle", boundaries, 2), ("tetra", regions, 3)])


def _check_names(regions: Cells, boundaries: Cells, where: str) -> None:
    solids = [n for n in regions if n == SOLID or n.startswith(SOLID + "_")]
    missing = [FLUID] if FLUID not in regions else []
    missing += [] if solids else ["solid[_k]"]
    missing += [b for b in (*REQUIRED_BOUNDARIES, "outflow") if b not in boundaries]
    if missing:
        raise ConfigError(
            f"the 3-D mesh lacks the named region(s)/boundary(ies) {missing} (it has regions "
            f"{sorted(regions)} and boundaries {sorted(boundaries)})",
            where,
        )


def _read(path: Path) -> tuple[NDArray[np.float64], Cells, Cells]:
    points, regions, boundaries = (
        _read_vol(path) if path.suffix.lower() == ".vol" else _read_meshio(path)
    )
    if points.shape[1] == 3:
        _check_geometry(points, regions, str(path))
    return points, regions, boundaries


def _check_geometry(points: NDArray[np.float64], regions: Cells, where: str) -> None:
    """Finite coordinates, cells that name existing points, no tetrahedron without volume
    (a flat mesh, one layer of points in a plane, has nothing but)."""
    if not np.isfinite(points).all():
        bad = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
        raise ConfigError(f"point {bad} of the mesh has a NaN or infinite coordinate", where)
    tets = np.vstack(list(regions.values())) if regions else np.empty((0, 4), np.int64)
    if len(tets) == 0:
        raise ConfigError("the mesh has no tetrahedra", where)
    if tets.min() < 0 or tets.max() >= len(points):
        raise ConfigError(
            f"tetrahedra name points up to {int(tets.max())}, the mesh has {len(points)}", where
        )
    corners = points[tets]
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6.0
    extent = float(np.ptp(points, axis=0).max())
    flat = volume <= 1e-12 * extent**3
    if flat.all():
        raise ConfigError(
            "the mesh has no volume: all its tetrahedra are flat (its points in one plane?)",
            where,
        )
    if flat.any():
        raise ConfigError(
            f"{int(flat.sum())} of the mesh's {len(tets)} tetrahedra have no volume "
            f"(e.g. tetrahedron {int(np.flatnonzero(flat)[0])})",
            where,
        )


def _read_vol(path: Path) -> tuple[NDArray[np.float64], Cells, Cells]:
    import netgen.meshing as nm

    where = str(path)
    if not path.is_file():
        raise ConfigError("mesh file not found", where)
    _check_vol_counts(path)
    ngmesh = nm.Mesh()
    try:
        ngmesh.Load(str(path))
    except Exception as exc:  # netgen raises bare Exception subclasses
        raise ConfigError(f"netgen cannot read the mesh: {exc}", where) from None
    if ngmesh.dim != 3:
        return np.zeros((0, ngmesh.dim)), {}, {}
    pts = np.array(ngmesh.Coordinates(), dtype=float, copy=True)
    regions = connectivity_by_region(ngmesh.Elements3D().NumPy(), ngmesh.GetRegionNames(dim=3), 4)
    boundaries = connectivity_by_region(
        ngmesh.Elements2D().NumPy(), ngmesh.GetRegionNames(dim=2), 3
    )
    return pts, regions, boundaries


#: netgen .vol sections whose next line is a value, not a count of the lines that follow
_VOL_VALUES = frozenset({b"dimension", b"geomtype"})
#: largest .vol file read [bytes]
MAX_VOL_BYTES = 2 << 30


def _check_vol_counts(path: Path) -> None:
    """netgen reads as many lines as a section announces, past the end of the file forever
    (a garbage or truncated ``.vol`` hangs it, its memory growing): check every section's
    count against the lines that follow first."""
    where = str(path)
    if path.stat().st_size > MAX_VOL_BYTES:
        raise ConfigError(f"the .vol file is larger than {MAX_VOL_BYTES >> 30} GB", where)
    lines = [line.strip() for line in path.read_bytes().splitlines()]
    lines = [line for line in lines if line and not line.startswith(b"#")]
    if not lines or lines[0] not in (b"mesh3d", b"mesh2d"):
        raise ConfigError("not a netgen .vol mesh: it does not begin with 'mesh3d'", where)
    for i in range(len(lines) - 1):
        key, count = lines[i], lines[i + 1]
        if key.replace(b"_", b"").isalpha() and key not in _VOL_VALUES and count.isdigit():
            left = len(lines) - i - 2
            if int(count) > left:
                raise ConfigError(
                    f"section {key.decode()!r} announces {int(count)} entries, but only {left} "
                    "lines follow: a truncated or damaged .vol file",
                    where,
                )


def _read_meshio(path: Path) -> tuple[NDArray[np.float64], Cells, Cells]:
    where = str(path)
    data = read_with_meshio(path)
    points = np.asarray(data.points, dtype=float)
    if points.shape[1] != 3:
        raise ConfigError("a 3-D mesh needs 3 coordinates per point", where)
    sets = {name: s for name, s in data.cell_sets.items() if not name.startswith("gmsh:")}
    if not sets and "gmsh:physical" in data.cell_data and data.field_data:
        # gmsh files: physical names in field_data {name: [tag, dim]}, tags per cell
        dims = {**dict.fromkeys(_TETS, 3), **dict.fromkeys(_TRIS, 2)}
        for name, value in data.field_data.items():
            tag, dim = int(value[0]), int(value[1])
            sets[name] = [
                np.flatnonzero(np.asarray(tags) == tag) if dims.get(block.type) == dim else None
                for block, tags in zip(data.cells, data.cell_data["gmsh:physical"], strict=True)
            ]
    if not sets:
        raise ConfigError("the mesh has no named cell sets (gmsh physical groups)", where)
    regions: Cells = {}
    boundaries: Cells = {}
    for name, per_block in sets.items():
        for block, idx in zip(data.cells, per_block, strict=True):
            if idx is None or len(idx) == 0:
                continue
            conn = np.asarray(block.data, dtype=np.int64)[np.asarray(idx, dtype=np.int64)]
            if block.type in _TETS:
                regions[name] = np.vstack(
                    [regions.get(name, np.empty((0, 4), np.int64)), conn[:, :4]]
                )
            elif block.type in _TRIS:
                boundaries[name] = np.vstack(
                    [boundaries.get(name, np.empty((0, 3), np.int64)), conn[:, :3]]
                )
            elif block.type not in ("vertex", "line", "line3"):
                raise ConfigError(f"unsupported cell type {block.type!r} in set {name!r}", where)
    return points, regions, boundaries
