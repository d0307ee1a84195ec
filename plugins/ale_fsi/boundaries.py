"""Boundary conditions of ``ale_fsi`` read off the named boundaries of its mesh.

* :class:`InflowSegment` (2-D): the straight ``inflow`` boundary (end points, width, inward
  normal) and the parabolic inflow of a given volume rate on it;
* :class:`InflowFace` (3-D): the planar, axis-aligned rectangular ``inflow`` face and the
  rectangular-duct inflow on it -- the product of two parabolas
  ``36 Q/(a b) s(1-s) t(1-t)`` (volume rate ``Q`` in mm^3/s; the exact duct profile is a
  Fourier series, the product has the same flux and no-slip edges), or, on a cell with
  ``symmetry`` side walls (a ridge in plane strain), the 2-D profile ``6 q/a s(1-s)`` constant
  across the depth with ``q`` per unit depth (mm^2/s), so the 2-D inflow rate carries over;
* :func:`inflow_of`: the one of them that fits the mesh's dimension;
* :func:`mesh_dirichlet`: which boundaries hold each component of the ALE mesh displacement
  (eq. 2.24: fixed, or sliding along walls normal to one axis);
* :func:`normal_axis`: the axis a boundary is normal to, if it is planar and axis-aligned
  (``symmetry`` side walls: v and d normal to them vanish).

Boundary names per :mod:`fbia.plugins.fem.flow_cell`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.flow_cell import FLUID

__all__ = ["InflowFace", "InflowSegment", "inflow_of", "mesh_dirichlet", "normal_axis"]


@dataclass(frozen=True)
class InflowSegment:
    """The straight inflow boundary: ``start`` point, ``width`` (mm), unit ``tangent`` from
    ``start`` along it and unit ``normal`` into the fluid."""

    start: NDArray[np.float64]
    width: float
    tangent: NDArray[np.float64]
    normal: NDArray[np.float64]

    @classmethod
    def of(cls, mesh: Any) -> InflowSegment:
        """The ``inflow`` boundary of ``mesh``; a :class:`ForwardModelError` (``bad_mesh``) if
        there is none or it is not straight."""
        import ngsolve as ngs

        verts: set[int] = set()
        for el in mesh.Elements(ngs.BND):
            if el.mat == "inflow":
                verts.update(v.nr for v in el.vertices)
        if not verts:
            raise ForwardModelError("mesh has no inflow boundary", "bad_mesh")
        pts = np.array([mesh.vertices[i].point for i in sorted(verts)])
        centre = pts.mean(axis=0)
        # principal direction of the inflow segment
        _, _, vt = np.linalg.svd(pts - centre)
        t = vt[0]
        s = (pts - centre) @ t
        a, b = centre + s.min() * t, centre + s.max() * t
        width = float(np.linalg.norm(b - a))
        if np.max(np.abs((pts - centre) @ vt[1])) > 1e-6 * width:
            raise ForwardModelError("the inflow boundary is not a straight segment", "bad_mesh")
        n = np.array([-t[1], t[0]])
        # inward: towards the fluid's centroid
        fluid = mesh.Materials(FLUID)
        fluid_c = np.array(
            [ngs.Integrate(c, mesh, definedon=fluid) for c in (ngs.x, ngs.y)]
        ) / ngs.Integrate(1.0, mesh, definedon=fluid)
        if np.dot(fluid_c - centre, n) < 0:
            n = -n
        return cls(start=a, width=width, tangent=(b - a) / width, normal=n)

    def profile(self, rate: float) -> Any:
        """Parabolic inflow velocity of volume rate ``rate`` (mm^2/s): 6 rate/W s(1-s) n."""
        import ngsolve as ngs

        a, w, n, t = self.start, self.width, self.normal, self.tangent
        s = ((ngs.x - a[0]) * t[0] + (ngs.y - a[1]) * t[1]) / w
        prof = 6.0 * rate / w * s * (1.0 - s)
        return ngs.CoefficientFunction((prof * n[0], prof * n[1]))

    def mean_speed(self, rate: float) -> float:
        """Mean inflow speed (mm/s) at volume rate ``rate`` (mm^2/s)."""
        return rate / self.width


@dataclass(frozen=True)
class InflowFace:
    """The planar inflow face of a 3-D cell, normal to coordinate axis ``axis``: its
    bounding box ``lower``..``upper`` (mm), ``sign`` of the inward normal (+1/-1 along
    ``axis``) and ``depth_axis``, the axis normal to the ``symmetry`` walls (plane strain:
    profile constant along it), or -1 for a duct."""

    axis: int
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    sign: float
    depth_axis: int

    @classmethod
    def of(cls, mesh: Any) -> InflowFace:
        """The ``inflow`` face of a 3-D ``mesh``; :class:`ForwardModelError` (``bad_mesh``)
        unless it is a full axis-aligned rectangle."""
        import ngsolve as ngs

        axis = normal_axis(mesh, "inflow")
        if axis is None:
            raise ForwardModelError("the inflow boundary is not an axis-aligned plane", "bad_mesh")
        pts = _boundary_points(mesh, "inflow")
        lower, upper = pts.min(axis=0), pts.max(axis=0)
        side = np.delete(upper - lower, axis)
        area = float(ngs.Integrate(1.0, mesh, ngs.BND, definedon=mesh.Boundaries("inflow")))
        if abs(area - side.prod()) > 1e-6 * side.prod():
            raise ForwardModelError("the inflow face is not a full rectangle", "bad_mesh")
        fluid = mesh.Materials(FLUID)
        coord = (ngs.x, ngs.y, ngs.z)[axis]
        centre = ngs.Integrate(coord, mesh, definedon=fluid) / ngs.Integrate(
            1.0, mesh, definedon=fluid
        )
        sign = 1.0 if centre > lower[axis] else -1.0
        depth = -1
        if "symmetry" in set(mesh.GetBoundaries()):
            depth_axis = normal_axis(mesh, "symmetry")
            if depth_axis is None or depth_axis == axis:
                raise ForwardModelError(
                    "the symmetry walls must be planes normal to one axis, not the inflow's",
                    "bad_mesh",
                )
            depth = depth_axis
        return cls(axis=axis, lower=lower, upper=upper, sign=sign, depth_axis=depth)

    @property
    def width(self) -> float:
        """The length scale of the inflow: the smaller side (duct) or the height (ridge)."""
        sides = [self.upper[k] - self.lower[k] for k in self._profile_axes()]
        return float(min(sides))

    def _profile_axes(self) -> list[int]:
        return [k for k in range(3) if k not in (self.axis, self.depth_axis)]

    def profile(self, rate: float) -> Any:
        """Inflow velocity of volume rate ``rate`` (module docstring): mm^3/s for a duct,
        mm^2/s per unit depth between symmetry walls."""
        import ngsolve as ngs

        prof: Any = self.mean_speed(rate)
        for k in self._profile_axes():
            a = float(self.upper[k] - self.lower[k])
            s = ((ngs.x, ngs.y, ngs.z)[k] - float(self.lower[k])) / a
            prof = prof * 6.0 * s * (1.0 - s)  # mean of 6 s(1-s) over [0, 1] is 1
        comps: list[Any] = [0.0, 0.0, 0.0]
        comps[self.axis] = self.sign * prof
        return ngs.CoefficientFunction(tuple(comps))

    def carried(self, rate: float) -> Any:
        """:meth:`profile` carried along the flow through the cell: the profile where the
        point's cross-section coordinates lie within the inflow face's, zero beside it (in a
        duct that widens downstream the polynomial would turn negative, or positive again where
        both factors are), as a start for Newton's method (``AleFsiProblem.fill_with_inflow``).
        In a straight duct the same as :meth:`profile` (Poiseuille flow)."""
        import ngsolve as ngs

        inside: Any = 1.0
        for k in self._profile_axes():
            c = (ngs.x, ngs.y, ngs.z)[k]
            inside = (
                inside
                * ngs.IfPos(c - float(self.lower[k]), 1.0, 0.0)
                * ngs.IfPos(float(self.upper[k]) - c, 1.0, 0.0)
            )
        return inside * self.profile(rate)

    def mean_speed(self, rate: float) -> float:
        """Mean inflow speed (mm/s) at volume rate ``rate``."""
        area = 1.0
        for k in self._profile_axes():
            area *= float(self.upper[k] - self.lower[k])
        return rate / area


def inflow_of(mesh: Any) -> InflowSegment | InflowFace:
    """The inflow boundary of a 2-D (:class:`InflowSegment`) or 3-D (:class:`InflowFace`) mesh."""
    return InflowSegment.of(mesh) if mesh.dim == 2 else InflowFace.of(mesh)


def mesh_dirichlet(mesh: Any, slip: bool) -> tuple[str, ...]:
    """Dirichlet boundaries (``|``-joined) of each mesh-displacement component: eq. 2.24, with
    walls normal to one axis sliding along themselves if ``slip``, every other outer boundary
    fixed; ``symmetry`` walls hold the normal component only."""
    bnds = set(mesh.GetBoundaries())
    fixed = ["solid_fixed"] + [b for b in ("obstacle",) if b in bnds]
    fix = [list(fixed) for _ in range(mesh.dim)]
    for name in ("inflow", "outflow", "walls"):
        if name not in bnds:
            continue
        # only walls slide: a sliding inflow would distort the prescribed profile
        axis = normal_axis(mesh, name) if slip and name == "walls" else None
        for k in range(mesh.dim):
            if axis is None or k == axis:
                fix[k].append(name)
    if "symmetry" in bnds:
        fix[symmetry_axis(mesh)].append("symmetry")
    return tuple("|".join(f) for f in fix)


def symmetry_axis(mesh: Any) -> int:
    """The axis the ``symmetry`` walls are normal to; ForwardModelError if there is none."""
    axis = normal_axis(mesh, "symmetry")
    if axis is None:
        raise ForwardModelError("the symmetry walls are not normal to one axis", "bad_mesh")
    return axis


def _boundary_points(mesh: Any, name: str) -> NDArray[np.float64]:
    import ngsolve as ngs

    verts = {v.nr for el in mesh.Elements(ngs.BND) if el.mat == name for v in el.vertices}
    return np.array([mesh.vertices[i].point for i in sorted(verts)])


def normal_axis(mesh: Any, name: str) -> int | None:
    """The axis (0: x, 1: y, 2: z) that every element of boundary ``name`` is normal to (the
    coordinate constant on each element; a wall may have several parallel pieces), or None."""
    import ngsolve as ngs

    elems = [
        np.array([mesh.vertices[v.nr].point for v in el.vertices])
        for el in mesh.Elements(ngs.BND)
        if el.mat == name
    ]
    spread = np.array([e.max(axis=0) - e.min(axis=0) for e in elems])
    scale = np.abs(spread).max()
    for k in range(mesh.dim):
        if np.all(spread[:, k] <= 1e-10 * scale):
            return k
    return None
