"""A 2-D biofilm mound on the floor of a flow channel, deformed in closed form.

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_2d", n_points=41)
>>> sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], workdir=".")
>>> gamma = sol.interface({"inflow_rate": 100.0})
>>> gamma                                                   # upstream foot -> downstream foot
Interface(41 vertices, 40 segments, 2-D)
>>> (state,) = sol.diagnostics["states"]                    # one coordinate, one state
>>> round(float(state["lean_mm"]), 3)
0.075

Geometry (Paper A, homogeneous example; Paper B, "Problem setup", Fig. 2): a channel of
length L = 2 mm and height H = 1 mm; the mound's footprint of width w = 0.8 mm is centred at
x0 = 1 mm, its crest (height h = 0.5 mm) sits ``c`` downstream of x0.  The undeformed interface
is the curve, for t in [0, pi],

    X(t) = x0 - (w/2) cos t + c sin^2 t,      Y(t) = h sin t            [mm]

sampled at ``n_points`` vertices evenly spaced in arc length and ordered from the upstream
foot to the downstream foot, so that the biofilm lies on the right and the normals (tangent
turned by +90 deg, Paper B eq. 24b) point into the fluid.

Deformation of a reference point (X, Y) of the interface (lean delta [mm] and flattening eps
[-] from :mod:`fbia.plugins.analytic._mechanics`; x_c = x0 + c is the crest)::

    u_x = delta (Y/h)^2 - eps (X - x_c) (Y/h)                            [mm]
    u_y = -eps Y                                                          [mm]

It vanishes on the floor (the bonded footing), is exactly zero at zero inflow, and keeps the
polyline simple (for every Y it is an increasing affine map of X; Y maps monotonically).

Inputs: ``E`` [Pa], ``nu`` [-], ``inflow_rate`` q [mm^2/s], ``load_scale`` [-].  Inputs not
given keep their option values.  A state's coordinate ``{"inflow_rate": q}`` sets q for that
state and takes precedence over ``parameters["inflow_rate"]``; an empty coordinate ``{}`` uses
``parameters["inflow_rate"]`` (or the option), which is how an uncertain inflow rate (Paper B)
enters.
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


class AnalyticMound2DForwardModel(MoundModel):
    """Closed-form FSI stand-in: a 2-D mound that leans and flattens under the flow.

    See the module docstring for the geometry and the formulas.
    """

    #: Spatial dimension of the interfaces it returns (checked against data files).
    dim = 2

    class Options(MoundOptions):
        channel_length: float = Field(2.0, gt=0, description="channel length L [mm]")
        centre: float = Field(1.0, description="x of the footprint centre x0 [mm]")
        width: float = Field(0.8, gt=0, description="footprint width w of the mound [mm]")
        n_points: int = Field(
            101, ge=5, le=10_000_000, description="vertices of the interface polyline [-]"
        )

        @model_validator(mode="after")
        def _check_footprint(self) -> Self:
            half = 0.5 * self.width
            if self.centre - half < 0.0 or self.centre + half > self.channel_length:
                raise ValueError(
                    f"footprint [{self.centre - half}, {self.centre + half}] mm leaves the "
                    f"channel [0, {self.channel_length}] mm"
                )
            if abs(self.crest_shift) >= 0.25 * self.width:
                raise ValueError(
                    f"|crest_shift| = {abs(self.crest_shift)} mm must be below width/4 = "
                    f"{0.25 * self.width} mm"
                )
            return self

    field_suffix = ".csv"  # written interfaces
    options: Options

    def _reference_shape(self) -> Interface:
        return _mound_polyline(self.options)

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """Options of a cheap instance (for the conformance checks of ``fbia.testing``)."""
        return {"n_points": 41}

    def states(
        self, parameters: Mapping[str, float], coordinates: Sequence[Mapping[str, float]]
    ) -> list[MoundState]:
        """Validated inputs and closed-form response (load, lean, flattening) per coordinate."""
        o = self.options
        return resolve_states(
            type(self).__name__,
            o,
            parameters,
            coordinates,
            gap=o.channel_height - o.height,
            footprint=o.width,
        )

    def displacement(self, state: MoundState) -> np.ndarray:
        """Displacement (n, 2) [mm] of the reference vertices in ``state``."""
        o = self.options
        X, Y = self._reference.vertices.T
        eta = Y / o.height
        x_crest = o.centre + o.crest_shift
        ux = state.lean * eta**2 - state.flattening * (X - x_crest) * eta
        uy = -state.flattening * Y
        return np.c_[ux, uy]


def _mound_polyline(o: AnalyticMound2DForwardModel.Options) -> Interface:
    """The undeformed mound, vertices evenly spaced in arc length, upstream -> downstream."""
    t = np.linspace(0.0, np.pi, 20001)
    half = 0.5 * o.width
    x = o.centre - half * np.cos(t) + o.crest_shift * np.sin(t) ** 2
    y = o.height * np.sin(t)
    s = np.r_[0.0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))]
    ts = np.interp(np.linspace(0.0, s[-1], o.n_points), s, t)
    ts[0], ts[-1] = 0.0, np.pi
    xs = o.centre - half * np.cos(ts) + o.crest_shift * np.sin(ts) ** 2
    ys = o.height * np.sin(ts)
    ys[0] = ys[-1] = 0.0
    return Interface.polyline(np.c_[xs, ys])
