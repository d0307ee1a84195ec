"""Boundary conditions of ``ale_fsi`` read off the named boundaries of its mesh.

* :class:`InflowSegment`: the straight ``inflow`` boundary (end points, width, inward normal)
  and the parabolic inflow of a given volume rate on it;
* :func:`mesh_dirichlet`: which boundaries hold the ALE mesh displacement in x and in y
  (eq. 2.24: fixed, or sliding along straight walls).

Boundary names per :mod:`fbia.plugins.ale_fsi.geometry`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from .geometry import FLUID

__all__ = ["InflowSegment", "mesh_dirichlet", "straight_direction"]


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


def mesh_dirichlet(mesh: Any, slip: bool) -> tuple[str, str]:
    """Dirichlet boundaries (``|``-joined) of the x and y mesh displacement: eq. 2.24, with
    straight walls sliding along themselves if ``slip``, every other outer boundary fixed."""
    bnds = set(mesh.GetBoundaries())
    fixed = ["solid_fixed"] + [b for b in ("obstacle",) if b in bnds]
    fx, fy = list(fixed), list(fixed)
    for name in ("inflow", "outflow", "walls"):
        if name not in bnds:
            continue
        # only walls slide: a sliding inflow would distort the prescribed profile
        direction = straight_direction(mesh, name) if slip and name == "walls" else None
        if direction == "x":  # horizontal boundary: the mesh may slide in x
            fy.append(name)
        elif direction == "y":  # vertical boundary: the mesh may slide in y
            fx.append(name)
        else:
            fx.append(name)
            fy.append(name)
    return "|".join(fx), "|".join(fy)


def straight_direction(mesh: Any, name: str) -> str | None:
    """ "x" if every segment of boundary ``name`` is horizontal, "y" if vertical, else None."""
    import ngsolve as ngs

    segs = [
        np.array([mesh.vertices[v.nr].point for v in el.vertices])
        for el in mesh.Elements(ngs.BND)
        if el.mat == name
    ]
    d = np.array([s[1] - s[0] for s in segs])
    scale = np.abs(d).max()
    if np.all(np.abs(d[:, 1]) <= 1e-10 * scale):
        return "x"
    if np.all(np.abs(d[:, 0]) <= 1e-10 * scale):
        return "y"
    return None
