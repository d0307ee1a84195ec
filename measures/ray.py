"""Distances along rays from measurement points (Paper A, "Surface distance measure"; Paper B
eq. 6).

At each measurement point on the observed interface a line is drawn along its search
direction (both ways) and intersected with the simulated interface; the signed length to the
intersection is the residual ``d_mp^i`` (Paper A eq. 19), the 2-norm of all of them the
distance ``D_mp`` (Paper B eq. 6).

>>> import numpy as np, fbia
>>> x = np.linspace(0.0, 1.0, 11)
>>> observed = fbia.Interface.polyline(np.c_[x, np.zeros_like(x)])      # solid below y = 0
>>> obs = fbia.Observation(observed, points=[[0.25, 0.0], [0.75, 0.0]])
>>> simulated = fbia.Interface.polyline(np.c_[x, 0.1 + 0.2 * x])       # grew upwards
>>> RayMeasure().residuals(simulated, obs).round(12).tolist()           # - : towards fluid
[-0.15, -0.25]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from ..core.errors import ConfigError, MeasureError
from ..core.interface import Interface
from ..core.observation import Observation
from ..core.options import PluginOptions
from ..core.protocols import MeasureBase
from ._geometry import (
    ElementGeometry,
    FloatArray,
    IdentityCache,
    biofilm_side_sign,
    check_dimensions,
    closest_points,
    geometry_of,
    line_intersections,
)


@dataclass(frozen=True)
class Rays:
    """The search lines of one observation."""

    points: FloatArray  # (n, dim)
    directions: FloatArray  # (n, dim), unit
    side: FloatArray  # (n,), +1 where t > 0 points into the fluid


class RayMeasure(MeasureBase):
    """Signed distances from measurement points along search directions (Paper A; Paper B
    eq. 6).

    For measurement point ``p_i`` with unit direction ``e_i`` the line ``p_i + t e_i``
    (``t`` of either sign) is intersected with the simulated interface; of several
    intersections the one of smallest ``|t|`` counts.  The residual is ``±|t|``: + when
    the intersection lies on the biofilm side of the observed interface (against the observed
    normal, which points from the solid into the fluid), - towards the fluid.

    Where the rays come from:

    * ``observation.measurement_points`` with directions: as given.  The sign uses the
      observed normal at the point (the (pseudo-)normal of the closest observed element) if
      the observation has an interface; without one the directions are taken to point from
      the biofilm into the fluid (e.g. "up" for OCT scans taken from above).
    * measurement points without directions: the observed normal at each point (closest
      observed element; a pseudo-normal at corners); the observation needs an interface.
    * no measurement points: every element centre of the observed interface with its
      element normal (the "fully automatable" variant of Paper A).

    Residuals: the ``n_mp`` signed distances [mm]; distance: their 2-norm [mm].
    """

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options

    class Options(PluginOptions):
        max_distance: float | None = Field(
            None,
            gt=0,
            description="search only this far along each ray, both ways [mm]; None: no limit",
        )
        miss_penalty: float | None = Field(
            None,
            gt=0,
            description=(
                "distance given to a ray that meets no simulated element [mm]; "
                "None: such a ray raises MeasureError"
            ),
        )

    options: Options
    dims = (2, 3)

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: object) -> None:
        super().__init__(options, **kwargs)
        self._rays: IdentityCache[Rays] = IdentityCache(maxsize=64)

    # -- protocol ----------------------------------------------------------------------------
    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray:
        """Signed distances ``d_mp^i`` at the measurement points [mm] (Paper A eq. 19)."""
        check_dimensions("ray", simulated, observation)
        rays = self.rays(observation)
        t = line_intersections(
            geometry_of(simulated),
            rays.points,
            rays.directions,
            max_distance=self.options.max_distance,
            prefer=-rays.side,  # on an exact tie prefer the biofilm side
        )
        missed = np.flatnonzero(np.isnan(t))
        if len(missed):
            if self.options.miss_penalty is None:
                i = int(missed[0])
                where = (
                    f" within max_distance={self.options.max_distance:g} mm"
                    if self.options.max_distance is not None
                    else ""
                )
                more = f" ({len(missed)} rays missed in all)" if len(missed) > 1 else ""
                raise MeasureError(
                    f"ray measure: the line through measurement point {i} at "
                    f"{_fmt(rays.points[i])} along {_fmt(rays.directions[i])} meets no element "
                    f"of the simulated interface{where}{more}"
                )
            t[missed] = 0.0
        d = -rays.side * t  # along the fluid-pointing side is negative
        if len(missed):
            d[missed] = self.options.miss_penalty
        return d

    def distance(self, simulated: Interface, observation: Observation) -> float:
        """``D_mp``: the 2-norm of the residuals [mm] (Paper B eq. 6)."""
        return float(np.linalg.norm(self.residuals(simulated, observation)))

    # -- rays of an observation --------------------------------------------------------------
    def rays(self, observation: Observation) -> Rays:
        """Points, unit directions and side signs of ``observation`` (cached per object)."""
        return self._rays.get((observation,), lambda: _make_rays(observation))


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _make_rays(observation: Observation) -> Rays:
    gamma = observation.interface
    mp = observation.measurement_points
    where = f"ray measure, observation {observation.label()!r}"
    if mp is None:
        assert gamma is not None  # an Observation has an interface or points
        points = np.array(gamma.centres)
        directions = np.array(gamma.normals)
        return Rays(points, directions, np.ones(len(points)))
    points = np.array(mp.points)
    if gamma is None:
        if mp.directions is None:
            raise ConfigError(
                "measurement points without directions need an observed interface "
                "(for the normals)",
                where,
            )
        return Rays(points, np.array(mp.directions), np.ones(len(points)))
    cp = closest_points(ElementGeometry(gamma), points)
    if mp.directions is None:
        return Rays(points, cp.normal, np.ones(len(points)))
    directions = np.array(mp.directions)
    cos = np.einsum("ij,ij->i", directions, cp.normal)
    flat = np.flatnonzero(np.abs(cos) < 1e-8)
    if len(flat):
        i = int(flat[0])
        raise ConfigError(
            f"direction {i} {_fmt(directions[i])} at measurement point {_fmt(points[i])} "
            "is tangent to the observed interface, so the side of a distance is undefined",
            where,
        )
    return Rays(points, directions, biofilm_side_sign(directions, cp.normal))
