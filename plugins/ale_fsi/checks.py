"""Admissibility of an ALE FSI state: det F of the ALE map and of the solid, and the shape
quality of the deformed fluid elements (what ends a run as :class:`fbia.ForwardModelError`)."""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from .geometry import FLUID


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
        """Smallest shape quality 4 sqrt(3) A / sum(l^2) of the deformed fluid triangles."""
        tris, pts = self._fluid_triangles()
        u = self._vertex_displacement()
        x = pts + u
        a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
        ab, ac, bc = b - a, c - a, c - b
        area = 0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
        l2 = (ab**2).sum(1) + (ac**2).sum(1) + (bc**2).sum(1)
        return float(np.min(4.0 * math.sqrt(3.0) * area / l2))

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
            # orient counter-clockwise in the reference configuration
            a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
            cw = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0] < 0
            tris[cw] = tris[cw][:, [0, 2, 1]]
            self._tri_cache = (tris, pts)
        return self._tri_cache

    def _vertex_displacement(self) -> NDArray[np.float64]:
        """Displacement at the mesh vertices (the first nv dofs of each P2 component)."""
        nv = self.problem.mesh.nv
        comps = self.problem.displacement.components
        return np.c_[comps[0].vec.FV().NumPy()[:nv], comps[1].vec.FV().NumPy()[:nv]]

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
