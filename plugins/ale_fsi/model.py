"""The ``ale_fsi`` forward model: parameters in, deformed fluid-biofilm interface out.

>>> import fbia
>>> from fbia.plugins.ale_fsi import AleFsiForwardModel
>>> model = AleFsiForwardModel(mesh_size=0.2, interface_mesh_size=0.06)
>>> model.parameter_names()
['E', 'nu', 'inflow_rate']
>>> sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], "run")  # doctest: +SKIP
>>> sol.interface({"inflow_rate": 100.0}).vertices.shape                           # doctest: +SKIP
(..., 2)

Quasi-static mode (default) solves the steady coupled problem with continuation in the inflow
rate; the coordinates are inflow levels ``{"inflow_rate": r}`` (mm^2/s; ``{}`` means the
parameter/option value).  Transient mode marches with one-step-theta from rest, the inflow
ramped by a cosine over ``ramp_time`` as in Paper A, and returns the interface at the requested
``{"time": t}`` (s).  Physics, weak forms and checks: :mod:`fbia.plugins.ale_fsi.solver`.

``geometry = "dome_3d"`` solves the same model on a 3-D duct with a dome on its floor
(:mod:`~fbia.plugins.ale_fsi.geometry3d`; inflow rate in mm^3/s) and returns the interface as
a triangulated surface; ``"ridge_3d"`` extrudes the 2-D cell between symmetry walls (the
plane-strain limit; inflow rate per unit depth, mm^2/s).  Both modes, probes (x, y, z) and
VTU output (tetrahedra) work in 3-D as in 2-D; ``"colony_3d"`` takes a user's colony surface
(:mod:`~fbia.plugins.ale_fsi.colony3d`) and ``mesh_file`` a 3-D tetrahedral mesh.

Recommended 3-D settings (``dome_3d``; :data:`~fbia.plugins.ale_fsi.options.RECOMMENDED_3D`,
``benchmarks/bench_ale_fsi_3d.py`` prints the table): ``order = 3, interface_mesh_size = 0.15,
mesh_size = 0.2, curved = True, threads = 2, mesh_motion_layer = 0.15, mesh_motion_order = 1,
newton_tol = 1e-6`` -- 32 k unknowns, 1.1 GB, 9.3-10.1 s wall from rest on two free cores
(2026-12-01, median 9.8 s of five; 2 Jacobians); the largest displacement within 1 % of both
references: -0.87 % from the finest run (order 3, duct 0.15 mm, 84 k unknowns) and -0.42 %
from the limit of orders 2, 3, 4 on the 0.15/0.3 mm mesh (Aitken), which differ by 0.45 %
themselves.  The motion layer keeps the ALE mesh fixed beyond one interface element of the
dome, and ``mesh_motion_order = 1`` makes it piecewise linear inside the fluid (the interface
keeps order 3): without both (the whole fluid mesh moving at order 3) 57 k unknowns, 2.5 GB,
27-30 s, and a displacement 0.03 % apart.  With ``mesh_size = 0.3`` (33 k
unknowns, 18 s before the layer) the displacement is +0.7 % / +1.15 % from them; order 4
there (81 k, 69 s, 4.5 GB) is -0.3 % / +0.14 %.
The error of order 2 comes from the duct (the flow), not from the dome: order 2 is +0.5 % /
+0.95 % with a 0.075 mm dome in a 0.15 mm duct (43 k unknowns, ~40 s CPU), and curving the
dome (``curved``) moves the displacement by < 0.5 %.  P2/P3 tetrahedra have no interior
unknowns to condense statically; Pardiso on the whole Jacobian stays faster than the block
GMRes (``linear_solver``) at these sizes (order 3, 57 k unknowns: 49 s against 78 s CPU,
2.4 against 2.1 GB).  ``threads = 2`` pays only when both cores are free (on a machine
loaded with other jobs one thread was faster).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError, ForwardModelError
from ...core.interface import Interface
from ...core.observation import Coordinate, Solution
from ...core.options import PluginOptions
from ...core.protocols import ForwardModelBase
from ..fem.flow_cell import SOLID
from .mesh_source import build_mesh, regions_in_file
from .options import AleFsiOptions, solver_settings
from .sensitivities import TangentReport, vertex_tangents

__all__ = ["AleFsiForwardModel", "AleFsiOptions", "solver_settings"]


class AleFsiForwardModel(ForwardModelBase):
    """Monolithic ALE fluid-biofilm interaction (Paper A eq. 1-4, thesis eq. 2.14-2.30).

    Incompressible Navier-Stokes in ALE form in the fluid, a plane-strain hyperelastic solid
    (Saint Venant-Kirchhoff eq. 2.15 or neo-Hooke eq. 2.18, Lame parameters from E and nu by
    eq. 2.16), no-slip and traction balance on the interface, pseudo-solid mesh motion; solved
    monolithically by Newton's method with a direct solver (Pardiso).

    The default mesh (element size 0.03 mm on the interface, 0.06 mm inside the biofilm,
    0.12 mm in the channel; 4 846 unknowns) puts the largest interface displacement of Paper
    A's reference state within 0.19 % of a mesh with 3.4x the unknowns (observed order 1.9;
    ``benchmarks/bench_ale_fsi.py convergence``).

    Parameters (``parameter_names``): ``E`` [Pa], ``nu`` [-] -- or ``E_k``, ``nu_k`` per solid
    subdomain k = 1..n -- and ``inflow_rate`` [mm^2/s].  Inputs that are not given keep their
    option values.  A run that fails raises :class:`fbia.ForwardModelError` with a ``reason``
    tag: ``limit_point`` (the branch of steady states turns back below the requested inflow:
    no steady state there -- soft Saint Venant-Kirchhoff biofilms, whose compressed feet
    soften), ``newton_divergence`` (Newton and the continuation could not get further),
    ``ale_jacobian``/``solid_jacobian``/``element_quality`` (inverted or degenerate elements)
    or ``invalid_parameter``.
    """

    #: the extra it needs (fbia.core.extras)
    requires = ("ngsolve", "netgen")

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options
    #: the height above the substratum is y in every geometry (x along the flow, z across)
    up_axis = "y"

    Options = AleFsiOptions

    options: AleFsiOptions

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        self._solver: Any = None
        self._post: Any = None  # AleFsiPostprocess of the solver
        self._store: list[_Stored] = []
        self._run_states: list[_Stored] = []  # the states of the latest run
        self._regions: list[str] | None = None
        self._given_rate = False

    # -- protocol ----------------------------------------------------------------------------
    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        """Parameters and coordinates for conformance tests (Paper A's homogeneous example)."""
        return {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}]

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """Options of a cheap instance for conformance runs (a coarse mesh, ~1 800 dofs)."""
        return {"mesh_size": 0.2, "interface_mesh_size": 0.06}

    def solid_regions(self) -> list[str]:
        """Names of the solid regions (``solid`` or ``solid_1..n``), without meshing."""
        if self._regions is None:
            o = self.options
            if o.mesh_file is not None:
                self._regions = regions_in_file(Path(o.mesh_file))
            elif o.subdomains:
                self._regions = [f"{SOLID}_{k}" for k in range(1, len(o.subdomains) + 2)]
            else:
                self._regions = [SOLID]
        return self._regions

    def parameter_names(self) -> list[str]:
        regions = self.solid_regions()
        if regions == [SOLID]:
            return ["E", "nu", "inflow_rate"]
        names: list[str] = []
        for k in range(1, len(regions) + 1):
            names += [f"E_{k}", f"nu_{k}"]
        return names + ["inflow_rate"]

    def prepare(self) -> None:
        """Mesh and build the solver now (the isolation helper does it once before it forks
        a run process, which then starts meshed)."""
        self._get_solver()

    def warm_state(self) -> list[_Stored]:
        """The states this model instance solved in its latest run (for later runs in another
        process: :meth:`adopt_warm_state`)."""
        return list(self._run_states)

    def adopt_warm_state(self, state: list[_Stored]) -> None:
        """Warm-start later runs from states another process solved (:meth:`warm_state`)."""
        self._store.extend(state)
        del self._store[:-16]

    def tangent_inputs(self) -> list[str]:
        """The inputs whose tangents :meth:`solve` gives (quasi-static mode: every material
        input and the inflow rate; transient: none, iterators use finite differences)."""
        if self.options.mode != "quasi_static":
            return []
        return self.parameter_names()

    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Coordinate],
        workdir: Path,
        tangents: Sequence[str] = (),
    ) -> Solution:
        """Solve at every coordinate; raise :class:`ForwardModelError` if the run fails.

        ``tangents``: inputs whose d(vertices)/d(input) each interface carries in
        ``Interface.tangents`` (:mod:`~fbia.plugins.ale_fsi.sensitivities`)."""
        t_start = time.perf_counter()
        cpu_start = time.process_time()
        params = self._check_parameters(parameters)
        self._given_rate = "inflow_rate" in parameters
        levels = self._check_coordinates(coordinates, params)
        tangents = self._check_tangents(tangents, coordinates)
        self._run_states = []
        tangent_report = TangentReport()
        solver = self._get_solver()
        post = self._post
        solver.set_materials(self._materials(params))
        t_setup = time.perf_counter()
        n = len(coordinates)
        diag: dict[str, Any] = {}
        per: dict[str, list[Any]] = {"max_displacement": [None] * n, "fluid_force": [None] * n}
        if self.options.probes:
            per["probe_displacements"] = [None] * n
        curves: list[Any] = [None] * n
        fields: dict[str, Path] = {}
        workdir = Path(workdir)

        def record(label: str, index: int) -> None:
            """Check the current state and store its results for coordinate ``index``."""
            for key, val in solver.check_state(label).items():
                diag[key] = min(diag.get(key, math.inf), val)
            curves[index] = post.interface()
            if tangents:
                curves[index].tangents = vertex_tangents(solver, post, tangents, tangent_report)
            per["max_displacement"][index] = post.max_interface_displacement()
            per["fluid_force"][index] = post.forces().tolist()
            if self.options.probes:
                per["probe_displacements"][index] = [
                    post.point_displacement(p).tolist() for p in self.options.probes
                ]
            if self.options.write_vtu:
                from .output import write_vtu

                fields[f"vtu_{index}"] = write_vtu(solver, workdir / f"ale_fsi_{index:03d}.vtu")

        solver.timings = {"assembly": 0.0, "solve": 0.0}
        if self.options.mode == "quasi_static":
            iterations, jacobians, warm = self._quasi_static(
                solver, params, levels, record, tangent_report
            )
            diag["newton_iterations_per_coordinate"] = iterations
            diag["newton_iterations"] = int(sum(iterations))
            diag["jacobians"] = int(sum(jacobians))
            diag["warm_start"] = warm
        else:
            o = self.options

            def on_time(t: float) -> None:
                for i, ti in enumerate(levels):
                    if ti == t:
                        record(f"time {t:g} s", i)

            rep = solver.solve_transient(
                params["inflow_rate"],
                sorted(set(levels)),
                o.time_step,
                o.ramp_time,
                o.ramp_steps,
                on_time,
            )
            diag["newton_iterations"] = rep.iterations
            diag["jacobians"] = rep.jacobians
            diag["warm_start"] = False
        diag.update(per)
        if tangents:
            diag["tangents"] = {
                "inputs": list(tangents),
                "seconds": tangent_report.seconds,
                "refinements": tangent_report.refinements,
                "refactorised": tangent_report.refactorised,
            }
        pairs: list[tuple[Coordinate, Interface]] = list(zip(coordinates, curves, strict=True))
        diag.update(
            linear_solver=solver.linear_solver,
            native_code=solver.native.describe(),
            ndof=solver.ndof,
            elements=int(solver.mesh.ne),
            setup_time=t_setup - t_start,
            assembly_time=solver.timings["assembly"],
            solve_time=solver.timings["solve"],
            wall_time=time.perf_counter() - t_start,
            cpu_time=time.process_time() - cpu_start,
        )
        return Solution.from_pairs(pairs, fields=fields, diagnostics=diag)

    # -- internals ---------------------------------------------------------------------------
    def _check_parameters(self, parameters: Mapping[str, float]) -> dict[str, float]:
        names = self.parameter_names()
        allowed = set(names) | {"E", "nu"}
        unknown = [k for k in parameters if k not in allowed]
        if unknown:
            raise ConfigError(
                f"unknown parameter(s) {unknown}; valid: {', '.join(names)}", "ale_fsi.solve"
            )
        o = self.options
        params = {"E": o.E, "nu": o.nu, "inflow_rate": o.inflow_rate}
        params.update({k: float(v) for k, v in parameters.items()})
        for k, v in params.items():
            if not math.isfinite(v):
                raise ForwardModelError(f"parameter {k} is not finite ({v})", "invalid_parameter")
        return params

    def _check_tangents(
        self, tangents: Sequence[str], coordinates: Sequence[Coordinate]
    ) -> list[str]:
        where = "ale_fsi.solve: tangents"
        names = list(tangents)
        unknown = [n for n in names if n not in self.tangent_inputs()]
        if unknown:
            mode = "" if self.options.mode == "quasi_static" else " (transient mode gives none)"
            raise ConfigError(f"no tangents for {unknown}{mode}", where)
        if "inflow_rate" in names and any("inflow_rate" in c for c in coordinates):
            raise ConfigError("inflow_rate is a coordinate here, not an input", where)
        return names

    def _materials(self, params: dict[str, float]) -> dict[str, tuple[float, float]]:
        regions = self.solid_regions()
        out = {}
        for k, region in enumerate(regions, start=1):
            suffix = "" if region == SOLID else f"_{k}"
            E = params.get(f"E{suffix}", params["E"])
            nu = params.get(f"nu{suffix}", params["nu"])
            if not E > 0:
                raise ForwardModelError(f"E{suffix} = {E} Pa is not positive", "invalid_parameter")
            if not -1.0 < nu < 0.5:
                raise ForwardModelError(
                    f"nu{suffix} = {nu} is outside (-1, 0.5)", "invalid_parameter"
                )
            out[region] = (E, nu)
        return out

    def _check_coordinates(
        self, coordinates: Sequence[Coordinate], params: dict[str, float]
    ) -> list[float]:
        """Inflow level of each coordinate (quasi-static) or check the times (transient)."""
        where = "ale_fsi.solve: coordinates"
        if len(coordinates) == 0:
            raise ConfigError("no coordinates requested", where)
        if self._given_rate and any("inflow_rate" in c for c in coordinates):
            raise ConfigError(
                "inflow_rate is both a parameter and a coordinate; give it in one place", where
            )
        levels = []
        for c in coordinates:
            keys = set(c)
            if self.options.mode == "quasi_static":
                if not keys <= {"inflow_rate"}:
                    raise ConfigError(
                        f"quasi-static coordinates take only 'inflow_rate', got {sorted(keys)}",
                        where,
                    )
                levels.append(float(c.get("inflow_rate", params["inflow_rate"])))
            else:
                if keys != {"time"}:
                    raise ConfigError(
                        f"transient coordinates need exactly 'time', got {sorted(keys)}", where
                    )
                if float(c["time"]) < 0:
                    raise ConfigError(f"negative time {c['time']}", where)
                levels.append(float(c["time"]))
        return levels

    def _get_solver(self) -> Any:
        if self._solver is None:
            from .solver import AleFsiSolver

            mesh = self.build_mesh()
            _check_probes(mesh, self.options.probes)
            settings = solver_settings(self.options)
            try:
                self._solver = AleFsiSolver(mesh, settings)
            except ForwardModelError as exc:
                raise ConfigError(str(exc), "ale_fsi mesh") from None
            self._regions = self._solver.solids
            from .postprocess import AleFsiPostprocess

            self._post = AleFsiPostprocess(self._solver)
        return self._solver

    @property
    def dim(self) -> int:
        """The spatial dimension of the model's interfaces (2 or 3), from the options."""
        o = self.options
        if o.mesh_file is not None:
            from .mesh_file3d import is_3d_mesh_file

            return 3 if is_3d_mesh_file(o.mesh_file) else 2
        return 2 if o.geometry == "flow_cell" else 3

    def undeformed(self) -> Interface:
        """The unloaded interface (the mesh's reference configuration), vertex for vertex
        the one :meth:`solve` returns: the displacement of a vertex is the difference."""
        self._get_solver()
        interface: Interface = self._post.interface(deformed=False)
        return interface

    def build_mesh(self) -> Any:
        """The NGSolve mesh this model solves on (built or read on every call)."""
        return build_mesh(self.options)

    @property
    def solver(self) -> Any:
        """The underlying :class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver` (built lazily)."""
        return self._get_solver()

    @property
    def postprocess(self) -> Any:
        """Its :class:`~fbia.plugins.ale_fsi.postprocess.AleFsiPostprocess` (curves, fluxes,
        forces of the current state)."""
        self._get_solver()
        return self._post

    def _quasi_static(
        self,
        solver: Any,
        params: dict[str, float],
        levels: list[float],
        record: Any,
        tangents: TangentReport,
    ) -> tuple[list[int], list[int], bool]:
        """Continuation through the requested inflow levels (ascending |rate|).

        Returns the Newton iterations (chord steps included) and the Jacobian assemblies per
        coordinate, and whether a stored state of an earlier run served as warm start.  Each
        solved state is kept with its dU/dp (``tangents.state_tangents``, set by ``record``
        when tangents are asked for) for first-order warm starts of later runs; without
        tangents the first order comes from the nearest states (:func:`_secant`): on the 3-D
        dome the nearest state alone lies 0.04-0.08 from the solution in Newton's scaled norm,
        near the 0.1 a chord update could then take on trust, their secant 0.003-0.006
        (CHANGELOG).
        """
        order = sorted(range(len(levels)), key=lambda i: abs(levels[i]))
        iterations = [0] * len(levels)
        jacobians = [0] * len(levels)
        key = {k: v for k, v in params.items() if k != "inflow_rate"}
        warm_used = False
        earlier = list(self._store)  # states of earlier runs only
        solved: dict[float, NDArray[np.float64]] = {}
        for i in order:
            rate = levels[i]
            if rate in solved:
                solver.set_state(solved[rate])
                solver.inflow_rate.Set(rate)
                record(f"inflow rate {rate:g} mm^2/s", i)
                continue
            start = _nearest(earlier, key, rate) if self.options.warm_start else None
            # (start rate, state, continuation): the warm state first, without continuation;
            # then the cold path from this run's last level (or rest) with continuation
            attempts: list[tuple[float, NDArray[np.float64] | None, bool]] = []
            if start is not None:
                predicted = _predicted(start, key, rate)
                if predicted is None:  # first order through the nearest states
                    predicted = _secant(earlier, key, rate)
                if predicted is not None:  # first order in the inputs
                    solver.set_state(predicted)
                    if solver.admissible():
                        attempts.append((rate, predicted, False))
                attempts.append((start[1], start[2], False))
            if solved:
                last = max(solved, key=abs)
                attempts.append((last, solved[last], True))
            else:
                attempts.append((0.0, None, True))
            error: ForwardModelError | None = None
            for r0, x0, continuation in attempts:
                solver.set_state(x0)
                solver.inflow_rate.Set(r0)
                try:
                    # after a failed warm start Newton straight from the cold state would only
                    # fail again: follow the branch at once
                    rep = solver.solve_steady(rate, continuation=continuation, direct=error is None)
                    solver.check_state(f"inflow rate {rate:g} mm^2/s")
                except ForwardModelError as exc:
                    iterations[i] += getattr(exc, "iterations", 0)
                    error = exc
                    continue
                iterations[i] += rep.iterations
                jacobians[i] += rep.jacobians
                warm_used = warm_used or (start is not None and not continuation)
                error = None
                break
            if error is not None:
                raise error
            tangents.state_tangents = {}
            record(f"inflow rate {rate:g} mm^2/s", i)  # sets them when tangents are asked for
            solved[rate] = solver.state()
            self._remember(key, rate, solved[rate], tangents.state_tangents)
        return iterations, jacobians, warm_used

    def _remember(
        self,
        key: dict[str, float],
        rate: float,
        state: NDArray[np.float64],
        dstate: dict[str, NDArray[np.float64]],
    ) -> None:
        self._store.append((dict(key), rate, state, dstate))
        self._run_states.append(self._store[-1])
        del self._store[:-16]


def _check_probes(mesh: Any, probes: Sequence[tuple[float, ...]]) -> None:
    """Every probe has one coordinate per mesh dimension and lies in the (reference) mesh."""
    where = "ale_fsi options: probes"
    for p in probes:
        if len(p) != mesh.dim:
            raise ConfigError(f"probe {tuple(p)} needs {mesh.dim} coordinates on this mesh", where)
        if mesh(*(float(c) for c in p)).nr < 0:
            raise ConfigError(f"probe {tuple(p)} lies outside the mesh", where)


#: A stored state: (inputs, inflow rate, state, d state / d input of the inputs it has).
_Stored = tuple[dict[str, float], float, NDArray[np.float64], dict[str, NDArray[np.float64]]]


def _nearest(store: list[_Stored], key: dict[str, float], rate: float) -> _Stored | None:
    """The stored state nearest to (parameters, rate); distances relative per input."""
    best, best_d = None, math.inf
    for entry in store:
        d = _distance(entry[0], entry[1], key, rate)
        if d < best_d:
            best, best_d = entry, d
    return best


def _distance(k: dict[str, float], r: float, key: dict[str, float], rate: float) -> float:
    """How far a stored state's (inputs, rate) lie from (key, rate): relative per input."""
    d = sum(abs(k[n] - key[n]) / max(abs(k[n]), abs(key[n]), 1.0) for n in key)
    return d + abs(r - rate) / max(abs(r), abs(rate), 1.0)


#: The largest sum of |weights| of a secant prediction (:func:`_secant`): beyond it the states
#: lie too close together, or too far to one side, to extrapolate from.
SECANT_MAX_WEIGHT = 3.0


def _secant(store: list[_Stored], key: dict[str, float], rate: float) -> NDArray[np.float64] | None:
    """The state at ``key`` to first order through stored states at ``rate``, without their
    tangents: ``U_0 + sum_j c_j (U_j - U_0)`` over the nearest state ``U_0`` and the ``n``
    next nearest (``n``: the inputs in which those states and ``key`` differ), where
    ``(p_j - p_0) c = key - p_0`` in units relative to ``key`` (a secant in one input, the
    affine interpolant in several).  None when fewer states lie at ``rate``, when their
    inputs do not span the moved ones, or when the weights extrapolate far
    (:data:`SECANT_MAX_WEIGHT`)."""
    same = sorted(
        (e for e in store if e[1] == rate), key=lambda e: _distance(e[0], rate, key, rate)
    )
    moved = [n for n in key if any(e[0][n] != key[n] for e in same)]
    if not moved or len(same) < len(moved) + 1:
        return None
    base, others = same[0], same[1 : len(moved) + 1]
    scale = np.array([max(abs(key[n]), 1.0) for n in moved])
    p0 = np.array([base[0][n] for n in moved])
    steps = np.array([[e[0][n] for n in moved] for e in others]).T - p0[:, None]
    target = (np.array([key[n] for n in moved]) - p0) / scale
    matrix = steps / scale[:, None]
    if np.linalg.cond(matrix) > 1e6:
        return None
    weights = np.linalg.solve(matrix, target)
    if float(np.abs(weights).sum()) > SECANT_MAX_WEIGHT:
        return None
    x0 = base[2]
    return x0 + sum(w * (e[2] - x0) for w, e in zip(weights, others, strict=True))


def _predicted(start: _Stored, key: dict[str, float], rate: float) -> NDArray[np.float64] | None:
    """The stored state moved to ``key`` to first order, ``U + sum dU/dp (p - p0)``, where it
    has the tangents of every input that differs and lies at ``rate``; else None."""
    k, r, x, dstate = start
    moved = [n for n in key if key[n] != k[n]]
    if r != rate or not moved or not all(n in dstate for n in moved):
        return None
    return x + sum((key[n] - k[n]) * dstate[n] for n in moved)
