"""Meshes of the ``cutfem_fpi`` model: the fixed background mesh of the channel, the fitted
mesh of the biofilm (curved along its outline), and a user's flow-cell mesh file split into
the two (read with the ``ale_fsi`` reader, the same named regions and boundaries)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError, ForwardModelError

__all__ = ["FlowCellFile", "biofilm_mesh", "channel_mesh", "read_flow_cell"]


def channel_mesh(
    length: float, height: float, mesh_size: float, origin: tuple[float, float] = (0.0, 0.0)
) -> Any:
    """Background mesh of the empty channel ``origin + [0, length] x [0, height]``:
    boundaries inflow, outflow, walls.  The grid is the same for every ``origin`` (netgen
    meshes a moved rectangle differently), so results do not depend on where a user's mesh
    puts its origin."""
    import ngsolve as ngs
    from netgen.occ import OCCGeometry, Rectangle, X, Y

    from ..fem.flow_cell import mesh_arrays, mesh_from_arrays

    face = Rectangle(length, height).Face()
    face.edges.Min(X).name = "inflow"
    face.edges.Max(X).name = "outflow"
    face.edges.Min(Y).name = "walls"
    face.edges.Max(Y).name = "walls"
    mesh = ngs.Mesh(OCCGeometry(face, dim=2).GenerateMesh(maxh=mesh_size))
    if origin == (0.0, 0.0):
        return mesh
    pts, regions, boundaries = mesh_arrays(mesh)
    return mesh_from_arrays(pts + np.asarray(origin), regions, boundaries, check=False)


def biofilm_mesh(
    outline: NDArray[np.float64], smooth: bool, mesh_size: float, curve_order: int = 2
) -> Any:
    """Fitted mesh of the biofilm alone (reference configuration): region ``solid``,
    boundaries ``interface`` (the outline) and ``solid_fixed`` (the floor).

    The outline runs from the upstream to the downstream foot on ``y = 0`` and is, with
    ``smooth``, the same cubic spline as :func:`fbia.plugins.fem.flow_cell.build_flow_cell`
    makes of it, so both models see the same biofilm.  ``curve_order`` 2 makes the element
    geometry follow the spline: on the default mound at h = 0.04 mm the reference interface
    is then 0.2 um off it, against 1.4 um with straight sides (``h^2 / (8 R)``).
    """
    import ngsolve as ngs
    from netgen.occ import Face, OCCGeometry, Pnt, Segment, SplineApproximation, Wire, Y

    p = np.asarray(outline, dtype=float)
    ccw = p[::-1]  # OCC wants the face boundary counter-clockwise
    if smooth:
        pts = [Pnt(float(x), float(y), 0.0) for x, y in ccw]
        edges = [SplineApproximation(pts, deg_min=3, deg_max=3, tol=1e-7)]
    else:
        edges = [Segment(Pnt(*ccw[i], 0.0), Pnt(*ccw[i + 1], 0.0)) for i in range(len(ccw) - 1)]
    base = Segment(Pnt(float(p[0, 0]), 0.0, 0.0), Pnt(float(p[-1, 0]), 0.0, 0.0))
    face = Face(Wire([*edges, base]))
    face.edges.name = "interface"
    face.edges.Min(Y).name = "solid_fixed"
    face.faces.name = "solid"
    try:
        mesh = ngs.Mesh(OCCGeometry(face, dim=2).GenerateMesh(maxh=mesh_size))
    except Exception as exc:  # netgen raises bare Exception/NgException subclasses
        raise ConfigError(
            f"netgen could not mesh the biofilm: {exc}", "cutfem_fpi geometry"
        ) from None
    if curve_order > 1:
        mesh.Curve(curve_order)
    return mesh


@dataclass(frozen=True)
class FlowCellFile:
    """What ``cutfem_fpi`` takes from a user's flow-cell mesh (:func:`read_flow_cell`)."""

    skeleton: Any  # NGSolve mesh of the solid: region solid, boundaries interface, solid_fixed
    origin: tuple[float, float]  # lower left corner of the channel [mm]
    length: float  # channel length [mm]
    height: float  # channel height [mm]
    outline: NDArray[np.float64]  # interface vertices, upstream foot first [mm]


def read_flow_cell(path: str | Path) -> FlowCellFile:
    """The biofilm and channel of a flow-cell mesh file, the same file ``ale_fsi`` reads.

    The file is read and its names checked by :func:`fbia.plugins.fem.flow_cell.read_mesh`
    (regions ``fluid``, ``solid`` or ``solid_1..n``; boundaries ``inflow``, ``outflow``,
    ``interface``, ``solid_fixed``, optional ``walls``); a file that breaks the convention
    raises its :class:`ConfigError`, which names the file.  Of the mesh, ``cutfem_fpi`` uses

    * the solid region(s), merged into one region ``solid``: the skeleton mesh in the
      reference configuration (straight-sided, as the file gives it), with its ``interface``
      edges (the biofilm outline seen from the fluid, from which the level set is built) and
      its clamped ``solid_fixed`` edges;
    * the bounding box: the channel, meshed by the fixed background grid.  The fluid region
      must therefore fill the box minus the biofilm, with ``inflow`` and ``outflow`` on its
      left and right sides, and the interface must be one curve from floor to floor (the
      level-set construction closes it along the floor), without a rigid ``obstacle``.
    """
    import ngsolve as ngs

    from ..fem.flow_cell import (
        interface_chains,
        mesh_arrays,
        mesh_from_arrays,
        read_mesh,
        solid_regions,
    )

    where = str(path)
    cell = read_mesh(path)
    pts, regions, boundaries = mesh_arrays(cell)
    if "obstacle" in boundaries:
        raise ConfigError("cutfem_fpi has no rigid obstacles; the mesh names an 'obstacle'", where)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo
    lo[np.abs(lo) < 1e-12 * size.max()] = 0.0  # a mesher's round-off at the origin
    area = sum(float(np.sum(_triangle_areas(pts, t))) for t in regions.values())
    if abs(area - size[0] * size[1]) > 1e-9 * size[0] * size[1]:
        raise ConfigError(
            f"the flow cell must fill its bounding box {lo.tolist()} - {hi.tolist()} (the "
            f"channel of cutfem_fpi's background grid); the mesh covers {area:.6g} of "
            f"{size[0] * size[1]:.6g} mm^2",
            where,
        )
    tol = 1e-9 * float(size.max())
    for name, side in (("inflow", lo[0]), ("outflow", hi[0])):
        if np.any(np.abs(pts[boundaries[name]][..., 0] - side) > tol):
            raise ConfigError(f"boundary {name!r} must lie on the side x = {side:g} mm", where)
    # the solid region(s) alone, renumbered
    tris = np.vstack([regions[name] for name in solid_regions(cell)])
    used, local = np.unique(tris, return_inverse=True)
    renumber = np.full(len(pts), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    edges, counts = np.unique(
        np.sort(np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1),
        axis=0,
        return_counts=True,
    )
    outer = {tuple(e) for e in edges[counts == 1]}
    named = {}
    for name in ("interface", "solid_fixed"):
        segs = boundaries[name]
        on = [tuple(sorted(e)) in outer for e in segs.tolist()]
        if not all(on):
            raise ConfigError(
                f"{on.count(False)} {name!r} edge(s) do not lie on the boundary of the solid", where
            )
        named[name] = renumber[segs]
    loose = outer - {tuple(sorted(e)) for name in named for e in boundaries[name].tolist()}
    if loose:
        raise ConfigError(
            f"{len(loose)} edge(s) of the solid's boundary are neither 'interface' nor "
            "'solid_fixed'",
            where,
        )
    skeleton = mesh_from_arrays(
        pts[used], {"solid": local.reshape(tris.shape)}, named, where, check=False
    )
    try:
        chains = interface_chains(skeleton, ngs)
    except ForwardModelError as exc:
        raise ConfigError(str(exc), where) from None
    bnd = list(skeleton.Elements(ngs.BND))
    chain_pts = [
        [
            *(start for _, start in chain),
            next(v.nr for v in bnd[chain[-1][0]].vertices if v.nr != chain[-1][1]),
        ]
        for chain in chains
    ]
    if len(chains) != 1 or chain_pts[0][0] == chain_pts[0][-1]:
        raise ConfigError(
            "cutfem_fpi needs one biofilm whose 'interface' is one open curve from the floor to "
            f"the floor; the mesh has {len(chains)} interface curve(s)"
            + (", closed" if len(chains) == 1 else ""),
            where,
        )
    return FlowCellFile(
        skeleton=skeleton,
        origin=(float(lo[0]), float(lo[1])),
        length=float(size[0]),
        height=float(size[1]),
        outline=pts[used][chain_pts[0]],
    )


def _triangle_areas(pts: NDArray[np.float64], tris: NDArray[np.int64]) -> NDArray[np.float64]:
    a = pts[tris[:, 1]] - pts[tris[:, 0]]
    b = pts[tris[:, 2]] - pts[tris[:, 0]]
    return 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
