"""The grown mesh: a growth displacement at the interface vertices, extended into the biofilm
and the fluid, applied as the new reference configuration (Paper A, "Surface growth" and the
multi-scale paragraph: "after the growth step an ALE relaxation of the mesh is necessary for the
domains on both sides of the interface").

:func:`grow_mesh` prescribes the displacement on the interface vertices, extends it by a
harmonic extension stiffened by the inverse element area (Jacobian-based stiffening, like
``ale_fsi``'s mesh motion, :meth:`~fbia.plugins.ale_fsi.forms.AleFsiProblem._build_motion`)
with the outer boundaries fixed -- the vertices on the straight floor ``y = 0`` (walls and
biofilm base) slide along it so that a foot of the biofilm can move -- moves the vertices and
builds a new mesh with the same regions and boundaries (straight elements).  A step that the
geometry cannot take is a :class:`fbia.ForwardModelError`, not a crash:

=================== ===========================================================================
reason              when
=================== ===========================================================================
``eroded_away``     the biofilm outline crosses itself while shrinking, its area falls to
                    ``min_area_fraction`` of the reference area, or the interface reaches the
                    floor away from its feet
``growth_blocked``  the interface reaches the top wall, the inflow or the outflow
``growth_inverted`` an element is inverted by the extension, or the outline crosses itself
                    while growing
``growth_quality``  an element's shape quality ``4 sqrt(3) A / sum(l^2)`` drops below
                    ``min_quality``
=================== ===========================================================================
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.errors import ForwardModelError
from ..fem.flow_cell import mesh_arrays, mesh_from_arrays, solid_regions
from .geometry import interface_vertices, vertex_normals

#: Outer boundaries held fixed by the extension (the interface is prescribed).
FIXED_BOUNDARIES = ("inflow", "outflow", "walls", "solid_fixed", "obstacle")


def triangle_quality(points: ArrayLike, triangles: ArrayLike) -> NDArray[np.float64]:
    """Shape quality ``4 sqrt(3) A / (l1^2 + l2^2 + l3^2)`` of triangles (1: equilateral);
    negative for a triangle whose orientation is clockwise."""
    x = np.asarray(points, dtype=float)
    t = np.asarray(triangles)
    a, b, c = x[t[:, 0]], x[t[:, 1]], x[t[:, 2]]
    l2 = ((b - a) ** 2).sum(1) + ((c - a) ** 2).sum(1) + ((c - b) ** 2).sum(1)
    return np.asarray(4.0 * math.sqrt(3.0) * _signed_areas(x, t) / l2, dtype=float)


def _signed_areas(x: NDArray[np.float64], t: NDArray[np.int64]) -> NDArray[np.float64]:
    ab, ac = x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]
    return np.asarray(0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]), dtype=float)


def mesh_quality(mesh: Any) -> float:
    """Smallest triangle quality of a mesh (all regions)."""
    pts, regions, _ = mesh_arrays(mesh)
    tris = np.vstack(list(regions.values()))
    return float(np.min(np.abs(triangle_quality(pts, tris))))


def solid_area(mesh: Any) -> float:
    """Area of the biofilm (all solid regions) in mm^2."""
    pts, regions, _ = mesh_arrays(mesh)
    solids = set(solid_regions(mesh))
    tris = np.vstack([t for name, t in regions.items() if name in solids])
    return float(np.abs(_signed_areas(pts, tris)).sum())


def _ccw(x: NDArray[np.float64], tris: NDArray[np.int64]) -> NDArray[np.int64]:
    """Triangles oriented counter-clockwise in configuration ``x``."""
    t = np.array(tris, dtype=np.int64)
    cw = triangle_quality(x, t) < 0
    t[cw] = t[cw][:, [0, 2, 1]]
    return t


def _outline_area(x: NDArray[np.float64], chain: NDArray[np.int64]) -> tuple[float, bool]:
    """Area enclosed by an interface chain closed by a straight base, and whether simple."""
    import shapely

    p = x[chain]
    ring = np.vstack([p, p[:1]])
    simple = bool(shapely.LineString(ring).is_simple)
    xx, yy = p[:, 0], p[:, 1]
    area = -0.5 * float(np.dot(xx, np.roll(yy, -1)) - np.dot(np.roll(xx, -1), yy))  # solid right
    return area, simple


class _Extension:
    """Harmonic extension with stiffening ``(A_max / A_K)^chi`` on P1, assembled once."""

    def __init__(self, mesh: Any, stiffening: float) -> None:
        import ngsolve as ngs

        self.mesh = mesh
        self.fes = ngs.H1(mesh, order=1)
        u, v = self.fes.TnT()
        vols = np.asarray(ngs.Integrate(1.0, mesh, element_wise=True))
        area = ngs.GridFunction(ngs.L2(mesh, order=0))
        area.vec.FV().NumPy()[:] = vols
        stiff = (float(vols.max()) / area) ** stiffening
        self.a = ngs.BilinearForm(self.fes, symmetric=True)
        self.a += stiff * ngs.grad(u) * ngs.grad(v) * ngs.dx
        self.a.Assemble()

    def solve(self, values: NDArray[np.float64], fixed: NDArray[np.bool_]) -> NDArray[np.float64]:
        """The extension of ``values`` given on the ``fixed`` vertices (P1: dof = vertex)."""
        import ngsolve as ngs

        free = ngs.BitArray(len(fixed))
        free.Clear()
        for i in np.flatnonzero(~fixed):
            free.Set(int(i))
        gf = ngs.GridFunction(self.fes)
        x = np.where(fixed, values, 0.0)
        gf.vec.FV().NumPy()[:] = x
        if np.any(~fixed) and np.any(x):
            rhs = gf.vec.CreateVector()
            rhs.data = -1.0 * (self.a.mat * gf.vec)
            inv = self.a.mat.Inverse(free, inverse="sparsecholesky")
            gf.vec.data += inv * rhs
        out = np.array(gf.vec.FV().NumPy(), dtype=float)
        out[fixed] = values[fixed]  # exactly as prescribed
        return out


def grow_mesh(
    mesh: Any,
    vertices: ArrayLike,
    displacement: ArrayLike,
    min_quality: float = 0.02,
    min_area_fraction: float = 0.05,
    reference_area: float | None = None,
    stiffening: float = 1.0,
) -> Any:
    """The mesh grown by ``displacement`` (n, 2, mm) at the interface ``vertices`` (n,).

    Parameters
    ----------
    mesh
        A straight-sided ``ale_fsi`` mesh (:mod:`fbia.plugins.fem.flow_cell`); a curved
        mesh is grown from its vertices and comes back straight.
    vertices, displacement
        Interface vertex numbers and their displacement (e.g. from
        :func:`~fbia.plugins.growth.growth_law.growth_displacement`); every interface vertex
        not listed stays where it is.  A vertex on the floor ``y = 0`` keeps ``y = 0`` (its
        vertical displacement is dropped: a foot slides along the floor).
    min_quality
        Smallest admissible triangle quality of the grown mesh.
    min_area_fraction, reference_area
        The biofilm is eroded away when its area falls to ``min_area_fraction *
        reference_area`` (default: the area before this step; pass the initial area in a
        sequence of steps).
    stiffening
        Exponent of the Jacobian-based stiffening of the extension.

    Returns a new mesh with the same named regions and boundaries; raises
    :class:`fbia.ForwardModelError` (reasons in the module docstring).
    """
    import ngsolve as ngs

    pts, regions, boundaries = mesh_arrays(mesh)
    nv = len(pts)
    if nv != mesh.nv:
        raise ValueError(f"mesh has {mesh.nv} vertices but {nv} points: not a P1 netgen mesh")
    verts = np.asarray(vertices, dtype=np.int64)
    d_in = np.asarray(displacement, dtype=float)
    if d_in.shape != (len(verts), 2):
        raise ValueError(f"displacement must have shape ({len(verts)}, 2), got {d_in.shape}")
    if not np.all(np.isfinite(d_in)):
        raise ForwardModelError("growth displacement is not finite", "nan")
    extent = float(np.ptp(pts, axis=0).max())
    tol = 1e-9 * extent
    y_floor = float(pts[:, 1].min())
    on_bnd = {name: np.unique(segs) for name, segs in boundaries.items()}
    iface = np.zeros(nv, dtype=bool)
    iface[on_bnd.get("interface", np.empty(0, np.int64))] = True
    fixed = np.zeros(nv, dtype=bool)
    for name in FIXED_BOUNDARIES:
        fixed[on_bnd.get(name, np.empty(0, np.int64))] = True
    fixed |= iface
    floor = fixed & (np.abs(pts[:, 1] - y_floor) <= tol)
    d = np.zeros((nv, 2))
    d[verts] = d_in
    d[floor, 1] = 0.0
    # x slides on the floor except at the feet (prescribed) and the channel corners (fixed)
    corner = np.zeros(nv, dtype=bool)
    for name in ("inflow", "outflow"):
        corner[on_bnd.get(name, np.empty(0, np.int64))] = True
    fixed_x = fixed & ~(floor & ~iface & ~corner)

    x_new = pts + d  # the interface as prescribed (the rest follows from the extension)
    _check_outline(mesh, pts, x_new, d, iface, floor, min_area_fraction, reference_area, tol)
    if np.any(d):
        ext = _Extension(mesh, stiffening)
        with ngs.TaskManager():
            d[:, 0] = ext.solve(d[:, 0], fixed_x)
            d[:, 1] = ext.solve(d[:, 1], fixed)
    x_new = pts + d
    tris_ref = np.vstack(list(regions.values()))
    q = triangle_quality(x_new, _ccw(pts, tris_ref))
    if np.any(q <= 0.0):
        raise ForwardModelError(
            f"growth step inverts {int(np.sum(q <= 0.0))} element(s) "
            f"(largest growth displacement {np.abs(d_in).max():.3g} mm)",
            "growth_inverted",
        )
    if q.min() < min_quality:
        raise ForwardModelError(
            f"growth step distorts elements: quality {q.min():.3g} below {min_quality}",
            "growth_quality",
        )
    return mesh_from_arrays(x_new, regions, boundaries, "grown mesh")


def _check_outline(
    mesh: Any,
    pts: NDArray[np.float64],
    x_new: NDArray[np.float64],
    d: NDArray[np.float64],
    iface: NDArray[np.bool_],
    floor: NDArray[np.bool_],
    min_area_fraction: float,
    reference_area: float | None,
    tol: float,
) -> None:
    """Raise unless the moved interface still bounds a biofilm inside the channel."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    moved = iface & np.any(d != 0.0, axis=1)
    xi = x_new[moved]
    area_old = area_new = 0.0
    crossing = False
    outward = 0.0  # the mean outward movement (growth > 0, erosion < 0)
    for chain in interface_vertices(mesh):
        a_old, _ = _outline_area(pts, chain)
        a_new, simple = _outline_area(x_new, chain)
        area_old += a_old
        area_new += a_new
        crossing |= not simple
        normals = vertex_normals(pts, chain, floor=None)  # only the sign of the sum counts
        outward += float(np.sum(d[chain] * normals))
    ref = area_old if reference_area is None else float(reference_area)
    # an interface pushed through the biofilm to the other walls is erosion, not growth
    eroding = outward < 0.0
    if np.any(xi[:, 1] >= hi[1] - tol) or np.any(xi[:, 0] <= lo[0] + tol):
        if eroding:
            raise ForwardModelError(
                "erosion pushes the interface through the biofilm to the walls", "eroded_away"
            )
        raise ForwardModelError("growth reaches the top wall or the inflow", "growth_blocked")
    if np.any(xi[:, 0] >= hi[0] - tol):
        if eroding:
            raise ForwardModelError(
                "erosion pushes the interface through the biofilm to the outflow", "eroded_away"
            )
        raise ForwardModelError("growth reaches the outflow", "growth_blocked")
    if np.any(x_new[moved & ~floor, 1] <= lo[1] + tol):
        raise ForwardModelError("erosion brings the interface down to the floor", "eroded_away")
    if crossing:
        if eroding:
            raise ForwardModelError("erosion makes the biofilm outline cross itself", "eroded_away")
        raise ForwardModelError("growth makes the biofilm outline cross itself", "growth_inverted")
    if area_new <= min_area_fraction * ref:
        raise ForwardModelError(
            f"biofilm eroded away: area {area_new:.3g} mm^2 of {ref:.3g} mm^2", "eroded_away"
        )
