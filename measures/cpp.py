"""Closest-point-projection distances of the simulated vertices (Paper B eq. 7).

>>> import numpy as np, fbia
>>> observed = fbia.Interface.polyline([[0.0, 0.0], [1.0, 0.0]])     # solid below y = 0
>>> obs = fbia.Observation(observed)
>>> simulated = fbia.Interface.polyline([[0.2, -0.1], [0.5, 0.05], [0.8, 0.3]])
>>> CppMeasure().residuals(simulated, obs).round(12).tolist()         # + : inside the biofilm
[0.1, -0.05, -0.3]
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, field_validator

from ..core.errors import ConfigError
from ..core.interface import Interface
from ..core.observation import Observation
from ..core.options import PluginOptions
from ..core.protocols import MeasureBase
from ._geometry import (
    ElementGeometry,
    IdentityCache,
    check_dimensions,
    closest_points,
    geometry_of,
)


class CppMeasure(MeasureBase):
    """Signed closest-point-projection distances ``d_cpp^i`` (Paper B eq. 7).

    For every vertex of the *simulated* interface the closest point on the *observed*
    interface is found exactly (on the segments in 2-D, on the triangles in 3-D, not only at
    their vertices).  The distance is positive when the vertex lies on the biofilm side of the
    observed interface (against its normal, which points from the solid into the fluid),
    negative towards the fluid.  Where the closest point is a vertex or edge shared by several
    observed elements the side is decided with the pseudo-normal (angle-weighted in 3-D), so
    it is right at corners too.  A vertex whose closest point lies on the open boundary of the
    observed interface and exactly in its tangent plane counts as on the fluid side.

    Residuals: one signed distance per simulated vertex (inside ``region``) [mm]; distance:
    their 2-norm [mm] (eq. 7).  With a ``region`` the number of residuals depends on how many
    vertices lie inside it, which a least-squares iterator needs to stay constant.
    """

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options

    class Options(PluginOptions):
        region: list[tuple[float, float]] | None = Field(
            None,
            description=(
                "only simulated vertices inside this box count: one [low, high] pair per "
                "axis, e.g. [[0.0, 2.0], [-1.0, 1.0]] [mm]; None: all vertices"
            ),
        )

        @field_validator("region")
        @classmethod
        def _check_region(
            cls, value: list[tuple[float, float]] | None
        ) -> list[tuple[float, float]] | None:
            if value is None:
                return value
            if len(value) not in (2, 3):
                raise ValueError(f"needs one [low, high] pair per axis (2 or 3), got {len(value)}")
            for axis, (lo, hi) in enumerate(value):
                if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                    raise ValueError(f"axis {axis}: need finite low < high, got [{lo}, {hi}]")
            return value

    options: Options
    #: one residual per simulated vertex: the count follows the simulated mesh (fbia.testing)
    mesh_dependent = True
    dims = (2, 3)

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: object) -> None:
        super().__init__(options, **kwargs)
        # search data (KD-tree, pseudo-normals) of each observed interface, built once
        self._observed: IdentityCache[ElementGeometry] = IdentityCache(maxsize=64)

    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray:
        """Signed closest-point distances of the simulated vertices [mm] (eq. 7)."""
        check_dimensions("cpp", simulated, observation)
        gamma = observation.interface
        if gamma is None:
            raise ConfigError(
                f"observation {observation.label()!r} has no observed interface "
                "(only measurement points); use the ray measure or add an interface",
                "cpp measure",
            )
        vertices = simulated.vertices
        region = self.options.region
        if region is not None:
            if len(region) != simulated.dim:
                raise ConfigError(
                    f"option 'region' has {len(region)} axes but the interfaces are "
                    f"{simulated.dim}-D",
                    "cpp measure",
                )
        vertices = vertices[self._inside(vertices)]
        if len(vertices) == 0:
            return np.zeros(0)
        return closest_points(geometry_of(gamma, self._observed), vertices).signed_distance

    def residuals_jvp(
        self, simulated: Interface, observation: Observation, dvertices: np.ndarray
    ) -> np.ndarray:
        """d residuals for a motion ``dvertices`` (n, dim) of the simulated vertices, exactly:
        the distance's gradient in a vertex is the unit vector from its closest point, signed
        as the residual (the envelope theorem: the closest point's own motion drops out); a
        vertex on the observed interface moves with minus its (pseudo-)normal."""
        self.residuals(simulated, observation)  # the checks, and the search data cached
        assert observation.interface is not None
        inside = self._inside(simulated.vertices)
        q = simulated.vertices[inside]
        cp = closest_points(geometry_of(observation.interface, self._observed), q)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = (q - cp.point) / cp.distance[:, None]
        sign = np.sign(cp.signed_distance)[:, None]
        grad = np.where(cp.distance[:, None] > 0.0, sign * unit, -cp.normal)
        return np.einsum("ij,ij->i", grad, np.asarray(dvertices, dtype=float)[inside])

    def distance(self, simulated: Interface, observation: Observation) -> float:
        """``D_cpp``: the 2-norm of the residuals [mm] (eq. 7)."""
        return float(np.linalg.norm(self.residuals(simulated, observation)))

    def _inside(self, vertices: np.ndarray) -> np.ndarray:
        region = self.options.region
        if region is None:
            return np.ones(len(vertices), dtype=bool)
        box = np.asarray(region, dtype=float)
        return np.all((vertices >= box[:, 0]) & (vertices <= box[:, 1]), axis=1)
