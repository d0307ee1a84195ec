"""3-D flow cells for the ALE FSI model: a dome on the floor of a duct, and a long ridge.

Both meshes follow the names of :mod:`fbia.plugins.fem.flow_cell` (regions ``fluid`` and
``solid``; boundaries ``inflow`` at ``x = 0``, ``outflow`` at ``x = length``, ``walls``,
``interface``, ``solid_fixed``, and for the ridge ``symmetry``), with the floor at ``y = 0``
and the depth along z:

* :func:`build_dome_cell` -- a rectangular duct ``length x height x width`` with a spherical
  cap (a dome) on its floor, centred on the mid-plane ``z = width/2``.  Netgen meshes the half
  ``z <= width/2`` and the mesh is mirrored, so that it -- and a steady state on it -- is
  mirror-symmetric to rounding, and a symmetry test is exact up to the solver's tolerance;
* :func:`build_ridge_cell` -- the 2-D flow cell of
  :func:`~fbia.plugins.fem.flow_cell.build_flow_cell` extruded over ``depth`` in ``layers``
  layers (every triangle a prism of three tetrahedra), with ``symmetry`` side walls: the
  plane-strain limit, where the 3-D model must give the 2-D model's answer.

The mirrored and extruded meshes carry no CAD geometry for netgen's ``mesh.Curve`` to curve
to.  The dome is curved instead by :func:`curve_dome`: an isoparametric map of order 2 (a P2
deformation of the mesh, ``mesh.SetDeformation``) that moves the edge midpoints of the
interface onto the sphere and those of the dome's foot onto its base circle; every other edge
stays straight.  On straight-sided elements the dome is a polyhedron whose volume and surface
are wrong by O(h^2) (the sagitta ``h^2 / (8 R)`` of every edge): its largest displacement then
wanders under refinement, 0.02805 / 0.02889 / 0.02685 / 0.02646 mm at interface sizes
0.2 / 0.15 / 0.1 / 0.075 mm, whereas the curved dome's converges monotonically (see
``benchmarks/bench_ale_fsi_3d.py``).  The ridge is extruded from a straight-sided 2-D mesh.

>>> from fbia.plugins.ale_fsi.geometry3d import build_dome_cell
>>> mesh = build_dome_cell(mesh_size=0.3, interface_mesh_size=0.12)   # doctest: +SKIP
>>> sorted(set(mesh.GetBoundaries()))                                 # doctest: +SKIP
['inflow', 'interface', 'outflow', 'solid_fixed', 'walls']
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ..fem.flow_cell import FLUID, SOLID, build_flow_cell, check_mesh, mesh_arrays
from ..fem.outlines import DEFAULT_OUTLINE

if TYPE_CHECKING:
    import ngsolve

__all__ = ["build_dome_cell", "build_ridge_cell", "curve_dome", "mesh_from_arrays_3d"]


def build_dome_cell(
    length: float = 2.0,
    height: float = 1.0,
    width: float = 1.0,
    dome_centre: float = 0.8,
    dome_radius: float = 0.4,
    dome_height: float = 0.4,
    mesh_size: float = 0.25,
    interface_mesh_size: float = 0.1,
    grading: float = 0.3,
    curve_order: int = 1,
) -> ngsolve.Mesh:
    """Mesh a duct with a dome-shaped biofilm (spherical cap) on its floor.

    Parameters
    ----------
    length, height, width
        Duct size in mm along x (flow), y (floor ``y = 0``) and z.
    dome_centre
        x of the dome's centre (mm); z is the mid-plane ``width/2``.
    dome_radius, dome_height
        Base radius ``a`` and height ``h`` of the cap (mm); the sphere's radius is
        ``(a^2 + h^2) / (2 h)``; ``h = a`` is a hemisphere.
    mesh_size, interface_mesh_size
        Maximum element size in the duct and on the dome (and inside it), mm.
    grading
        Netgen's mesh grading (0..1).
    curve_order
        1: straight-sided elements; 2 (or more): the dome curved by :func:`curve_dome`.
    """
    from netgen.occ import Box, Glue, OCCGeometry, Pnt, Sphere, X, Y, Z

    where = "ale_fsi geometry (dome_3d)"
    a, h, xc = dome_radius, dome_height, dome_centre
    if not (length > 0 and height > 0 and width > 0):
        raise ConfigError(f"duct size must be positive, got {length} x {height} x {width}", where)
    if not (0 < h < height and 0 < a < width / 2):
        raise ConfigError(
            f"the dome (radius {a}, height {h} mm) must fit inside the duct's height and width",
            where,
        )
    if not (a < xc < length - a):
        raise ConfigError("the dome must stay clear of the inflow and outflow", where)
    if not (mesh_size > 0 and interface_mesh_size > 0):
        raise ConfigError("mesh sizes must be positive", where)
    radius = (a * a + h * h) / (2.0 * h)
    half = Box(Pnt(0, 0, 0), Pnt(length, height, width / 2))
    half.faces.name = "walls"
    half.faces.Min(X).name = "inflow"
    half.faces.Max(X).name = "outflow"
    half.faces.Max(Z).name = "mirror"
    dome = Sphere(Pnt(xc, h - radius, width / 2), radius) * half
    dome.faces.name = "interface"
    dome.faces.Min(Y).name = "solid_fixed"
    dome.faces.Max(Z).name = "mirror"
    dome.faces.maxh = interface_mesh_size
    dome.mat(SOLID)
    fluid = half - dome
    fluid.mat(FLUID)
    try:
        ngmesh = OCCGeometry(Glue([fluid, dome])).GenerateMesh(maxh=mesh_size, grading=grading)
    except Exception as exc:  # netgen raises bare Exception/NgException subclasses
        raise ConfigError(f"netgen could not mesh the dome cell: {exc}", where) from None
    pts = np.array(ngmesh.Coordinates(), dtype=float, copy=True)
    e3, e2 = ngmesh.Elements3D().NumPy(), ngmesh.Elements2D().NumPy()
    regions = connectivity_by_region(e3, ngmesh.GetRegionNames(dim=3), 4)
    boundaries = connectivity_by_region(e2, ngmesh.GetRegionNames(dim=2), 3)
    boundaries.pop("mirror")
    locked = np.vstack([c for n, c in boundaries.items() if n != "outflow"])
    pts, regions[FLUID] = split_locked_tets(pts, regions[FLUID], locked)
    # mirror about z = width/2; the points on that plane are shared
    on = np.abs(pts[:, 2] - width / 2) <= 1e-9 * max(length, height, width)
    image = np.flatnonzero(on)
    remap = np.empty(len(pts), dtype=np.int64)
    remap[on] = image
    remap[~on] = len(pts) + np.arange(int((~on).sum()))
    mirrored = pts[~on] * np.array([1.0, 1.0, -1.0]) + np.array([0.0, 0.0, width])
    all_pts = np.vstack([pts, mirrored])
    regions = {n: np.vstack([c, remap[c]]) for n, c in regions.items()}
    boundaries = {n: np.vstack([c, remap[c]]) for n, c in boundaries.items()}
    mesh = mesh_from_arrays_3d(all_pts, regions, boundaries)
    check_mesh(mesh, where)
    if curve_order > 1:
        curve_dome(mesh, (xc, h - radius, width / 2), radius, a, curve_order)
    return mesh


def curve_dome(
    mesh: ngsolve.Mesh,
    centre: tuple[float, float, float],
    radius: float,
    base_radius: float,
    order: int = 2,
    min_ratio: float = 0.1,
) -> None:
    """Curve the ``interface`` of a dome mesh onto its sphere (isoparametric, ``order``).

    The mesh gets the deformation (``mesh.SetDeformation``) of order ``order`` whose
    canonical interpolant on the interface (vertex values, then edge moments: ``Set(...,
    dual=True)``, edge by edge, so that one face's projection cannot leak into the next) is
    the closest-point map onto the sphere -- and, on the foot ``y = 0``, onto the base circle
    in the floor, so that the floor stays flat; the other boundaries stay where they are, and
    inside the deformation is the harmonic extension of these boundary values (component by
    component), so that the elements next to the interface bend with it instead of taking
    all of the curvature in their first layer.  The interface vertices (on the sphere
    already) do not move.  All forms and integrals on the mesh then see the curved reference
    configuration.

    Curving the interface edges alone would turn a flat element next to the interface (one
    whose far vertex lies closer to the sphere than the sagitta ``h^2 / (8 R)`` of its edges)
    inside out -- it did on a 0.15 mm mesh; with the harmonic extension the curved Jacobian
    determinant stays above 0.6 times the straight one on the default meshes.  Should an
    element still fall below ``min_ratio`` times it at a sample point (vertices, edge
    midpoints, centroid, quadrature points), the deformation on all its dofs is halved,
    repeatedly, until none does.
    """
    import ngsolve as ngs

    cx, cy, cz = centre
    dx, dy, dz = ngs.x - cx, ngs.y - cy, ngs.z - cz
    r = ngs.sqrt(dx * dx + dy * dy + dz * dz)
    sphere = ngs.CF(
        (cx + radius * dx / r - ngs.x, cy + radius * dy / r - ngs.y, cz + radius * dz / r - ngs.z)
    )
    rb = ngs.sqrt(dx * dx + dz * dz)
    circle = ngs.CF((cx + base_radius * dx / rb - ngs.x, 0.0, cz + base_radius * dz / rb - ngs.z))
    foot = 1e-9 * radius
    target = ngs.IfPos(ngs.y - foot, sphere, circle)
    # each component: the interface values, extended harmonically into both regions
    scalar = ngs.H1(mesh, order=order, dirichlet=".*")
    u, w = scalar.TnT()
    laplace = ngs.BilinearForm(ngs.grad(u) * ngs.grad(w) * ngs.dx).Assemble()
    inverse = laplace.mat.Inverse(scalar.FreeDofs(), inverse="sparsecholesky")
    deformation = ngs.GridFunction(ngs.VectorH1(mesh, order=order))
    part = ngs.GridFunction(scalar)
    for k in range(3):
        part.Set(target[k], ngs.BND, definedon=mesh.Boundaries("interface"), dual=True)
        part.vec.data += inverse * (-laplace.mat * part.vec)
        deformation.components[k].vec.data = part.vec
    # sample points: the vertices, edge midpoints and centroid, and a quadrature rule's points
    corners = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)], dtype=float)
    mids = [(corners[i] + corners[j]) / 2 for i in range(4) for j in range(i + 1, 4)]
    inner = ngs.IntegrationRule(ngs.TET, 2 * order + 1)
    pts = [tuple(p) for p in [*corners, *mids, corners.mean(axis=0)]]
    pts += [tuple(ip.point) for ip in inner]
    rule = ngs.IntegrationRule(pts, [0.0] * len(pts))
    jac = ngs.Det(ngs.specialcf.JacobianMatrix(3))
    ne = mesh.ne
    straight = np.asarray(jac(mesh.MapToAllElements(rule, ngs.VOL)))[:, 0].reshape(ne, -1)
    values = deformation.vec.FV().NumPy()
    for _ in range(20):
        mesh.SetDeformation(deformation)
        curved = np.asarray(jac(mesh.MapToAllElements(rule, ngs.VOL)))[:, 0].reshape(ne, -1)
        bad = np.flatnonzero((curved / straight).min(axis=1) < min_ratio)
        if not len(bad):
            return
        mesh.UnsetDeformation()
        dofs = [d for e in bad for d in deformation.space.GetDofNrs(ngs.ElementId(ngs.VOL, int(e)))]
        values[dofs] *= 0.5
    raise ConfigError("could not curve the dome without inverting elements", "curve_dome")


def build_ridge_cell(
    depth: float = 0.2,
    layers: int = 1,
    length: float = 2.0,
    height: float = 1.0,
    outline: Any = DEFAULT_OUTLINE,
    smooth: bool = True,
    mesh_size: float = 0.1,
    interface_mesh_size: float = 0.03,
    solid_mesh_size: float | None = None,
) -> ngsolve.Mesh:
    """The 2-D flow cell (straight-sided, same arguments) extruded in z over ``depth`` (mm) in
    ``layers`` layers, with ``symmetry`` side walls at ``z = 0`` and ``z = depth``."""
    where = "ale_fsi geometry (ridge_3d)"
    if not (depth > 0 and layers >= 1):
        raise ConfigError(f"depth must be positive and layers >= 1, got {depth}, {layers}", where)
    flat = build_flow_cell(
        length=length,
        height=height,
        outline=outline,
        smooth=smooth,
        mesh_size=mesh_size,
        interface_mesh_size=interface_mesh_size,
        solid_mesh_size=solid_mesh_size,
        curve_order=1,
    )
    pts2, tris, segs = mesh_arrays(flat)
    nv = len(pts2)
    z = np.linspace(0.0, depth, layers + 1)
    pts = np.vstack([np.c_[pts2, np.full(nv, zk)] for zk in z])
    regions: dict[str, NDArray[np.int64]] = {}
    boundaries: dict[str, NDArray[np.int64]] = {}
    for name, t in tris.items():
        # a prism over the triangle a < b < c (sorted vertex numbers) splits into three
        # tetrahedra whose quad-face diagonals join the lower-numbered bottom vertex to the
        # higher-numbered top vertex -- the same on both prisms sharing a face: conforming
        a, b, c = np.sort(t, axis=1).T
        tets = []
        for k in range(layers):
            lo, up = k * nv, (k + 1) * nv
            tets += [
                np.c_[a + lo, b + lo, c + lo, c + up],
                np.c_[a + lo, b + lo, b + up, c + up],
                np.c_[a + lo, a + up, b + up, c + up],
            ]
        regions[name] = np.vstack(tets)
    for name, sg in segs.items():
        p, q = np.sort(sg, axis=1).T
        quads = [
            np.vstack([np.c_[p + lo, q + lo, q + lo + nv], np.c_[p + lo, q + lo + nv, p + lo + nv]])
            for lo in (k * nv for k in range(layers))
        ]
        boundaries[name] = np.vstack(quads)
    all_tris = np.vstack(list(tris.values()))
    boundaries["symmetry"] = np.vstack([all_tris, all_tris + layers * nv])
    mesh = mesh_from_arrays_3d(pts, regions, boundaries)
    check_mesh(mesh, where)
    return mesh


def mesh_from_arrays_3d(
    points: NDArray[np.float64],
    regions: Mapping[str, NDArray[np.int64]],
    boundaries: Mapping[str, NDArray[np.int64]],
) -> ngsolve.Mesh:
    """An NGSolve mesh from vertex coordinates (n, 3) and named tetrahedra / boundary
    triangles (0-based); the tetrahedra are oriented positively."""
    import netgen.meshing as nm
    import ngsolve

    ngmesh = nm.Mesh(dim=3)
    ngmesh.AddPoints(np.ascontiguousarray(points, dtype=float))
    for name, tets in regions.items():
        t = np.array(tets, dtype=np.int32)
        e = [points[t[:, i]] - points[t[:, 0]] for i in (1, 2, 3)]
        negative = np.einsum("ij,ij->i", e[0], np.cross(e[1], e[2])) < 0
        t[negative] = t[negative][:, [0, 2, 1, 3]]
        idx = ngmesh.AddRegion(name, dim=3)
        ngmesh.AddElements(dim=3, index=idx, data=np.ascontiguousarray(t), base=0)
    # every boundary triangle's normal (right-hand rule) points out of the fluid where it
    # touches the fluid, else out of the solid: NGSolve's boundary normal, used by fluxes
    away_from: dict[frozenset[int], int] = {}
    for _, tets in sorted(regions.items(), key=lambda item: item[0] == FLUID):
        for t in np.asarray(tets):
            for i in range(4):
                away_from[frozenset(np.delete(t, i).tolist())] = int(t[i])
    for name, tris in boundaries.items():
        t = np.array(tris, dtype=np.int32)
        opp = np.array([away_from[frozenset(f.tolist())] for f in t])
        normal = np.cross(points[t[:, 1]] - points[t[:, 0]], points[t[:, 2]] - points[t[:, 0]])
        inward = np.einsum("ij,ij->i", normal, points[opp] - points[t[:, 0]]) > 0
        t[inward] = t[inward][:, [0, 2, 1]]
        idx = ngmesh.AddRegion(name, dim=2)
        ngmesh.AddElements(dim=2, index=idx, data=np.ascontiguousarray(t), base=0)
    return ngsolve.Mesh(ngmesh)


def split_locked_tets(
    points: NDArray[np.float64], tets: NDArray[np.int64], faces: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Split every tetrahedron whose four vertices lie on ``faces`` (boundaries where the
    velocity is prescribed) at its centroid into four.

    The P2/P1 Taylor-Hood pair is not inf-sup stable on a mesh with such a fluid tetrahedron:
    its velocity has no free vertex value, and a pressure mode on its four vertices is
    spurious (Boffi 1997; seen here as a singular Jacobian at the
    foot of the dome).  The centroid is an inner vertex; the faces, hence the neighbours,
    stay as they are.
    """
    on = np.zeros(len(points), dtype=bool)
    on[faces.ravel()] = True
    bad = on[tets].all(axis=1)
    if not np.any(bad):
        return points, tets
    centre = len(points) + np.arange(int(bad.sum()))
    points = np.vstack([points, points[tets[bad]].mean(axis=1)])
    split = []
    for i in range(4):
        t = tets[bad].copy()
        t[:, i] = centre
        split.append(t)
    return points, np.vstack([tets[~bad], *split])


def connectivity_by_region(
    elements: Any, names: list[str], nodes: int
) -> dict[str, NDArray[np.int64]]:
    """0-based connectivities of netgen elements grouped by region name."""
    out: dict[str, NDArray[np.int64]] = {}
    for i, name in enumerate(names, start=1):
        sel = elements["index"] == i
        if np.any(sel) and name:
            conn = elements["nodes"][sel][:, :nodes].astype(np.int64) - 1
            out[name] = np.vstack([out[name], conn]) if name in out else conn
    return out
