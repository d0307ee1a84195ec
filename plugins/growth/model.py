"""The ``growth`` forward model: FSI, nutrient transport and surface growth (Paper A).

Per growth step (``growth_steps`` per ``growth_period``), on the current (grown) mesh:

1. **FSI** with :mod:`fbia.plugins.ale_fsi` on this mesh: transient over ``fsi_period`` with
   the cosine-ramped inflow (``mode = "transient"``, Paper A: 5 s) or steady
   (``mode = "quasi_static"``, the faster variant);
2. **nutrient transport** (eq. 5-8, :mod:`.transport`) on the moving mesh, stepped with the
   FSI (transient) or steady on the final FSI state;
3. the nutrient flux ``h`` into the biofilm and the fluid traction at the interface vertices
   give the **growth displacement** of eq. 9 (:mod:`.growth_law`) over
   ``growth_period / growth_steps``; it is extended into both domains by the mesh motion and
   the grown mesh becomes the reference configuration of the next step (:mod:`.mesh_update`).

Coordinates ``{"day": k}`` (k = 0, 1, 2, ... growth periods) ask for the interface after k
growth periods, deformed by the flow: the grown interface plus the FSI displacement of the
last FSI solve (k = 0: the FSI-deformed initial interface).  One run returns every requested
day, so a study can calibrate against several scans of one biofilm.

**State reuse** (issue 15, point 6).  With one growth step in all (``growth_steps = 1`` and
days 0 and 1 only), the FSI and transport solution does not depend on ``K1g``, ``K2g``,
``K3g``: it is kept per distinct other inputs (all other parameters and the options) and a run
that changes only the growth coefficients costs one cheap growth update.  With more growth
steps everything is solved again.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from ...core.errors import ConfigError, ForwardModelError
from ...core.interface import Interface
from ...core.observation import Coordinate, Solution
from ...core.options import PluginOptions
from ...core.protocols import ForwardModelBase
from ..ale_fsi.options import AleFsiOptions, solver_settings
from .geometry import finger_outline, interface_state, vertex_coordinates
from .growth_law import NODE_AREA, GrowthCoefficients, growth_displacement
from .mesh_update import grow_mesh, solid_area
from .transport import NutrientTransport, TransportSettings

__all__ = ["GrowthForwardModel", "GrowthOptions"]

#: parameters that only the growth update uses (the state before it does not depend on them)
GROWTH_ONLY = ("K1g", "K2g", "K3g")


class GrowthOptions(AleFsiOptions):
    """Options of :class:`GrowthForwardModel`: those of ``ale_fsi`` (FSI physics, mesh and
    solver) with the Paper A growth example as defaults, plus transport and growth."""

    mode: Literal["quasi_static", "transient"] = Field(
        "transient",
        description="transient: FSI + transport over fsi_period with a cosine-ramped inflow "
        "(Paper A); quasi_static: steady FSI + steady transport per growth step [-]",
    )
    E: float = Field(100.0, gt=0, description="Young's modulus of the biofilm [Pa]")
    inflow_rate: float = Field(0.1, description="volume inflow rate [mm^2/s]")
    channel_length: float = Field(0.6, gt=0, description="channel length [mm]")
    channel_height: float = Field(0.3, gt=0, description="channel height [mm]")
    finger_x0: float = Field(
        0.2, gt=0, description="x of the finger axis (not given in Paper A) [mm]"
    )
    finger_width: float = Field(0.04, gt=0, description="finger width [mm]")
    finger_height: float = Field(0.1, gt=0, description="finger height incl. its tip [mm]")
    smooth_outline: bool = Field(False, description="spline through the outline [-]")
    curved: bool = Field(False, description="curved element geometry (grown meshes: no) [-]")
    mesh_size: float = Field(0.03, gt=0, description="maximum element size [mm]")
    interface_mesh_size: float = Field(
        0.006, gt=0, description="element size at the interface [mm]"
    )
    time_step: float = Field(0.25, gt=0, description="FSI and transport time step [s]")
    ramp_time: float = Field(5.0, ge=0, description="duration of the inflow ramp [s]")
    fsi_period: float = Field(5.0, gt=0, description="FSI + transport period per growth step [s]")
    D: float | None = Field(
        None, gt=0, description="diffusion coefficient of both phases; sets both below [mm^2/s]"
    )
    D_fluid: float = Field(2.5e-3, gt=0, description="diffusion coefficient, fluid [mm^2/s]")
    D_biofilm: float = Field(2.5e-3, gt=0, description="diffusion coefficient, biofilm [mm^2/s]")
    K1R: float = Field(3e-11, ge=0, description="Monod reaction rate (eq. 6) [mol/(mm^3 s)]")
    K2R: float = Field(3e-12, gt=0, description="Monod half saturation (eq. 6) [mol/mm^3]")
    phi_in: float = Field(2.5e-11, ge=0, description="nutrient at the inflow [mol/mm^3]")
    K1g: float = Field(6e4, description="growth by nutrient flux (eq. 9) [mm^3/mol]")
    K2g: float = Field(
        5e-2,
        description="erosion by normal traction (eq. 9): s/g with traction_measure = "
        "'nodal_force' (the default), mm^2 s/g with 'density' [s/g or mm^2 s/g]",
    )
    K3g: float = Field(
        8e-2,
        description="erosion by shear traction (eq. 9), units as K2g [s/g or mm^2 s/g]",
    )
    growth_period: float = Field(86400.0, gt=0, description="growth period, Paper A: 1 day [s]")
    growth_steps: int = Field(1, ge=1, le=1000, description="growth steps per growth period [-]")
    traction_measure: Literal["nodal_force", "density"] = Field(
        "nodal_force",
        description="the traction in eq. 9: nodal force of the quasi-2-D mesh (traction x "
        "node length x thickness) or traction density (see the module docstring) [-]",
    )
    node_area: float = Field(
        NODE_AREA,
        gt=0,
        description="the stated node area of traction_measure = nodal_force (independent "
        "of the mesh; see fbia.plugins.growth.growth_law) [mm^2]",
    )
    transport_order: int = Field(2, ge=1, le=3, description="polynomial order of Phi [-]")


@dataclass
class _StepState:
    """What one FSI + transport solve leaves for the growth update, at the interface
    vertices (in chain order)."""

    vertices: NDArray[np.int64]
    reference: NDArray[np.float64]  # (n, 2) reference positions [mm]
    fsi_displacement: NDArray[np.float64]  # (n, 2) [mm]
    normals: NDArray[np.float64]  # (n, 2) unit, out of the biofilm, deformed
    flux: NDArray[np.float64]  # (n,) h [mol/(mm^2 s)]
    traction: NDArray[np.float64]  # (n, 2) in the chosen measure
    uptake: float  # nutrient consumed in the biofilm [mol/s]
    chains: list[NDArray[np.int64]]  # positions in ``vertices`` of each interface chain
    # the solvers of this state, for field output (dropped before a state is kept for reuse)
    solver: Any = None
    transport: Any = None


class GrowthForwardModel(ForwardModelBase):
    """Fluid-biofilm interaction, nutrient transport and surface growth (Paper A eq. 1-9).

    Parameters (``parameter_names``): ``K1g`` [mm^3/mol], ``K2g``, ``K3g`` (eq. 9; units per
    ``traction_measure``, see :mod:`.growth_law`), ``E`` [Pa], ``nu`` [-], ``inflow_rate``
    [mm^2/s], ``D_fluid``, ``D_biofilm`` [mm^2/s] (or ``D`` for both), ``K1R``
    [mol/(mm^3 s)], ``K2R``, ``phi_in`` [mol/mm^3]; inputs not given keep their option values.
    Coordinates: ``{"day": k}``, k = 0, 1, ... growth periods (see the module docstring).
    A run that fails raises :class:`fbia.ForwardModelError` with a reason: those of
    ``ale_fsi`` and of the transport, ``growth_inverted``, ``growth_quality`` or
    ``eroded_away`` for a growth step the mesh cannot take.
    """

    #: the extra it needs (fbia.core.extras)
    requires = ("ngsolve", "netgen")

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options

    Options = GrowthOptions

    options: GrowthOptions

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        # the FSI + transport state of one growth step, by the inputs it depends on
        self._states: dict[tuple[Any, ...], _StepState] = {}

    # -- protocol ----------------------------------------------------------------------------
    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        """Parameters and coordinates for conformance tests (Paper A's reference)."""
        return {"K1g": 6e4, "K2g": 5e-2, "K3g": 8e-2}, [{"day": 0}, {"day": 1}]

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """A cheap instance for conformance runs: coarse mesh, quasi-steady."""
        return {"mesh_size": 0.06, "interface_mesh_size": 0.012, "mode": "quasi_static"}

    def parameter_names(self) -> list[str]:
        return [
            "K1g",
            "K2g",
            "K3g",
            "E",
            "nu",
            "inflow_rate",
            "D_fluid",
            "D_biofilm",
            "K1R",
            "K2R",
            "phi_in",
        ]

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Coordinate], workdir: Path
    ) -> Solution:
        """Grow to the last requested day; the interface at every requested day."""
        t_start = time.perf_counter()
        params = self._check_parameters(parameters)
        days = self._check_coordinates(coordinates)
        o = self.options
        steps_total = max(days) * o.growth_steps
        reuse = steps_total <= 1
        mesh = self.build_mesh()
        area0 = solid_area(mesh)
        curves: dict[int, list[NDArray[np.float64]]] = {}
        diag: dict[str, Any] = {"growth": [], "uptake": [], "reused_state": False}
        fields: dict[str, Path] = {}
        state: _StepState | None = None
        dt_g = o.growth_period / o.growth_steps
        for step in range(max(1, steps_total)):
            key = self._state_key(params) if reuse else None
            if key is not None and key in self._states:
                state = self._states[key]
                diag["reused_state"] = True
            else:
                state = self._fsi_and_transport(
                    mesh, params, f"growth step {step + 1}", initial=step == 0
                )
                if key is not None:
                    self._remember(key, replace(state, solver=None, transport=None))
            if step == 0 and 0 in days:
                curves[0] = self._curves(state, np.zeros_like(state.reference))
            if steps_total == 0:
                break
            d_g = self._growth(state, params, dt_g)
            if o.write_vtu and state.solver is not None:
                fields[f"vtu_step_{step + 1:03d}"] = self._write_vtu(
                    state, d_g, Path(workdir) / f"growth_{step + 1:03d}.vtu"
                )
            mesh = grow_mesh(mesh, state.vertices, d_g, o.min_element_quality, reference_area=area0)
            n = np.linalg.norm(d_g, axis=1) * np.sign(np.sum(d_g * state.normals, axis=1))
            diag["growth"].append([float(n.max()), float(n.min())])
            diag["uptake"].append(state.uptake)
            day = (step + 1) / o.growth_steps
            if day in days:
                curves[int(day)] = self._curves(state, d_g)
        assert state is not None
        pairs = [(c, Interface.polylines(curves[int(c["day"])])) for c in coordinates]
        diag.update(
            max_growth=max((g[0] for g in diag["growth"]), default=0.0),
            max_erosion=-min((g[1] for g in diag["growth"]), default=0.0),
            mean_flux=float(np.mean(state.flux)),
            wall_time=time.perf_counter() - t_start,
        )
        return Solution.from_pairs(pairs, fields=fields, diagnostics=diag)

    # -- the stages ----------------------------------------------------------------------------
    def _fsi_and_transport(
        self, mesh: Any, params: dict[str, float], where: str, initial: bool
    ) -> _StepState:
        """FSI (transient over fsi_period, or steady) with the transport on its moving mesh;
        the interface data of the final state."""
        from ..ale_fsi.solver import AleFsiSolver

        o = self.options
        try:
            solver = AleFsiSolver(mesh, solver_settings(o))
        except ForwardModelError as exc:
            if initial:  # the user's mesh (or outline) is bad input; a grown one is a failure
                raise ConfigError(str(exc), "growth mesh") from None
            raise
        solver.set_materials({r: (params["E"], params["nu"]) for r in solver.solids})
        transport = NutrientTransport(mesh, self._transport_settings(params))
        rate = params["inflow_rate"]
        if o.mode == "quasi_static":
            solver.solve_steady(rate, f"{where}: FSI")
            transport.set_flow(solver.velocity, solver.displacement)
            transport.solve_steady(f"{where}: transport")
        else:
            ngs = solver.ngs
            d_old = ngs.GridFunction(solver.displacement.space)
            clock = {"t": 0.0}

            def on_time(t: float) -> None:
                dt = t - clock["t"]
                if dt <= 0.0:
                    return
                w = (solver.displacement - d_old) * (1.0 / dt)
                transport.set_flow(solver.velocity, solver.displacement, w)
                transport.step(dt, f"{where}: transport at {t:g} s")
                d_old.vec.data = solver.displacement.vec
                clock["t"] = t

            n = max(1, int(math.ceil(o.fsi_period / o.time_step - 1e-9)))
            times = [min(o.fsi_period, k * o.time_step) for k in range(1, n + 1)]
            solver.solve_transient(rate, times, o.time_step, o.ramp_time, o.ramp_steps, on_time)
        solver.check_state(f"{where}: FSI")
        chains = interface_state(solver)
        vertices = np.concatenate([c.vertices for c in chains])
        sizes = np.cumsum([0] + [len(c.vertices) for c in chains])
        return _StepState(
            vertices=vertices,
            reference=vertex_coordinates(mesh)[vertices],
            fsi_displacement=np.vstack([c.displacement for c in chains]),
            normals=np.vstack([c.normals for c in chains]),
            flux=transport.interface_flux(vertices.tolist()),
            traction=np.vstack([c.tractions for c in chains]),
            uptake=transport.balance()["consumption"],
            chains=[np.arange(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True)],
            solver=solver,
            transport=transport,
        )

    @staticmethod
    def _write_vtu(state: _StepState, growth: NDArray[Any], path: Path) -> Path:
        """The FSI state (velocity, pressure, displacement, interface force) with the nutrient
        ``phi`` [mol/mm^3] and the growth displacement ``growth`` [mm] of this step."""
        nv = state.solver.mesh.nv
        g = np.zeros((nv, 2))
        g[state.vertices] = growth
        phi = np.array(state.transport.phi.vec.FV().NumPy()[:nv], copy=True)
        return state.solver.write_vtu(path, {"phi": phi, "growth": g})

    def _growth(self, state: _StepState, params: dict[str, float], dt_g: float) -> NDArray[Any]:
        """Eq. 9 at the interface vertices."""
        o = self.options
        coeffs = GrowthCoefficients(k1g=params["K1g"], k2g=params["K2g"], k3g=params["K3g"])
        return growth_displacement(
            state.normals,
            state.flux,
            state.traction,
            coeffs,
            dt_g,
            traction_measure=o.traction_measure,
            nodal_area=o.node_area,
        )

    @staticmethod
    def _curves(state: _StepState, growth: NDArray[Any]) -> list[NDArray[np.float64]]:
        """The interface chains: reference + growth + FSI displacement."""
        x = state.reference + growth + state.fsi_displacement
        return [x[c] for c in state.chains]

    # -- inputs --------------------------------------------------------------------------------
    def _check_parameters(self, parameters: Mapping[str, float]) -> dict[str, float]:
        names = self.parameter_names()
        unknown = [k for k in parameters if k not in names and k != "D"]
        if unknown:
            raise ConfigError(
                f"unknown parameter(s) {unknown}; valid: {', '.join(names)}, D", "growth.solve"
            )
        o = self.options
        d_f = o.D if o.D is not None else o.D_fluid
        d_b = o.D if o.D is not None else o.D_biofilm
        params = {
            "K1g": o.K1g,
            "K2g": o.K2g,
            "K3g": o.K3g,
            "E": o.E,
            "nu": o.nu,
            "inflow_rate": o.inflow_rate,
            "D_fluid": d_f,
            "D_biofilm": d_b,
            "K1R": o.K1R,
            "K2R": o.K2R,
            "phi_in": o.phi_in,
        }
        if "D" in parameters:
            params["D_fluid"] = params["D_biofilm"] = float(parameters["D"])
        params.update({k: float(v) for k, v in parameters.items() if k != "D"})
        for k, v in params.items():
            if not math.isfinite(v):
                raise ForwardModelError(f"parameter {k} is not finite ({v})", "invalid_parameter")
        positive = ("E", "D_fluid", "D_biofilm", "K2R")
        bad = [k for k in positive if not params[k] > 0]
        if bad or not -1.0 < params["nu"] < 0.5 or params["K1R"] < 0 or params["phi_in"] < 0:
            raise ForwardModelError(
                f"parameters out of range: {', '.join(f'{k} = {params[k]:g}' for k in bad)}"
                f" nu = {params['nu']:g}, K1R = {params['K1R']:g}, phi_in = {params['phi_in']:g}",
                "invalid_parameter",
            )
        return params

    def _check_coordinates(self, coordinates: Sequence[Coordinate]) -> list[int]:
        where = "growth.solve: coordinates"
        if not coordinates:
            raise ConfigError("no coordinates requested", where)
        days = []
        for c in coordinates:
            if set(c) != {"day"}:
                raise ConfigError(f"coordinates need exactly 'day', got {sorted(c)}", where)
            day = float(c["day"])
            if day < 0 or day != int(day):
                raise ConfigError(
                    f"day must be a whole number of growth periods >= 0, got {day:g}", where
                )
            days.append(int(day))
        return days

    def _transport_settings(self, params: dict[str, float]) -> TransportSettings:
        return TransportSettings(
            d_fluid=params["D_fluid"],
            d_biofilm=params["D_biofilm"],
            k1r=params["K1R"],
            k2r=params["K2R"],
            phi_in=params["phi_in"],
            order=self.options.transport_order,
        )

    def _state_key(self, params: dict[str, float]) -> tuple[Any, ...]:
        """What the FSI + transport state depends on: every input but the growth
        coefficients (the options are fixed for this model object)."""
        return tuple(sorted((k, v) for k, v in params.items() if k not in GROWTH_ONLY))

    def _remember(self, key: tuple[Any, ...], state: _StepState) -> None:
        if len(self._states) >= 8:
            self._states.pop(next(iter(self._states)))
        self._states[key] = state

    def build_mesh_outline(self) -> NDArray[np.float64]:
        """The biofilm outline of the built mesh (mm): ``outline`` or the finger."""
        o = self.options
        if o.outline is not None:
            from ..fem.outlines import resolve_outline

            return np.asarray(resolve_outline(o.outline), dtype=float)
        return finger_outline(o.finger_x0, o.finger_width, o.finger_height)

    def build_mesh(self) -> Any:
        """The initial mesh: a user mesh, an outline in a channel, or the finger channel."""
        from ..fem import flow_cell as geometry

        o = self.options
        if o.mesh_file is not None:
            return geometry.read_mesh(o.mesh_file)
        outline = self.build_mesh_outline()
        return geometry.build_flow_cell(
            length=o.channel_length,
            height=o.channel_height,
            outline=outline,
            smooth=o.smooth_outline,
            mesh_size=o.mesh_size,
            interface_mesh_size=o.interface_mesh_size,
            solid_mesh_size=(
                2.0 * o.interface_mesh_size if o.solid_mesh_size is None else o.solid_mesh_size
            ),
            curve_order=2 if o.curved else 1,
        )
