"""Admissibility of an ALE FSI state: det F of the ALE map and of the solid, and the shape
quality of the deformed fluid elements (what ends a run as :class:`fbia.ForwardModelError`)."""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.flow_cell import FLUID


class CheckedState(Protocol):
    """What the checks read (an :class:`~fbia.plugins.ale_fsi.forms.AleFsiProblem`)."""

    ngs: Any
    mesh: Any
    gfu: Any
    displacement: Any
    settings: Any

    def min_det_f(self) -> tuple[float, float]: ...


class StateChecks:
    """The checks of one :class:`~fbia.plugins.ale_fsi.forms.AleFsiProblem`'s state."""

    def __init__(self, problem: CheckedState) -> None:
        self.problem = problem
        self._tri_cache: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None

    def min_fluid_quality(self) -> float:
        """Smallest shape quality of the deformed fluid elements: 4 sqrt(3) A / sum(l^2) of a
        triangle, 12 (3 V)^(2/3) / sum(l^2) of a tetrahedron (1: equilateral, <= 0: inverted)."""
        tris, pts = self._fluid_triangles()
        u = self._vertex_displacement()
        x = pts + u
        corners = [x[tris[:, i]] for i in range(tris.shape[1])]
        edges = [
            corners[j] - corners[i] for i in range(len(corners)) for j in range(i + 1, len(corners))
        ]
        l2 = sum((e**2).sum(1) for e in edges)
        if tris.shape[1] == 3:
            ab, ac = edges[0], edges[1]
            area = 0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
            return float(np.min(4.0 * math.sqrt(3.0) * area / l2))
        vol = np.einsum("ij,ij->i", edges[0], np.cross(edges[1], edges[2])) / 6.0
        return float(np.min(12.0 * np.sign(vol) * np.abs(3.0 * vol) ** (2.0 / 3.0) / l2))

    def _fluid_triangles(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        if self._tri_cache is None:
            ngs = self.problem.ngs
            tris = np.array(
                [
                    [v.nr for v in el.vertices]
                    for el in self.problem.mesh.Elements(ngs.VOL)
                    if el.mat == FLUID
                ]
            )
            pts = np.array([v.point for v in self.problem.mesh.vertices])
            # orient positively (counter-clockwise) in the reference configuration
            a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
            if tris.shape[1] == 3:
                cw = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0] < 0
            else:
                cw = np.einsum("ij,ij->i", b - a, np.cross(c - a, pts[tris[:, 3]] - a)) < 0
            tris[cw] = tris[cw][:, [0, 2, 1] + list(range(3, tris.shape[1]))]
            self._tri_cache = (tris, pts)
        return self._tri_cache

    def _vertex_displacement(self) -> NDArray[np.float64]:
        """Displacement at the mesh vertices (the first nv dofs of each P2 component)."""
        nv = self.problem.mesh.nv
        comps = self.problem.displacement.components
        return np.column_stack([c.vec.FV().NumPy()[:nv] for c in comps])

    def check(self, where: str) -> dict[str, float]:
        """Raise :class:`ForwardModelError` unless the current state is admissible."""
        s = self.problem.settings
        x = self.problem.gfu.vec.FV().NumPy()
        if not np.all(np.isfinite(x)):
            raise ForwardModelError(f"{where}: the solution contains NaN", "nan")
        det_fluid, det_solid = self.problem.min_det_f()
        if det_fluid < s.min_det_f:
            raise ForwardModelError(
                f"{where}: ALE map inverted or degenerate "
                f"(min det F = {det_fluid:.3g} in the fluid)",
                "ale_jacobian",
            )
        if det_solid < s.min_det_f:
            raise ForwardModelError(
                f"{where}: solid deformation degenerate (min det F = {det_solid:.3g})",
                "solid_jacobian",
            )
        quality = self.min_fluid_quality()
        if quality < s.min_quality:
            raise ForwardModelError(
                f"{where}: fluid element quality {quality:.3g} below {s.min_quality}",
                "element_quality",
            )
        return {"min_det_f_fluid": det_fluid, "min_det_f_solid": det_solid, "min_quality": quality}
