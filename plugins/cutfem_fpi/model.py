"""The ``cutfem_fpi`` forward model: fixed-grid fluid-poroelastic interaction.

>>> from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel
>>> model = CutFemFpiForwardModel(background_mesh_size=0.08, interface_mesh_size=0.06)
>>> model.parameter_names()
['E', 'nu', 'phi0', 'K', 'inflow_rate']
>>> sol = model.solve({"E": 300.0, "phi0": 0.25}, [{"inflow_rate": 100.0}], "run")  # doctest: +SKIP

A user mesh of the flow cell, the file ``ale_fsi`` reads, replaces the builder::

    model = CutFemFpiForwardModel(mesh_file="cell.msh", background_mesh_size=0.05)

Its solid region(s) become the skeleton mesh, their ``interface`` edges the biofilm outline
and its bounding box the channel (:func:`.coupled.read_flow_cell`); the background grid is
always cutfem's own.

Coordinates are inflow levels ``{"inflow_rate": r}`` (mm^2/s, plane strain) or, in the
quasi-2-D setting of Paper A, ``{"inflow_volume_rate": Q}`` (mm^3/s over a channel of
``thickness`` mm; ``r = Q / thickness``).  The levels are solved in ascending order, each
starting from the previous one, so the result does not depend on the order requested.
Physics and numerics: :mod:`.flow`, :mod:`.skeleton`, :mod:`.coupled`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from ...core.errors import ConfigError, ForwardModelError
from ...core.interface import Interface
from ...core.observation import Coordinate, Solution
from ...core.options import PluginOptions, settings_from
from ...core.protocols import ForwardModelBase
from ..fem.outlines import NAMED_OUTLINES, OutlineName, resolve_outline

if TYPE_CHECKING:
    from .coupled import CouplingSettings
    from .flow import FlowSettings
    from .skeleton import SkeletonSettings

Point = tuple[float, float]


#: The default biofilm outline (a name of ``fbia.plugins.fem.outlines``).  Paper A's
#: poroelastic example uses the same mound as its FSI examples and names it
#: (``outline = "paper_a_facts"``, ale_fsi's default), which this model solves at the
#: example's settings (K = 1e-4 mm^2, the study's whole path); as the plugin's default it does
#: not yet: measured (issue 46 item 5), the skeleton's Newton stagnates in coupling iteration
#: 2 of the cross-check against ale_fsi (K down to 1e-12 mm^2; scaled updates 0.21, 0.47,
#: 0.046, 0.062), so the default stays fbia's earlier mound.
POROELASTIC_OUTLINE: OutlineName = "fig2_sketch"


class CutFemFpiForwardModel(ForwardModelBase):
    """Fluid-poroelastic interaction on a fixed background grid (Paper A eq. 10-15).

    Navier-Stokes in the channel and Darcy flow in the biofilm on one background mesh cut by
    the deformed biofilm (CutFEM, ngsxfem), coupled through the Beavers-Joseph interface
    conditions (eq. 14-15); a neo-Hooke poroelastic skeleton (eq. 10c, 12-13) with
    Kozeny-Carman permeability (eq. 11) on the biofilm's own (curved) mesh; partitioned
    coupling accelerated by interface quasi-Newton (IQN-ILS) or Aitken relaxation.
    Parameters: ``E`` [Pa], ``nu`` [-], ``phi0`` [-], ``K`` [mm^2], ``inflow_rate``
    [mm^2/s].  Failures (coupling or Newton divergence, no admissible skeleton state with
    porosity in (0, 1) and J > 0) raise :class:`fbia.ForwardModelError` with a ``reason``.
    """

    #: the extra it needs (fbia.core.extras)
    requires = ("ngsolve", "netgen", "xfem")

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options

    dim = 2

    class Options(PluginOptions):
        E: float = Field(300.0, gt=0, description="Young's modulus of the skeleton [Pa]")
        nu: float = Field(0.3, gt=-1.0, lt=0.5, description="Poisson's ratio of the skeleton [-]")
        phi0: float = Field(0.25, gt=0, lt=1, description="initial porosity [-]")
        K: float = Field(1e-4, gt=0, description="reference permeability (eq. 11) [mm^2]")
        inflow_rate: float = Field(
            100.0, description="2-D volume inflow rate of the parabolic profile [mm^2/s]"
        )
        thickness: float = Field(
            0.01,
            gt=0,
            description="quasi-2-D channel thickness: a coordinate {'inflow_volume_rate': Q} "
            "means inflow_rate = Q / thickness [mm]",
        )
        channel_length: float = Field(
            2.0, gt=0, description="flow-cell length (with mesh_file: its bounding box) [mm]"
        )
        channel_height: float = Field(
            1.0, gt=0, description="flow-cell height (with mesh_file: its bounding box) [mm]"
        )
        outline: list[Point] | OutlineName | None = Field(
            None,
            description="biofilm outline from the upstream to the downstream foot on y = 0, "
            "or a named one (fbia.plugins.fem.outlines: 'paper_a_facts', the FSI examples' "
            "flow cell, or 'fig2_sketch'); default 'fig2_sketch' (POROELASTIC_OUTLINE) [mm]",
        )
        mesh_file: Path | None = Field(
            None,
            description="user mesh of the flow cell, the file ale_fsi reads (gmsh .msh or any "
            "meshio format; regions fluid, solid[_k]; boundaries inflow, outflow, interface, "
            "solid_fixed[, walls]): its solid regions, merged, are the skeleton mesh "
            "(straight-sided), its interface edges the biofilm outline, its bounding box the "
            "channel; replaces outline and the builder's geometry options [path]",
        )
        smooth_outline: bool = Field(
            True, description="interpolate the outline by a cubic spline [-]"
        )
        skeleton_curve_order: int = Field(
            2,
            ge=1,
            le=3,
            description="geometry order of the biofilm mesh along the outline (1: straight) [-]",
        )
        background_mesh_size: float = Field(
            0.05, gt=0, description="element size of the fixed background mesh [mm]"
        )
        interface_mesh_size: float = Field(
            0.04, gt=0, description="element size of the biofilm (skeleton) mesh [mm]"
        )
        fluid_density: float = Field(1e-3, ge=0, description="fluid density, 0: Stokes [g/mm^3]")
        fluid_viscosity: float = Field(
            1e-3, gt=0, description="viscosity of channel and pore fluid [g/(mm s)]"
        )
        alpha_bj: float = Field(1.0, gt=0, description="Beavers-Joseph alpha (eq. 15) [-]")
        beta_bj: float = Field(1.0, ge=0, description="Beavers-Joseph beta (eq. 14d) [-]")
        saffman: bool = Field(
            False, description="Beavers-Joseph-Saffman: drop beta_BJ q.t in eq. 14d [-]"
        )
        kappa: float = Field(100.0, gt=0, description="bulk modulus of psi_vol (eq. 13a) [Pa]")
        eta: float = Field(1.0, gt=0, description="porosity penalty of psi_pen (eq. 13b) [Pa]")
        outflow: Literal["horizontal", "do_nothing"] = Field(
            "horizontal", description="outflow: v_y = 0 and traction-free in x, or free [-]"
        )
        ghost_penalty: float = Field(0.1, gt=0, description="ghost-penalty factor gamma [-]")
        pore_ghost_floor: float = Field(
            1.0,
            ge=0,
            description="K-independent part of the pore-pressure ghost penalty, relative to "
            "the fluid pressure's gamma/mu: keeps the pore pressure stable for K << h^2, where "
            "it is the multiplier of the interface mass condition (eq. 14c) [-]",
        )
        pore_pressure_transfer: Literal["interface", "volume"] = Field(
            "interface",
            description="pore pressure of the skeleton: the flow's values on the interface "
            "extended by steady Darcy on the skeleton mesh ('interface'), or the flow's field "
            "interpolated everywhere ('volume') [-]",
        )
        coupling_tol: float = Field(
            1e-6, gt=0, description="interface change that ends the coupling [mm]"
        )
        coupling_max_iter: int = Field(40, ge=1, description="coupling iterations per level [-]")
        omega0: float = Field(
            0.5, gt=0, le=1, description="relaxation factor of the first coupling iteration [-]"
        )
        flow_newton_tol: float = Field(
            1e-8, gt=0, description="estimated relative velocity error ending the NS Newton [-]"
        )
        level_set: Literal["nodal", "voxel"] = Field(
            "nodal",
            description="level set of the deformed biofilm: 'nodal' = P2 interpolant of the "
            "signed distance on the background mesh, 'voxel' = bilinear on a voxel grid of "
            "spacing voxel_size [-]",
        )
        voxel_size: float = Field(
            0.004, gt=0, description="grid spacing of the voxel level set [mm]"
        )
        acceleration: Literal["iqn_ils", "aitken"] = Field(
            "iqn_ils",
            description="coupling acceleration: interface quasi-Newton with a least-squares "
            "inverse Jacobian (IQN-ILS) or Aitken relaxation [-]",
        )
        coupling_inexact: float = Field(
            0.1,
            ge=0,
            description="inexact coupling: Newton tolerances of flow and skeleton are "
            "coupling_inexact * (last interface change) / channel_height, never below "
            "flow_newton_tol and 1e-10; 0: always exact [-]",
        )
        write_vtu: bool = Field(
            False, description="write VTU fields per coordinate into the workdir [-]"
        )
        threads: int = Field(1, ge=1, description="NGSolve task-manager threads [-]")

        @field_validator("outline", mode="before")
        @classmethod
        def _outline_name(cls, v: Any) -> Any:
            # as ale_fsi's options (an unknown name is named, not the union's type errors);
            # one function in fem/outlines.py when ale_fsi's code changes next (a change
            # there now would mark every ale_fsi row of docs/reproductions.md as stale)
            if isinstance(v, str) and v not in NAMED_OUTLINES:
                raise ValueError(
                    f"unknown outline {v!r}; named outlines: {', '.join(sorted(NAMED_OUTLINES))}"
                    " (or give the points)"
                )
            return v

        @model_validator(mode="after")
        def _mesh_source(self) -> CutFemFpiForwardModel.Options:
            builder = (
                "outline",
                "smooth_outline",
                "skeleton_curve_order",
                "interface_mesh_size",
                "channel_length",
                "channel_height",
            )
            clash = [k for k in builder if k in self.model_fields_set]
            if self.mesh_file is not None and clash:
                raise ValueError(
                    f"give either mesh_file or {', '.join(clash)}, not both (the mesh file "
                    "sets the biofilm, its mesh and the channel)"
                )
            return self

    options: Options

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        self._solver: Any = None

    # -- protocol ----------------------------------------------------------------------------
    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        """Paper A's poroelastic example (E = 300 Pa, phi0 = 0.25) at two inflow levels."""
        return {"E": 300.0, "phi0": 0.25}, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}]

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """A coarse, cheap instance for conformance runs."""
        return {
            "background_mesh_size": 0.1,
            "interface_mesh_size": 0.08,
            "coupling_tol": 1e-5,
        }

    def parameter_names(self) -> list[str]:
        return ["E", "nu", "phi0", "K", "inflow_rate"]

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Coordinate], workdir: Path
    ) -> Solution:
        """Coupled steady states at every coordinate; :class:`ForwardModelError` on failure.

        Diagnostics, one entry per coordinate unless said otherwise: ``coupling_iterations``,
        ``relaxation_factors`` (per coupling iteration: Aitken's factor, or for IQN-ILS
        ``omega0`` in the first iteration and 1, the full quasi-Newton step, afterwards),
        ``interface_changes`` (largest interface movement per coupling iteration, mm),
        ``flow_newton_iterations``, ``skeleton_newton_iterations``, ``max_displacement`` (mm),
        ``porosity_range``, ``interface_flux`` (net flux into the biofilm, mm^2/s),
        ``inflow_outflow_flux`` (mm^2/s); for the whole run ``ndof_flow`` and
        ``ndof_skeleton`` (free dofs), ``time_split`` (level set, flow, skeleton, transfer;
        s), ``setup_time`` and ``wall_time`` (s).
        """
        t_start = time.perf_counter()
        params = self._check_parameters(parameters)
        levels = self._levels(coordinates, params)
        solver = self._get_solver()
        solver.set_material(params["E"], params["nu"], params["phi0"], params["K"])
        solver.reset()
        t_setup = time.perf_counter() - t_start
        n = len(levels)
        curves: list[Any] = [None] * n
        diag: dict[str, Any] = {
            "coupling_iterations": [0] * n,
            "relaxation_factors": [[] for _ in range(n)],
            "interface_changes": [[] for _ in range(n)],
            "flow_newton_iterations": [0] * n,
            "skeleton_newton_iterations": [0] * n,
            "max_displacement": [0.0] * n,
            "porosity_range": [[0.0, 0.0]] * n,
            "interface_flux": [0.0] * n,
            "inflow_outflow_flux": [[0.0, 0.0]] * n,
        }
        times = {"level_set": 0.0, "flow": 0.0, "skeleton": 0.0, "transfer": 0.0}
        fields: dict[str, Path] = {}
        solved: dict[float, int] = {}
        for i in sorted(range(n), key=lambda j: (abs(levels[j]), levels[j])):
            rate = levels[i]
            if rate in solved:
                j = solved[rate]
                for key in diag:
                    diag[key][i] = diag[key][j]
                curves[i] = curves[j]
                continue
            rep = solver.solve(rate, f"cutfem_fpi, inflow rate {rate:g} mm^2/s")
            for k, v in rep.times.items():
                times[k] += v
            curves[i] = solver.interface_curve()
            diag["coupling_iterations"][i] = rep.iterations
            diag["relaxation_factors"][i] = rep.omegas
            diag["interface_changes"][i] = rep.changes
            diag["flow_newton_iterations"][i] = rep.flow_iterations
            diag["skeleton_newton_iterations"][i] = rep.skeleton_iterations
            diag["max_displacement"][i] = float(
                np.max(np.linalg.norm(curves[i] - solver.sampler.reference, axis=1))
            )
            diag["porosity_range"][i] = list(solver.porosity_range())
            diag["interface_flux"][i] = solver.flow.interface_mass_balance()[0]
            diag["inflow_outflow_flux"][i] = list(solver.boundary_fluxes())
            if self.options.write_vtu:
                from .output import write_vtu

                fields.update(write_vtu(solver, Path(workdir), i))
            solved[rate] = i
        diag.update(
            ndof_flow=solver.flow.ndof if solver.flow is not None else 0,
            ndof_skeleton=solver.skeleton.ndof,
            time_split=times,
            setup_time=t_setup,
            wall_time=time.perf_counter() - t_start,
        )
        pairs = [(c, Interface.polyline(cv)) for c, cv in zip(coordinates, curves, strict=True)]
        return Solution.from_pairs(pairs, fields=fields, diagnostics=diag)

    # -- internals ---------------------------------------------------------------------------
    def _check_parameters(self, parameters: Mapping[str, float]) -> dict[str, float]:
        names = self.parameter_names()
        unknown = [k for k in parameters if k not in names]
        if unknown:
            raise ConfigError(
                f"unknown parameter(s) {unknown}; valid: {', '.join(names)}", "cutfem_fpi.solve"
            )
        o = self.options
        params = {"E": o.E, "nu": o.nu, "phi0": o.phi0, "K": o.K, "inflow_rate": o.inflow_rate}
        params.update({k: float(v) for k, v in parameters.items()})
        for k, v in params.items():
            if not math.isfinite(v):
                raise ForwardModelError(f"parameter {k} is not finite ({v})", "invalid_parameter")
        if not params["E"] > 0:
            raise ForwardModelError(f"E = {params['E']} Pa is not positive", "invalid_parameter")
        if not -1.0 < params["nu"] < 0.5:
            raise ForwardModelError(
                f"nu = {params['nu']} is outside (-1, 0.5)", "invalid_parameter"
            )
        if not 0.0 < params["phi0"] < 1.0:
            raise ForwardModelError(
                f"phi0 = {params['phi0']} is outside (0, 1)", "porosity_out_of_range"
            )
        if not params["K"] > 0:
            raise ForwardModelError(f"K = {params['K']} mm^2 is not positive", "invalid_parameter")
        return params

    def _levels(self, coordinates: Sequence[Coordinate], params: dict[str, float]) -> list[float]:
        where = "cutfem_fpi.solve: coordinates"
        if len(coordinates) == 0:
            raise ConfigError("no coordinates requested", where)
        out = []
        for c in coordinates:
            keys = set(c)
            if keys <= {"inflow_rate"}:
                out.append(float(c.get("inflow_rate", params["inflow_rate"])))
            elif keys == {"inflow_volume_rate"}:
                out.append(float(c["inflow_volume_rate"]) / self.options.thickness)
            else:
                raise ConfigError(
                    "coordinates take 'inflow_rate' [mm^2/s] or 'inflow_volume_rate' "
                    f"[mm^3/s], got {sorted(keys)}",
                    where,
                )
            if not math.isfinite(out[-1]):
                raise ConfigError(f"inflow level {out[-1]} is not finite", where)
        return out

    def _get_solver(self) -> Any:
        if self._solver is None:
            import os

            os.environ.setdefault("MKL_NUM_THREADS", str(self.options.threads))
            import ngsolve as ngs

            from .coupled import PoroFsiSolver
            from .meshes import biofilm_mesh, channel_mesh, read_flow_cell

            o = self.options
            ngs.SetNumThreads(o.threads)
            if o.mesh_file is not None:
                cell = read_flow_cell(o.mesh_file)
                _check_outline(
                    cell.outline, cell.origin, cell.length, cell.height, f"{o.mesh_file}: interface"
                )
                skeleton_mesh, origin = cell.skeleton, cell.origin
                length, height = cell.length, cell.height
            else:
                length, height, origin = o.channel_length, o.channel_height, (0.0, 0.0)
                skeleton_mesh = biofilm_mesh(
                    self._outline(), o.smooth_outline, o.interface_mesh_size, o.skeleton_curve_order
                )
            self._solver = PoroFsiSolver(
                channel_mesh(length, height, o.background_mesh_size, origin),
                skeleton_mesh,
                length,
                height,
                *coupled_settings(o),
                outflow=o.outflow,
                origin=origin,
            )
        return self._solver

    def _outline(self) -> np.ndarray:
        """The biofilm outline option (mm), checked like the ``ale_fsi`` flow cell checks it."""
        o = self.options
        where = "cutfem_fpi options: outline"
        p = np.asarray(resolve_outline(o.outline or POROELASTIC_OUTLINE), dtype=float)
        if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
            raise ConfigError(f"needs at least 3 finite points (x, y), got shape {p.shape}", where)
        _check_outline(p, (0.0, 0.0), o.channel_length, o.channel_height, where)
        return p

    @property
    def solver(self) -> Any:
        """The underlying :class:`~fbia.plugins.cutfem_fpi.coupled.PoroFsiSolver`."""
        return self._get_solver()

    def undeformed(self) -> Interface:
        """The reference interface, point for point the one :meth:`solve` returns deformed
        (what ``[synthetic] placement = "displacement"`` measures the motion against)."""
        return Interface.polyline(self._get_solver().sampler.reference)


def _check_outline(
    p: np.ndarray, origin: tuple[float, float], length: float, height: float, where: str
) -> None:
    """Raise :class:`ConfigError` unless the outline ``p`` (n, 2) runs from an upstream to a
    downstream foot on the floor of the channel ``origin + [0, length] x [0, height]``,
    strictly inside it otherwise and without self-intersection (what the level set needs)."""
    import shapely

    x0, y0 = origin
    tol = 1e-9 * max(length, height)
    x, y = p[:, 0] - x0, p[:, 1] - y0
    if abs(y[0]) > tol or abs(y[-1]) > tol:
        raise ConfigError(f"must start and end on the channel floor (y = {y0:g})", where)
    if np.any(y[1:-1] <= tol) or np.any(y >= height - tol):
        raise ConfigError("inner points must lie strictly inside the channel", where)
    if np.any(x <= tol) or np.any(x >= length - tol):
        raise ConfigError("must stay clear of the inflow and outflow", where)
    if x[0] >= x[-1]:
        raise ConfigError("must run from the upstream to the downstream foot", where)
    if not shapely.LineString(np.vstack([p, p[:1]])).is_simple:
        raise ConfigError("intersects itself", where)


def coupled_settings(o: Any) -> tuple[FlowSettings, SkeletonSettings, CouplingSettings]:
    """The flow's, the skeleton's and the coupling's settings from the plugin's options (the
    one place they are mapped)."""
    from .coupled import CouplingSettings
    from .flow import FlowSettings
    from .skeleton import SkeletonSettings

    flow = {"viscosity": "fluid_viscosity", "density": "fluid_density"}
    coupling = {"tol": "coupling_tol", "max_iter": "coupling_max_iter"}
    return (
        settings_from(o, FlowSettings, {**flow, "newton_tol": "flow_newton_tol"}),
        settings_from(o, SkeletonSettings),
        settings_from(
            o,
            CouplingSettings,
            {**coupling, "inexact": "coupling_inexact", "pore_pressure": "pore_pressure_transfer"},
        ),
    )
