"""A 3-D biofilm dome on the floor of a flow channel, deformed in closed form.

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_3d", n_rings=4)
>>> sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], workdir=".")
>>> sol.interface({"inflow_rate": 100.0})
Interface(61 vertices, 96 triangles, 3-D)

Axes: x downstream, y across the channel, z up; the floor is z = 0.  The dome is a half
ellipsoid with footprint semi-axes a = length/2 (x) and b = width/2 (y), height h, centred at
(x0, y0), its crest shifted downstream by c.  In the polar angle theta in [0, pi/2] and the
azimuth phi::

    X = x0 + a sin(theta) cos(phi) + c cos^2(theta)
    Y = y0 + b sin(theta) sin(phi)                                          [mm]
    Z = h cos(theta)

Triangulation: ``n_rings`` rings at theta_k = (pi/2) k / n_rings with 6 k vertices each around
the crest vertex, zipped into triangles counter-clockwise seen from above, so that the
right-hand normals point out of the biofilm into the fluid.  The rim ring lies on the floor.

Deformation of a reference point (X, Y, Z) (lean delta [mm], flattening eps [-] from
:mod:`fbia.plugins.analytic._mechanics`; (x_c, y0) is the crest)::

    u_x = delta (Z/h)^2 - eps (X - x_c) (Z/h)
    u_y = -eps (Y - y0) (Z/h)                                               [mm]
    u_z = -eps Z

Inputs: ``E`` [Pa], ``nu`` [-], ``inflow_rate`` Q [mm^3/s through the channel cross-section
W x H; the load uses the rate per width q = Q/W in mm^2/s], ``load_scale`` [-].  A state's
coordinate ``{"inflow_rate": Q}`` takes precedence over ``parameters["inflow_rate"]``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Self

import numpy as np
from pydantic import Field, model_validator

from ...core.interface import Interface
from ._mechanics import (
    MoundModel,
    MoundOptions,
    MoundState,
    resolve_states,
)


class AnalyticMound3DForwardModel(MoundModel):
    """Closed-form FSI stand-in: a 3-D dome that leans downstream and flattens under the flow.

    See the module docstring for the geometry and the formulas.
    """

    #: Spatial dimension of the interfaces it returns (checked against data files).
    dim = 3
    #: x downstream, y across the channel, z up (fbia's frame, an OCT scan's own)
    up_axis = "z"

    class Options(MoundOptions):
        channel_length: float = Field(2.0, gt=0, description="channel length L along x [mm]")
        channel_width: float = Field(1.0, gt=0, description="channel width W along y [mm]")
        inflow_rate: float = Field(
            100.0, description="volume inflow rate used when not given [mm^3/s]"
        )
        centre_x: float = Field(1.0, description="x of the footprint centre x0 [mm]")
        centre_y: float = Field(0.5, description="y of the footprint centre y0 [mm]")
        length: float = Field(0.8, gt=0, description="footprint length 2a along the flow [mm]")
        width: float = Field(0.8, gt=0, description="footprint width 2b across the flow [mm]")
        n_rings: int = Field(
            8, ge=2, le=1000, description="rings of vertices from crest to rim; 6 n^2 triangles [-]"
        )

        @model_validator(mode="after")
        def _check_footprint(self) -> Self:
            a, b = 0.5 * self.length, 0.5 * self.width
            if not (
                0.0 <= self.centre_x - a
                and self.centre_x + a <= self.channel_length
                and 0.0 <= self.centre_y - b
                and self.centre_y + b <= self.channel_width
            ):
                raise ValueError("the dome's footprint leaves the channel floor")
            if abs(self.crest_shift) >= 0.25 * self.length:
                raise ValueError(
                    f"|crest_shift| = {abs(self.crest_shift)} mm must be below length/4 = "
                    f"{0.25 * self.length} mm"
                )
            return self

    options: Options

    def _reference_shape(self) -> Interface:
        return _dome_surface(self.options)

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """Options of a cheap instance (for the conformance checks of ``fbia.testing``)."""
        return {"n_rings": 4}

    def states(
        self, parameters: Mapping[str, float], coordinates: Sequence[Mapping[str, float]]
    ) -> list[MoundState]:
        """Validated inputs and closed-form response per coordinate (load per unit width)."""
        o = self.options
        # the load formulas take the rate per width q = Q / W: scale the viscous load by 1/W
        scaled = o.model_copy(update={"viscosity": o.viscosity / o.channel_width})
        return resolve_states(
            type(self).__name__,
            scaled,
            parameters,
            coordinates,
            gap=o.channel_height - o.height,
            footprint=o.length,
        )

    def displacement(self, state: MoundState) -> np.ndarray:
        """Displacement (n, 3) [mm] of the reference vertices in ``state``."""
        o = self.options
        X, Y, Z = self._reference.vertices.T
        eta = Z / o.height
        x_crest = o.centre_x + o.crest_shift
        ux = state.lean * eta**2 - state.flattening * (X - x_crest) * eta
        uy = -state.flattening * (Y - o.centre_y) * eta
        uz = -state.flattening * Z
        return np.c_[ux, uy, uz]


def _dome_surface(o: AnalyticMound3DForwardModel.Options) -> Interface:
    """Half-ellipsoid triangulated in rings around the crest, normals out of the biofilm."""
    n = o.n_rings
    a, b, h, c = 0.5 * o.length, 0.5 * o.width, o.height, o.crest_shift
    theta = np.r_[0.0]
    phi = np.r_[0.0]
    rings: list[np.ndarray] = [np.array([0])]
    for k in range(1, n + 1):
        m = 6 * k
        start = len(theta)
        theta = np.r_[theta, np.full(m, 0.5 * np.pi * k / n)]
        phi = np.r_[phi, 2.0 * np.pi * np.arange(m) / m]
        rings.append(np.arange(start, start + m))
    rho = np.sin(theta)
    x = o.centre_x + a * rho * np.cos(phi) + c * np.cos(theta) ** 2
    y = o.centre_y + b * rho * np.sin(phi)
    z = h * np.cos(theta)
    z[rings[-1]] = 0.0  # the rim lies exactly on the floor
    triangles = []
    for k in range(1, n + 1):
        triangles.extend(_zip_rings(rings[k - 1], phi[rings[k - 1]], rings[k], phi[rings[k]]))
    return Interface.surface(np.c_[x, y, z], np.array(triangles))


def _zip_rings(
    inner: np.ndarray, inner_phi: np.ndarray, outer: np.ndarray, outer_phi: np.ndarray
) -> list[tuple[int, int, int]]:
    """Triangles between two rings (azimuths increasing from 0), counter-clockwise from above."""
    p, m = len(inner), len(outer)
    i = j = 0
    tris: list[tuple[int, int, int]] = []
    while i < p or j < m:
        next_inner = inner_phi[i + 1] if i + 1 < p else 2.0 * np.pi
        next_outer = outer_phi[j + 1] if j + 1 < m else 2.0 * np.pi
        if p == 1 or (j < m and next_outer <= next_inner):
            tris.append((int(inner[i % p]), int(outer[j]), int(outer[(j + 1) % m])))
            j += 1
        else:
            tris.append((int(inner[i]), int(outer[j % m]), int(inner[(i + 1) % p])))
            i += 1
        if p == 1 and j == m:
            break
    return tris
