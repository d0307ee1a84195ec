"""Meshes for the ALE FSI model: the flow-cell builder and the user-mesh reader/writer.

Every mesh the solver sees has *named* regions and boundaries:

=============== ===========================================================================
region          ``fluid``; ``solid`` or ``solid_1``, ``solid_2``, ... (one per subdomain)
boundary        ``inflow``, ``outflow``, ``walls`` (no-slip), ``interface`` (fluid-solid),
                ``solid_fixed`` (solid clamped), optional ``obstacle`` (rigid no-slip body),
                optional ``symmetry`` (planes normal to one axis: no normal velocity and
                displacement -- the side walls of a 3-D ridge in plane strain)
=============== ===========================================================================

The same names serve 3-D meshes (tetrahedra, boundary triangles), built by
:mod:`fbia.plugins.ale_fsi.geometry3d`.

>>> from fbia.plugins.fem.flow_cell import build_flow_cell
>>> mesh = build_flow_cell(mesh_size=0.2, interface_mesh_size=0.08)   # doctest: +SKIP
>>> sorted(mesh.GetMaterials())                                        # doctest: +SKIP
['fluid', 'solid']

A user mesh (gmsh ``.msh`` or any format meshio reads, with the names above as physical
groups / cell sets) goes through :func:`read_mesh`; :func:`write_mesh` writes a mesh in the
same convention (gmsh 2.2), so a generated mesh can be read back exactly as a user's would.
NGSolve is imported inside the functions, so importing this module is cheap.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.data_files import read_meshio
from ...core.errors import ConfigError, ForwardModelError
from .outlines import DEFAULT_OUTLINE

if TYPE_CHECKING:
    import ngsolve

FLUID = "fluid"
SOLID = "solid"
BOUNDARY_NAMES = (
    "inflow",
    "outflow",
    "walls",
    "interface",
    "solid_fixed",
    "obstacle",
    "internal",
    "symmetry",
)
REQUIRED_BOUNDARIES = ("inflow", "interface", "solid_fixed")


def _as_outline(points: ArrayLike, where: str) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
        raise ConfigError(
            f"an outline needs at least 3 points of shape (n, 2), got {p.shape}", where
        )
    if not np.all(np.isfinite(p)):
        raise ConfigError("outline contains NaN or infinite coordinates", where)
    return p


def _signed_area(p: NDArray[np.float64]) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def build_flow_cell(
    length: float = 2.0,
    height: float = 1.0,
    outline: ArrayLike = DEFAULT_OUTLINE,
    smooth: bool = True,
    subdomains: Sequence[ArrayLike] = (),
    mesh_size: float = 0.1,
    interface_mesh_size: float = 0.03,
    grading: float = 0.3,
    curve_order: int = 2,
    solid_mesh_size: float | None = None,
) -> ngsolve.Mesh:
    """Mesh a 2-D flow cell: a channel ``length`` x ``height`` with a biofilm on its floor.

    Parameters
    ----------
    length, height
        Channel size in mm; the floor is ``y = 0``, the inflow ``x = 0``.
    outline
        Biofilm outline (n, 2) in mm from the upstream foot to the downstream foot (both on the
        floor, ``y = 0``); the solid lies under it.
    smooth
        Interpolate the outline by a cubic spline (True) or use the polygon (False).
    subdomains
        Closed polygons (mm); the part of the biofilm inside the k-th becomes region
        ``solid_k`` (k = 1, 2, ...), the rest the last region.  Paper A Fig. 9.
    mesh_size
        Maximum element size in mm.
    interface_mesh_size
        Element size on the fluid-solid interface (and inside the biofilm, unless
        ``solid_mesh_size`` is given), in mm.
    grading
        Netgen's mesh grading (0..1; smaller grows the elements more slowly).
    curve_order
        Polynomial order of the element geometry along the curved outline (1: straight).
    solid_mesh_size
        Element size inside the biofilm and on its base, in mm (default:
        ``interface_mesh_size``); the elements grade from the interface size to it.
    """
    import ngsolve
    from netgen.occ import (
        Face,
        Glue,
        OCCGeometry,
        Pnt,
        Rectangle,
        Segment,
        SplineApproximation,
        Wire,
        X,
        Y,
    )

    where = "ale_fsi geometry"
    if not (length > 0 and height > 0):
        raise ConfigError(f"channel size must be positive, got {length} x {height} mm", where)
    p = _as_outline(outline, f"{where}: outline")
    tol = 1e-9 * max(length, height)
    if abs(p[0, 1]) > tol or abs(p[-1, 1]) > tol:
        raise ConfigError("the outline must start and end on the channel floor (y = 0)", where)
    if np.any(p[1:-1, 1] <= tol) or np.any(p[:, 1] >= height - tol):
        raise ConfigError("inner outline points must lie strictly inside the channel", where)
    if np.any(p[:, 0] <= tol) or np.any(p[:, 0] >= length - tol):
        raise ConfigError("the outline must stay clear of the inflow and outflow", where)
    if p[0, 0] >= p[-1, 0]:
        raise ConfigError(
            "the outline must run from the upstream foot to the downstream foot "
            f"(x from {p[0, 0]} to {p[-1, 0]}); reverse it",
            where,
        )
    import shapely

    closed = np.vstack([p, p[:1]])
    if not shapely.LineString(closed).is_simple:
        raise ConfigError("the outline intersects itself", where)
    h_solid = interface_mesh_size if solid_mesh_size is None else solid_mesh_size
    if not (mesh_size > 0 and interface_mesh_size > 0 and h_solid > 0):
        raise ConfigError("mesh sizes must be positive", where)

    channel = Rectangle(length, height).Face()
    channel.edges.Min(X).name = "inflow"
    channel.edges.Max(X).name = "outflow"
    channel.edges.Min(Y).name = "walls"
    channel.edges.Max(Y).name = "walls"
    # OCC needs the face boundary counter-clockwise: downstream foot -> top -> upstream foot,
    # then the base along the floor.
    ccw = p[::-1]
    if smooth:
        top = SplineApproximation(
            [Pnt(float(x), float(y), 0.0) for x, y in ccw], deg_min=3, deg_max=3, tol=1e-7
        )
        edges = [top]
    else:
        edges = [Segment(Pnt(*ccw[i], 0.0), Pnt(*ccw[i + 1], 0.0)) for i in range(len(ccw) - 1)]
    base = Segment(Pnt(float(p[0, 0]), 0.0, 0.0), Pnt(float(p[-1, 0]), 0.0, 0.0))
    biofilm = Face(Wire([*edges, base]))
    biofilm.edges.name = "interface"
    biofilm.edges.Min(Y).name = "solid_fixed"
    for e in biofilm.edges:
        e.maxh = interface_mesh_size
    biofilm.edges.Min(Y).maxh = h_solid
    biofilm.maxh = h_solid
    fluid = channel - biofilm
    fluid.faces.name = FLUID

    parts = _split_subdomains(biofilm, subdomains, h_solid, where)
    shape = Glue([fluid, *parts])
    try:
        ngmesh = OCCGeometry(shape, dim=2).GenerateMesh(maxh=mesh_size, grading=grading)
    except Exception as exc:  # netgen raises bare Exception/NgException subclasses
        raise ConfigError(f"netgen could not mesh the flow cell: {exc}", where) from None
    mesh = ngsolve.Mesh(ngmesh)
    check_mesh(mesh, where)
    if curve_order > 1:
        mesh.Curve(curve_order)
    return mesh


def _split_subdomains(biofilm: Any, subdomains: Sequence[ArrayLike], h: float, where: str) -> list:
    """The biofilm face cut into ``solid_k`` faces by the subdomain polygons (Paper A Fig. 9)."""
    from netgen.occ import MoveTo

    if not subdomains:
        biofilm.faces.name = SOLID
        return [biofilm]
    parts = []
    rest = biofilm
    for k, poly in enumerate(subdomains, start=1):
        q = _as_outline(poly, f"{where}: subdomains[{k - 1}]")
        if _signed_area(q) < 0:
            q = q[::-1]
        wire = MoveTo(float(q[0, 0]), float(q[0, 1]))
        for x, y in q[1:]:
            wire = wire.LineTo(float(x), float(y))
        cut = wire.Close().Face()
        cut.edges.name = "internal"
        part = rest * cut
        if not part.faces:
            raise ConfigError(f"subdomain {k} does not overlap the biofilm", where)
        part.faces.name = f"{SOLID}_{k}"
        parts.append(part)
        rest = rest - cut
    if rest.faces:
        rest.faces.name = f"{SOLID}_{len(parts) + 1}"
        parts.append(rest)
    for part in parts:
        part.faces.maxh = h
    return parts


def solid_regions(mesh: ngsolve.Mesh) -> list[str]:
    """Names of the solid regions, ``["solid"]`` or ``["solid_1", "solid_2", ...]``."""
    names = sorted(
        {m for m in mesh.GetMaterials() if m == SOLID or m.startswith(SOLID + "_")},
        key=lambda s: (len(s), s),
    )
    return names


def check_mesh(mesh: ngsolve.Mesh, where: str = "mesh") -> None:
    """Raise :class:`ConfigError` unless the mesh follows the naming convention of this module."""
    if mesh.dim not in (2, 3):
        raise ConfigError(f"ale_fsi needs a 2-D or 3-D mesh, got dimension {mesh.dim}", where)
    materials = set(mesh.GetMaterials())
    solids = solid_regions(mesh)
    if FLUID not in materials:
        raise ConfigError(f"no region named 'fluid' (regions: {sorted(materials)})", where)
    if not solids:
        raise ConfigError(
            f"no region named 'solid' or 'solid_<k>' (regions: {sorted(materials)})", where
        )
    if SOLID in solids and len(solids) > 1:
        raise ConfigError("mix of region 'solid' and 'solid_<k>' regions", where)
    if len(solids) > 1:
        want = [f"{SOLID}_{k}" for k in range(1, len(solids) + 1)]
        if solids != want:
            raise ConfigError(f"solid subdomains must be numbered 1..n, got {solids}", where)
    other = materials - {FLUID, *solids}
    if other:
        raise ConfigError(f"unknown region name(s) {sorted(other)}; use fluid, solid[_k]", where)
    bnds = set(mesh.GetBoundaries()) - {""}
    unknown = bnds - set(BOUNDARY_NAMES)
    if unknown:
        raise ConfigError(
            f"unknown boundary name(s) {sorted(unknown)}; valid: {', '.join(BOUNDARY_NAMES)}", where
        )
    missing = [b for b in REQUIRED_BOUNDARIES if b not in bnds]
    if missing:
        raise ConfigError(f"missing boundary name(s) {missing}", where)
    if "outflow" not in bnds:
        raise ConfigError("missing boundary 'outflow'", where)


# -- user meshes --------------------------------------------------------------------------------
_TRIANGLES = ("triangle", "triangle6", "triangle7")
_LINES = ("line", "line3")


def read_mesh(path: str | Path) -> ngsolve.Mesh:
    """Read a 2-D mesh with named regions and boundaries (gmsh ``.msh`` or any meshio format).

    Names come from meshio's ``cell_sets`` (gmsh physical groups).  Triangles named ``fluid``
    and ``solid[_k]`` make the regions, line elements named after :data:`BOUNDARY_NAMES` the
    boundaries.  Quadratic elements are read with straight sides (their corner nodes).
    """
    points, regions, boundaries = _read_named_cells(Path(path))
    return mesh_from_arrays(points, regions, boundaries, str(path))


def read_mesh_names(path: str | Path) -> list[str]:
    """Names of the regions and boundaries in a mesh file (meshio only, no NGSolve)."""
    _, regions, boundaries = _read_named_cells(Path(path))
    return [*regions, *boundaries]


def read_with_meshio(path: Path) -> Any:
    """``meshio.read(path)``, every failure a one-line ConfigError naming the file (2-D and 3-D
    mesh files alike: :func:`fbia.core.data_files.read_meshio`)."""
    return read_meshio(path, "mesh")


def _read_named_cells(
    path: Path,
) -> tuple[NDArray[np.float64], dict[str, NDArray[np.int64]], dict[str, NDArray[np.int64]]]:
    where = str(path)
    data = read_with_meshio(path)
    points = np.asarray(data.points, dtype=float)
    if points.shape[1] == 3:
        if np.any(np.abs(points[:, 2]) > 1e-12 * max(1.0, float(np.abs(points).max()))):
            raise ConfigError("the mesh is not planar (z != 0)", where)
        points = points[:, :2]
    sets = {name: s for name, s in data.cell_sets.items() if not name.startswith("gmsh:")}
    if not sets and "gmsh:physical" in data.cell_data and data.field_data:
        # gmsh files: physical names in field_data {name: [tag, dim]}, tags per cell
        dims = {"triangle": 2, "triangle6": 2, "triangle7": 2, "line": 1, "line3": 1}
        for name, (tag, dim) in ((n, (int(v[0]), int(v[1]))) for n, v in data.field_data.items()):
            sets[name] = [
                np.flatnonzero(np.asarray(tags) == tag) if dims.get(block.type) == dim else None
                for block, tags in zip(data.cells, data.cell_data["gmsh:physical"], strict=True)
            ]
    if not sets:
        raise ConfigError("the mesh has no named cell sets (gmsh physical groups)", where)
    regions: dict[str, NDArray[np.int64]] = {}
    boundaries: dict[str, NDArray[np.int64]] = {}
    for name, per_block in sets.items():
        for block, idx in zip(data.cells, per_block, strict=True):
            if idx is None or len(idx) == 0:
                continue
            conn = np.asarray(block.data)[np.asarray(idx, dtype=np.int64)]
            if block.type in _TRIANGLES:
                regions.setdefault(name, np.empty((0, 3), np.int64))
                regions[name] = np.vstack([regions[name], conn[:, :3]])
            elif block.type in _LINES:
                boundaries.setdefault(name, np.empty((0, 2), np.int64))
                boundaries[name] = np.vstack([boundaries[name], conn[:, :2]])
            elif block.type != "vertex":
                raise ConfigError(f"unsupported cell type {block.type!r} in set {name!r}", where)
    return points, regions, boundaries


def mesh_from_arrays(
    points: ArrayLike,
    regions: Mapping[str, ArrayLike],
    boundaries: Mapping[str, ArrayLike],
    where: str = "mesh",
    check: bool = True,
) -> ngsolve.Mesh:
    """An NGSolve mesh from vertex coordinates and named triangle/segment connectivities.

    With ``check`` (default) the names must follow this module's convention
    (:func:`check_mesh`); ``check=False`` builds any named mesh, e.g. a solid region alone.
    """
    import netgen.meshing as nm
    import ngsolve

    pts = np.asarray(points, dtype=float)
    ngmesh = nm.Mesh(dim=2)
    ngmesh.AddPoints(np.ascontiguousarray(pts))
    for name, tris in regions.items():
        t = np.array(tris, dtype=np.int32)
        a = pts[t[:, 1]] - pts[t[:, 0]]
        b = pts[t[:, 2]] - pts[t[:, 0]]
        cw = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0
        t[cw] = t[cw][:, [0, 2, 1]]  # netgen wants counter-clockwise triangles
        idx = ngmesh.AddRegion(name, dim=2)
        ngmesh.AddElements(dim=2, index=idx, data=np.ascontiguousarray(t), base=0)
    for name, segs in boundaries.items():
        idx = ngmesh.AddRegion(name, dim=1)
        s = np.ascontiguousarray(np.asarray(segs, dtype=np.int32))
        ngmesh.AddElements(dim=1, index=idx, data=s, base=0)
    mesh = ngsolve.Mesh(ngmesh)
    if check:
        check_mesh(mesh, where)
    return mesh


def mesh_arrays(
    mesh: ngsolve.Mesh,
) -> tuple[NDArray[np.float64], dict[str, NDArray[np.int64]], dict[str, NDArray[np.int64]]]:
    """Vertex coordinates and named triangle/segment connectivities (0-based) of a mesh."""
    ngmesh = mesh.ngmesh
    pts = np.array(ngmesh.Coordinates(), dtype=float, copy=True)[:, :2]
    e2 = ngmesh.Elements2D().NumPy()
    e1 = ngmesh.Elements1D().NumPy()
    names2 = ngmesh.GetRegionNames(dim=2)
    names1 = ngmesh.GetRegionNames(dim=1)
    regions: dict[str, NDArray[np.int64]] = {}
    for i, name in enumerate(names2, start=1):
        sel = e2["index"] == i
        if np.any(sel):
            conn = e2["nodes"][sel][:, :3].astype(np.int64) - 1
            regions[name] = np.vstack([regions[name], conn]) if name in regions else conn
    boundaries: dict[str, NDArray[np.int64]] = {}
    for i, name in enumerate(names1, start=1):
        sel = e1["index"] == i
        if np.any(sel) and name:
            conn = e1["nodes"][sel][:, :2].astype(np.int64) - 1
            boundaries[name] = np.vstack([boundaries[name], conn]) if name in boundaries else conn
    return pts, regions, boundaries


def write_mesh(mesh: ngsolve.Mesh, path: str | Path) -> Path:
    """Write a named 2-D mesh as gmsh 2.2 (physical groups = region/boundary names)."""
    pts, regions, boundaries = mesh_arrays(mesh)
    groups = [("line", boundaries, 1), ("triangle", regions, 2)]
    return write_named_gmsh(path, np.c_[pts, np.zeros(len(pts))], groups)


def write_named_gmsh(
    path: str | Path,
    points: NDArray[np.float64],
    groups: Sequence[tuple[str, dict[str, NDArray[np.int64]], int]],
) -> Path:
    """Write cells grouped by name as gmsh 2.2, one physical group per name.

    ``groups``: (meshio cell type, {name: connectivity}, dimension of the cells), boundaries
    first; ``points`` with three coordinates.  Used for 2-D and 3-D meshes alike.
    """
    import meshio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cells, phys, field_data = [], [], {}
    tag = 1
    for kind, named, dim in groups:
        for name, conn in named.items():
            cells.append((kind, conn))
            phys.append(np.full(len(conn), tag, dtype=np.int32))
            field_data[name] = np.array([tag, dim])
            tag += 1
    out = meshio.Mesh(
        points,
        cells,
        cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
        field_data=field_data,
    )
    meshio.write(path, out, file_format="gmsh22", binary=False)
    return path


def interface_chains(mesh: Any, ngs: Any) -> list[list[tuple[int, int]]]:
    """The interface as chains of ``(boundary element, start vertex)``, solid on the right."""
    solid_names = set(solid_regions(mesh))
    pts = np.array([v.point for v in mesh.vertices])
    edges: dict[tuple[int, int], tuple[int, int]] = {}  # directed (a, b) -> (element, a)
    solid_tris: dict[frozenset[int], int] = {}
    for el in mesh.Elements(ngs.VOL):
        if el.mat in solid_names:
            vs = [v.nr for v in el.vertices]
            for i in range(3):
                solid_tris[frozenset((vs[i], vs[(i + 1) % 3]))] = vs[(i + 2) % 3]
    for nr, el in enumerate(mesh.Elements(ngs.BND)):
        if el.mat != "interface":
            continue
        a, b = (v.nr for v in el.vertices)
        opp = solid_tris.get(frozenset((a, b)))
        if opp is None:
            raise ForwardModelError("an interface edge touches no solid element", "bad_mesh")
        t, c = pts[b] - pts[a], pts[opp] - pts[a]
        solid_left = t[0] * c[1] - t[1] * c[0] > 0
        start, stop = (b, a) if solid_left else (a, b)  # the solid must lie on the right
        if (start, stop) in edges or any(s == start for s, _ in edges):
            raise ForwardModelError("interface edges branch at a vertex", "bad_mesh")
        edges[(start, stop)] = (nr, start)
    if not edges:
        raise ForwardModelError("mesh has no interface edges", "bad_mesh")
    succ = {s: (t, edges[(s, t)]) for s, t in edges}
    starts = set(succ) - {t for t, _ in succ.values()}
    chains: list[list[tuple[int, int]]] = []
    seen: set[int] = set()
    for first in sorted(starts, key=lambda i: (pts[i][0], pts[i][1])):
        chain, v = [], first
        while v in succ:
            v, item = succ[v]
            chain.append(item)
        chains.append(chain)
        seen.update(e for e, _ in chain)
    for first in sorted(succ):  # closed loops
        if succ[first][1][0] in seen:
            continue
        chain, v = [], first
        while True:
            v, item = succ[v]
            chain.append(item)
            seen.add(item[0])
            if v == first:
                break
        chains.append(chain)
    return chains


def interface_triangles(mesh: Any, ngs: Any) -> NDArray[np.int64]:
    """The 3-D interface's triangles (vertex numbers), right-hand normal out of the solid."""
    solid_names = set(solid_regions(mesh))
    pts = np.array([v.point for v in mesh.vertices])
    opposite: dict[frozenset[int], int] = {}
    for el in mesh.Elements(ngs.VOL):
        if el.mat in solid_names:
            vs = [v.nr for v in el.vertices]
            for i in range(4):
                opposite[frozenset(vs[:i] + vs[i + 1 :])] = vs[i]
    tris = []
    for el in mesh.Elements(ngs.BND):
        if el.mat != "interface":
            continue
        a, b, c = (v.nr for v in el.vertices)
        opp = opposite.get(frozenset((a, b, c)))
        if opp is None:
            raise ForwardModelError("an interface face touches no solid element", "bad_mesh")
        normal = np.cross(pts[b] - pts[a], pts[c] - pts[a])
        tris.append((a, b, c) if np.dot(normal, pts[opp] - pts[a]) < 0 else (a, c, b))
    if not tris:
        raise ForwardModelError("mesh has no interface faces", "bad_mesh")
    return np.array(tris, dtype=np.int64)
