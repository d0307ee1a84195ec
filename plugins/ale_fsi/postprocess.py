"""Post-processing of an ALE FSI state: interface curves or surfaces, fluxes, forces, probes.

:class:`AleFsiPostprocess` reads the state of an
:class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver` (no solving): the deformed interface as
ordered polylines (2-D) or a triangulated surface (3-D: the P1 vertices of the interface faces,
each triangle's right-hand normal into the fluid, as :meth:`fbia.Interface.surface` wants) --
what the measures compare --, volume fluxes through boundaries of the
deformed domain, the force of the fluid on a body from the residual of the fluid equations,
nodal interface forces and point displacements.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.interface import Interface
from ..fem.flow_cell import interface_chains, interface_triangles
from .forms import AleFsiProblem


class AleFsiPostprocess:
    """What an :class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver` state gives."""

    def __init__(self, solver: AleFsiProblem) -> None:
        self.solver = solver
        self._iface_cache: tuple[Any, Any, Any] | None = None
        self._surface_cache: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
        self._lattice_cache: tuple[Any, NDArray[np.bool_]] | None = None

    def interface(self, deformed: bool = True) -> Interface:
        """The interface as a :class:`fbia.Interface`: polylines (2-D) or a surface (3-D)."""
        if self.solver.dim == 2:
            return Interface.polylines(self.interface_curves(deformed))
        return Interface.surface(*self.interface_surface(deformed))

    def interface_surface(
        self, deformed: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Vertices (n, 3) and triangles (m, 3) of the 3-D interface, moved by the displacement
        at the vertices; each triangle's right-hand normal points into the fluid."""
        if self._surface_cache is None:
            tris = interface_triangles(self.solver.mesh, self.solver.ngs)
            verts, local = np.unique(tris, return_inverse=True)
            self._surface_cache = (verts, local.reshape(tris.shape))
        verts, tris = self._surface_cache
        mesh = self.solver.mesh
        x = np.array([mesh.vertices[int(i)].point for i in verts])
        if deformed:
            # the vertex dofs of an H1 field are its values at the vertices
            comps = self.solver.displacement.components
            x = x + np.column_stack([c.vec.FV().NumPy()[verts] for c in comps])
        return x, tris

    def _interface_lattice(self) -> tuple[Any, NDArray[np.bool_]]:
        """Lattice points on every boundary triangle, and which lie on the interface."""
        if self._lattice_cache is None:
            ngs = self.solver.ngs
            k = 4 * self.solver.settings.order
            lattice = [(i / k, j / k) for i in range(k + 1) for j in range(k + 1 - i)]
            rule = ngs.IntegrationRule(lattice, [0.0] * len(lattice))
            points = self.solver.mesh.MapToAllElements(rule, ngs.BND)
            names = [el.mat for el in self.solver.mesh.Elements(ngs.BND)]
            on = np.repeat(np.array(names) == "interface", len(lattice))
            self._lattice_cache = (points, on)
        return self._lattice_cache

    def interface_curves(self, deformed: bool = True) -> list[NDArray[np.float64]]:
        """Ordered interface polylines (solid on the right), with the edge midpoints.

        Each chain of ``interface`` edges is walked so that the solid lies on its right; open
        chains start at their upstream end.  The points are the ends and midpoints of the
        (possibly curved) reference edges, moved by the displacement evaluated on the edges.
        """
        ngs = self.solver.ngs
        if self._iface_cache is None:
            chains = interface_chains(self.solver.mesh, ngs)
            ir = ngs.IntegrationRule([(0.0,), (0.5,), (1.0,)], [0.0, 0.0, 0.0])
            pts = self.solver.mesh.MapToAllElements(ir, ngs.BND)
            xy = np.c_[np.asarray(ngs.x(pts)).ravel(), np.asarray(ngs.y(pts)).ravel()]
            xy = xy.reshape(-1, 3, 2)
            vert = np.array([v.point for v in self.solver.mesh.vertices])
            # per edge of a chain: is reference point 1 (not 0) the start vertex?
            oriented = [
                [
                    (
                        el,
                        bool(
                            np.linalg.norm(xy[el, 2] - vert[start])
                            < np.linalg.norm(xy[el, 0] - vert[start])
                        ),
                    )
                    for el, start in chain
                ]
                for chain in chains
            ]
            self._iface_cache = (oriented, pts, xy)
        oriented, pts, xy = self._iface_cache
        u = np.asarray(self.solver.displacement(pts)).reshape(-1, 3, 2) if deformed else 0.0 * xy
        out = []
        for chain_o in oriented:
            curve = []
            for el, flip in chain_o:
                order = [2, 1] if flip else [0, 1]  # start point and midpoint of the edge
                curve.append(xy[el, order] + u[el, order])
            el, flip = chain_o[-1]
            end = 0 if flip else 2
            curve.append((xy[el, end] + u[el, end])[None, :])
            out.append(np.vstack(curve))
        return out

    def flux(self, boundary: str) -> float:
        """Volume flux (mm^2/s) out of the fluid through a boundary of the deformed domain."""
        ngs = self.solver.ngs
        dim = self.solver.dim
        n = ngs.specialcf.normal(dim)
        F = ngs.Id(dim) + ngs.Grad(self.solver.displacement)
        # Nanson: n da = J F^-T N dA; for the boundary integrals use the reference normal.
        Jn = ngs.Det(F) * ngs.Inv(F).trans * n
        val = ngs.Integrate(
            ngs.InnerProduct(self.solver.velocity, Jn),
            self.solver.mesh,
            definedon=self.solver.mesh.Boundaries(boundary),
            order=2 * self.solver.settings.order + 2,
        )
        return float(val)

    def _fluid_residual(self) -> NDArray[np.float64]:
        """Residual of the fluid equations alone (velocity rows: consistent nodal forces)."""
        res = self.solver.gfu.vec.CreateVector()
        with self.solver.ngs.TaskManager():
            self.solver._fluid_form.Apply(self.solver.gfu.vec, res)
        r = self.solver.fes.Range(0)
        return np.array(res.FV().NumPy()[r.start : r.stop], copy=True)

    def _vertex_dofs(self, names: tuple[str, ...], boundary: bool) -> NDArray[np.int64]:
        """Vertex numbers of the named boundaries (or regions)."""
        ngs = self.solver.ngs
        kind = ngs.BND if boundary else ngs.VOL
        verts: set[int] = set()
        for el in self.solver.mesh.Elements(kind):
            if el.mat in names:
                verts.update(v.nr for v in el.vertices)
        return np.array(sorted(verts), dtype=np.int64)

    def forces(
        self, boundaries: tuple[str, ...] = ("obstacle", "interface")
    ) -> NDArray[np.float64]:
        """Force of the fluid on the body bounded by ``boundaries`` (g/s^2 per unit depth in
        2-D; g mm/s^2 in 3-D).

        Computed from the residual of the fluid equations (Babuska-Miller): the test function
        that is 1 (in x or y) on the body and 0 elsewhere on the boundary is the sum of the
        vertex hat functions of the body's nodes, so the force is minus the sum of the fluid
        residual over those rows -- far more accurate than integrating the traction.
        """
        res = self._fluid_residual()
        verts = self._vertex_dofs(boundaries, boundary=True)
        dim = self.solver.dim
        n = len(res) // dim  # VectorH1: all x dofs, then all y dofs, ...; vertex dofs first
        return -np.array([res[k * n + verts].sum() for k in range(dim)])

    def interface_nodal_forces(self) -> NDArray[np.float64]:
        """Consistent nodal force (g/s^2) of the fluid on every interface vertex; 0 elsewhere."""
        res = self._fluid_residual()
        dim = self.solver.dim
        n = len(res) // dim
        nv = self.solver.mesh.nv
        out = np.zeros((nv, dim))
        verts = self._vertex_dofs(("interface",), boundary=True)
        for k in range(dim):
            out[verts, k] = -res[k * n + verts]
        return out

    def point_displacement(self, point: tuple[float, ...]) -> NDArray[np.float64]:
        """Displacement (mm, one component per dimension) at a point of the reference mesh."""
        mp = self.solver.mesh(*(float(c) for c in point))
        return np.asarray(self.solver.displacement(mp), dtype=float).ravel()

    def max_interface_displacement(self) -> float:
        """Largest displacement magnitude (mm) on the interface.

        2-D: at the ends and midpoints of the interface edges.  3-D: on a lattice of
        ``4 order`` intervals per edge on every interface triangle: the vertices alone miss a
        maximum inside a triangle by O(h^2) -- 1 to 2 % of the dome's at interface size
        0.15 mm, more than the finite-element error of order 3 there.
        """
        if self.solver.dim == 3:
            points, on = self._interface_lattice()
            values = np.asarray(self.solver.displacement(points))[on]
            return float(np.linalg.norm(values, axis=1).max())
        ref = self.interface_curves(deformed=False)
        cur = self.interface_curves(deformed=True)
        return float(
            max(np.linalg.norm(c - r, axis=1).max() for c, r in zip(cur, ref, strict=True))
        )
