"""Geometry of the growth model: Paper A's finger channel and the interface at the vertices.

The growth example of Paper A (Figs. 19-21, Table 6): a channel 0.6 x 0.3 mm (quasi-2-D,
0.01 mm thick) with a biofilm finger 0.04 mm wide and 0.1 mm high with a semicircular tip on
its floor.  The paper does not give the finger's position; :func:`finger_channel` puts its
axis at ``x0 = 0.2 mm``, a third of the length: 0.18 mm of channel upstream (at Re ~ 0.01 the
parabolic inflow profile is developed at once) and 0.38 mm downstream for the wake.

The interface helpers work on the vertices of an ``ale_fsi`` mesh (named per
:mod:`fbia.plugins.fem.flow_cell`): the ordered vertex chains of the interface (solid on
the right, i.e. from the upstream foot to the downstream foot), unit normals out of the
biofilm, lumped nodal lengths and traction densities from ``ale_fsi``'s consistent nodal
forces, all in the reference or a deformed configuration; :func:`interface_state` gives them
all for an ``AleFsiSolver`` state, ready for
:func:`~fbia.plugins.growth.growth_law.growth_displacement`.

>>> p = finger_outline(n_tip=4)
>>> print(p[0], p[-1], p[3])
[0.18 0.  ] [0.22 0.  ] [0.2 0.1]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.errors import ConfigError
from ..fem.flow_cell import build_flow_cell, interface_chains

if TYPE_CHECKING:
    import ngsolve

#: Paper A growth example: channel length and height (mm).
CHANNEL_LENGTH = 0.6
CHANNEL_HEIGHT = 0.3


def finger_outline(
    x0: float = 0.2, width: float = 0.04, height: float = 0.1, n_tip: int = 12
) -> NDArray[np.float64]:
    """Outline (mm) of a finger with a semicircular tip on the floor ``y = 0``.

    From the upstream foot ``(x0 - width/2, 0)`` up the straight side, over the tip (``n_tip``
    equal chords of the semicircle of radius ``width/2`` centred at ``(x0, height - width/2)``)
    and down to the downstream foot: the solid lies on the right of the walking direction, as
    :func:`~fbia.plugins.fem.flow_cell.build_flow_cell` expects.  The polygon is mirror
    symmetric about ``x = x0`` for every ``n_tip``.
    """
    r = 0.5 * width
    if not (width > 0 and height > r):
        raise ConfigError(
            f"a finger needs width > 0 and height > width/2, got {width} x {height} mm",
            "finger_outline",
        )
    if n_tip < 2:
        raise ConfigError(f"n_tip must be at least 2, got {n_tip}", "finger_outline")
    # the upstream half (foot to apex), mirrored exactly onto the downstream half
    angle = np.pi * (1.0 - np.arange(n_tip // 2 + 1) / n_tip)  # pi .. pi/2 (or just above)
    half = np.vstack([[[-r, 0.0]], np.c_[r * np.cos(angle), height - r + r * np.sin(angle)]])
    if n_tip % 2 == 0:
        half[-1] = (0.0, height)  # the apex
        right = half[-2::-1] * (-1.0, 1.0)
    else:
        right = half[::-1] * (-1.0, 1.0)
    return np.vstack([half, right]) + (x0, 0.0)


def finger_channel(
    mesh_size: float,
    interface_mesh_size: float,
    x0: float = 0.2,
    n_tip: int = 12,
    grading: float = 0.3,
) -> ngsolve.Mesh:
    """Paper A's growth example: channel 0.6 x 0.3 mm with a finger 0.04 x 0.1 mm at ``x0``.

    Straight elements (``smooth=False, curve_order=1``): the interface is the polygon of
    :func:`finger_outline`, so that growth moves vertices, not curved edges.
    """
    return build_flow_cell(
        length=CHANNEL_LENGTH,
        height=CHANNEL_HEIGHT,
        outline=finger_outline(x0=x0, n_tip=n_tip),
        smooth=False,
        mesh_size=mesh_size,
        interface_mesh_size=interface_mesh_size,
        grading=grading,
        curve_order=1,
    )


def vertex_coordinates(mesh: Any) -> NDArray[np.float64]:
    """(nv, 2) reference coordinates of the mesh vertices (mm)."""
    return np.array([v.point for v in mesh.vertices], dtype=float)


def interface_vertices(mesh: Any) -> list[NDArray[np.int64]]:
    """Vertex numbers of each interface chain, in order with the solid on the right.

    Open chains run from their upstream end (for a mound: upstream foot -> downstream foot);
    a closed chain does not repeat its first vertex.
    """
    return [verts for verts, _ in _interface_chains(mesh)]


def _interface_chains(mesh: Any) -> list[tuple[NDArray[np.int64], bool]]:
    """(vertex numbers, closed) of each interface chain."""
    import ngsolve

    chains = interface_chains(mesh, ngsolve)
    el_vertices = [tuple(v.nr for v in el.vertices) for el in mesh.Elements(ngsolve.BND)]
    out = []
    for chain in chains:
        verts = [start for _, start in chain]
        el, start = chain[-1]
        a, b = el_vertices[el]
        end = b if start == a else a
        closed = end == verts[0]
        if not closed:
            verts.append(end)
        out.append((np.array(verts, dtype=np.int64), closed))
    return out


def _chain_points(
    points: NDArray[np.float64], vertices: NDArray[np.int64], displacement: ArrayLike | None
) -> NDArray[np.float64]:
    x = points if displacement is None else points + np.asarray(displacement, dtype=float)
    return np.asarray(x[vertices], dtype=float)


def vertex_normals(
    points: ArrayLike,
    vertices: ArrayLike,
    displacement: ArrayLike | None = None,
    closed: bool = False,
    floor: float | None = 0.0,
) -> NDArray[np.float64]:
    """(n, 2) unit normals out of the biofilm at the vertices of one interface chain.

    ``points`` (nv, 2) are the reference vertex coordinates, ``displacement`` (nv, 2) an
    optional vertex displacement (the normals are then those of the deformed chain).  The
    chain runs with the solid on its right, so the outward normal of an edge is its direction
    turned left.  A vertex normal is the bisector of its two edges' unit normals (so that the
    normals of a mirror-symmetric polygon are mirror-symmetric however its edges are
    subdivided); the end vertices of an open chain take their edge's normal, projected onto the
    floor ``y = floor`` when they lie on it (the feet slide along the floor; ``floor=None``
    keeps them as they are).
    """
    x = _chain_points(np.asarray(points, dtype=float), np.asarray(vertices), displacement)
    e = (np.roll(x, -1, axis=0) - x) if closed else np.diff(x, axis=0)
    length = np.linalg.norm(e, axis=1)
    if np.any(length <= 0.0):
        raise ValueError("interface chain has an edge of zero length")
    en = np.c_[-e[:, 1], e[:, 0]] / length[:, None]  # edge normals, out of the biofilm
    if closed:
        n = en + np.roll(en, 1, axis=0)
    else:
        n = np.vstack([en[:1], en[:-1] + en[1:], en[-1:]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    if not closed and floor is not None:
        tol = 1e-9 * max(1.0, float(np.abs(x).max()))
        for i in (0, -1):
            if abs(x[i, 1] - floor) <= tol and n[i, 0] != 0.0:
                n[i] = (np.sign(n[i, 0]), 0.0)
    return np.asarray(n, dtype=float)


def nodal_lengths(
    points: ArrayLike,
    vertices: ArrayLike,
    displacement: ArrayLike | None = None,
    closed: bool = False,
) -> NDArray[np.float64]:
    """(n,) lumped interface length (mm) of each vertex of a chain: half its edges' lengths,
    i.e. the integral of the vertex's hat function along the (deformed) chain."""
    x = _chain_points(np.asarray(points, dtype=float), np.asarray(vertices), displacement)
    e = (np.roll(x, -1, axis=0) - x) if closed else np.diff(x, axis=0)
    half = 0.5 * np.linalg.norm(e, axis=1)
    if closed:
        return np.asarray(half + np.roll(half, 1), dtype=float)
    out = np.zeros(len(x))
    out[:-1] += half
    out[1:] += half
    return out


def vertex_displacement(solver: Any) -> NDArray[np.float64]:
    """(nv, 2) displacement of an ``AleFsiSolver`` state at the mesh vertices (mm)."""
    nv = solver.mesh.nv
    comps = solver.displacement.components
    return np.c_[comps[0].vec.FV().NumPy()[:nv], comps[1].vec.FV().NumPy()[:nv]]


def vertex_tractions(
    nodal_forces: ArrayLike, vertices: ArrayLike, lengths: ArrayLike, closed: bool = False
) -> NDArray[np.float64]:
    """(n, 2) traction density (Pa) of the fluid on the biofilm at the chain's vertices.

    ``nodal_forces`` (nv, 2) are ``ale_fsi``'s consistent nodal forces per unit depth (g/s^2,
    :meth:`~fbia.plugins.ale_fsi.postprocess.AleFsiPostprocess.interface_nodal_forces`): the
    traction integrated against the vertex hat function, so the density is the force over the
    lumped nodal length (:func:`nodal_lengths`, deformed).  The end vertices of an open chain
    (the feet) take their neighbour's traction: their hat function also covers half an edge of
    the floor (or of another boundary), whose pressure and shear would be lumped into them
    (on the finger channel that is a vertical 0.05 Pa at the upstream foot).
    """
    f = np.asarray(nodal_forces, dtype=float)[np.asarray(vertices)]
    t = f / np.asarray(lengths, dtype=float)[:, None]
    if not closed and len(t) > 2:
        t[0], t[-1] = t[1], t[-2]
    return np.asarray(t, dtype=float)


@dataclass(frozen=True)
class InterfaceState:
    """What eq. 9 needs of an ``ale_fsi`` state, at the vertices of one interface chain.

    ``vertices`` (n,) vertex numbers (solid on the right), ``normals`` (n, 2) unit normals out
    of the biofilm, ``lengths`` (n,) lumped nodal lengths (mm), ``tractions`` (n, 2) traction
    density of the fluid on the biofilm (Pa), ``displacement`` (n, 2) FSI displacement (mm);
    normals and lengths in the configuration the state was taken in.
    """

    vertices: NDArray[np.int64]
    normals: NDArray[np.float64]
    lengths: NDArray[np.float64]
    tractions: NDArray[np.float64]
    displacement: NDArray[np.float64]


def interface_state(solver: Any, deformed: bool = True) -> list[InterfaceState]:
    """Per interface chain, the :class:`InterfaceState` of an ``AleFsiSolver``'s current state.

    ``deformed``: normals and nodal lengths of the deformed interface (the tractions act
    there), else of the reference one.  The tractions are always the deformed state's.
    """
    mesh = solver.mesh
    pts = vertex_coordinates(mesh)
    u = vertex_displacement(solver)
    forces = solver.interface_nodal_forces()
    out = []
    for chain, closed in _interface_chains(mesh):
        disp = u if deformed else None
        lengths = nodal_lengths(pts, chain, disp, closed=closed)
        normals = vertex_normals(pts, chain, disp, closed=closed)
        tractions = vertex_tractions(forces, chain, lengths, closed=closed)
        out.append(InterfaceState(chain, normals, lengths, tractions, u[chain]))
    return out
