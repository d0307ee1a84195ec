"""Monolithic ALE fluid-solid interaction on NGSolve: spaces, weak forms, state, residual.

Unknowns on one mesh (reference configuration, Taylor-Hood for the fluid; 2-D meshes in plane
strain, 3-D meshes as they are -- the forms below are written for any dimension):

* ``v`` -- velocity, continuous over fluid *and* solid (P2): fluid velocity in the fluid, solid
  velocity in the solid, so the kinematic coupling (thesis eq. 2.28, Paper A eq. 4b) holds
  strongly;
* ``d`` -- displacement, continuous over fluid and solid (P2): solid displacement ``d^S`` in the
  solid, ALE mesh displacement ``d^G`` in the fluid, so eq. 2.30 holds strongly;
* ``p`` -- fluid pressure (P1, fluid only).

Transient mode: the fluid momentum (eq. 2.19a, pulled back to the reference configuration) and
the solid balance of momentum (eq. 2.25) are tested with the *same* test function ``phi``; the
interface integrals cancel and the traction balance (eq. 2.29, Paper A eq. 4a) holds weakly
without an interface term.  The second test function ``psi`` carries the solid kinematics
``dd/dt = v`` in the solid and the pseudo-solid mesh motion (harmonic or linear-elastic
extension, Jacobian-stiffened) in the fluid, weighted by a tiny factor so that it does not
disturb the interface rows.

Quasi-static mode: the solid is at rest, so ``v = 0`` on the solid and on the interface
(eq. 2.28) and those velocity dofs (about a third of all) are dropped from the Newton system.
The solid balance is tested with ``psi`` instead, and the fluid momentum rows of the interface
nodes are added to the ``psi`` rows of the same nodes -- the discrete form of eq. 2.29: solid
stress + fluid traction = 0 at every interface node, exactly what the shared test function
gives in transient mode.  The mesh-motion operator is linear in ``d`` with coefficients fixed
on the reference mesh, so it is assembled once and added to every Jacobian.

:class:`AleFsiProblem` is the discrete problem (what :class:`~fbia.plugins.fem.newton.NewtonSolver`
and :class:`~fbia.plugins.fem.continuation.ArclengthContinuation` need);
:class:`~fbia.plugins.ale_fsi.solver.AleFsiSolver` adds the solution algorithms.

>>> from fbia.plugins.fem.flow_cell import build_flow_cell
>>> from fbia.plugins.ale_fsi.solver import AleFsiSolver, SolverSettings
>>> solver = AleFsiSolver(build_flow_cell(mesh_size=0.2), SolverSettings())  # doctest: +SKIP
>>> solver.set_materials({"solid": (400.0, 0.3)})                             # doctest: +SKIP
>>> report = solver.solve_steady(100.0)                                       # doctest: +SKIP
>>> from fbia.plugins.ale_fsi.postprocess import AleFsiPostprocess
>>> curves = AleFsiPostprocess(solver).interface_curves()                     # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.flow_cell import FLUID, solid_regions
from ..fem.native import NativeCode, compile_integrand
from .boundaries import InflowFace, inflow_of, mesh_dirichlet, symmetry_axis
from .checks import StateChecks
from .materials import lame, stress_pk2

if TYPE_CHECKING:
    import ngsolve


@dataclass(frozen=True)
class SolverSettings:
    """Physics and numerics of :class:`AleFsiSolver` (units mm, s, g; stresses in Pa)."""

    fluid_density: float = 1e-3  # g/mm^3
    fluid_viscosity: float = 1e-3  # g/(mm s)
    solid_density: float = 1e-3  # g/mm^3
    material: str = "svk"  # "svk" (eq. 2.15) | "neo_hooke" (eq. 2.18)
    gravity: tuple[float, ...] = (0.0, 0.0)  # mm/s^2, on the solid only; 3-D: padded with 0
    outflow: str = "horizontal"  # "horizontal" (v_y = 0, traction-free in x) | "do_nothing"
    mesh_motion: str = "harmonic"  # "harmonic" | "elastic"
    mesh_stiffening: float = 1.0  # exponent chi of the Jacobian-based stiffening
    mesh_weight: float = 1e-8  # weight of the mesh-motion operator (a stiffness, Pa)
    mesh_slip: bool = True  # mesh slides along straight walls/inflow/outflow (eq. 2.24)
    motion_layer: float | None = None  # mm; the mesh moves only this near the interface
    motion_order: int | None = None  # 1: a piecewise-linear mesh motion in the fluid; None: order
    order: int = 2  # velocity/displacement order (pressure: order - 1)
    newton_tol: float = 1e-8  # scaled Newton correction
    newton_max_iter: int = 12  # Jacobian assemblies per Newton solve (chord steps extra)
    continuation_min_fraction: float = 1.0 / 16.0  # smallest continuation step / first step
    min_det_f: float = 0.01  # smallest admissible det F (ALE map and solid)
    min_quality: float = 0.02  # smallest admissible deformed fluid element quality
    theta: float = 1.0  # one-step-theta
    linear_solver: str = "direct"  # "direct" (Pardiso) | "block_gmres" (fem.krylov)
    threads: int = 1
    native_code: bool = True  # integrands compiled to machine code (fem.native)


class AleFsiProblem:
    """Spaces, forms, state and residual of the monolithic ALE FSI problem on one mesh.

    Parameters
    ----------
    mesh
        A mesh named per :mod:`fbia.plugins.fem.flow_cell`.
    settings
        Physics and numerics.
    """

    def __init__(self, mesh: ngsolve.Mesh, settings: SolverSettings) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.mesh = mesh
        self.settings = s = settings
        ngs.SetNumThreads(max(1, int(s.threads)))
        self.solids = solid_regions(mesh)
        self.dim = dim = int(mesh.dim)
        bnds = set(mesh.GetBoundaries())
        self._has = {b: b in bnds for b in ("outflow", "walls", "obstacle", "inflow")}
        self.inflow = inflow_of(mesh)
        self.length_scale = self.inflow.width

        # -- spaces: velocity and displacement continuous over the whole mesh (see module doc)
        noslip = "|".join(b for b in ("walls", "obstacle", "solid_fixed") if b in bnds)
        vx = "|".join(x for x in ("inflow", noslip) if x)
        v_fixed = [vx] * dim
        if s.outflow == "horizontal":  # the tangential velocity vanishes on the outflow
            v_fixed[1:] = ["|".join(x for x in (vx, "outflow") if x)] * (dim - 1)
        elif s.outflow != "do_nothing":
            raise ValueError(f"unknown outflow condition {s.outflow!r}")
        if "symmetry" in bnds:  # symmetry walls: no normal velocity
            k = symmetry_axis(mesh)
            v_fixed[k] = "|".join(x for x in (v_fixed[k], "symmetry") if x)
        xyz = ("dirichletx", "dirichlety", "dirichletz")
        V = ngs.VectorH1(mesh, order=s.order, **dict(zip(xyz, v_fixed, strict=False)))
        d_fixed = mesh_dirichlet(mesh, s.mesh_slip)
        D = ngs.VectorH1(mesh, order=s.order, **dict(zip(xyz, d_fixed, strict=False)))
        Q = ngs.H1(mesh, order=s.order - 1, definedon=FLUID)
        self.fes = ngs.FESpace([V, D, Q])
        self.gfu = ngs.GridFunction(self.fes)
        self.gfu_old = ngs.GridFunction(self.fes)  # previous time step
        self.velocity, self.displacement, self.pressure = self.gfu.components

        # -- coefficients that change between runs without recompiling the forms
        self.inflow_rate = ngs.Parameter(0.0)
        self.dt = ngs.Parameter(1.0)
        self._mu = {r: ngs.Parameter(1.0) for r in self.solids}
        self._lam = {r: ngs.Parameter(1.0) for r in self.solids}
        self.transient = False
        self._fluid_parts = self._motion_layer(s.motion_layer)
        self._build_motion()
        self._build_forms(transient=False)
        self._det_points = mesh.MapToAllElements(self._check_rule(dim), ngs.VOL)
        self._region_of_point = mesh.MaterialCF({FLUID: 1.0}, default=0.0)(self._det_points)[
            :, 0
        ].astype(bool)
        self.materials: dict[str, tuple[float, float]] = {}
        self._checks = StateChecks(self)
        self._dxd_rate: NDArray[np.float64] | None = None  # see load_direction

    # -- set-up ------------------------------------------------------------------------------
    @staticmethod
    def _check_rule(dim: int = 2) -> Any:
        """Vertices, edge midpoints and centroid of the reference triangle / tetrahedron."""
        import ngsolve as ngs

        if dim == 2:
            pts = [(0, 0), (1, 0), (0, 1), (0.5, 0), (0.5, 0.5), (0, 0.5), (1 / 3, 1 / 3)]
        else:
            corners = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)], dtype=float)
            mids = [(corners[i] + corners[j]) / 2 for i in range(4) for j in range(i + 1, 4)]
            pts = [tuple(p) for p in [*corners, *mids, corners.mean(axis=0)]]
        return ngs.IntegrationRule(pts, [0.0] * len(pts))

    def _motion_layer(self, layer: float | None) -> tuple[Any, Any]:
        """The fluid elements whose mesh moves and those whose mesh stays fixed (NGSolve
        BitArrays over all elements; ``(None, None)``: the whole fluid moves).

        With ``layer`` (mm) the ALE mesh displacement lives only on the fluid elements with a
        vertex within ``layer`` of an interface vertex (those touching the interface always);
        the displacement dofs of every other fluid element, and so of the layer's outer
        boundary, are fixed at zero (:meth:`_set_free_dofs`) and those elements are assembled
        on the reference geometry, F = I.  The ALE extension is arbitrary (eq. 2.24 asks only
        that it follow the interface and keep the mesh valid), so the solution changes at the
        size of the discretisation error; the unknowns and the Jacobian's entries that couple
        the flow to the mesh motion go.  The layer must be thick enough for the mesh to take
        the interface's displacement: a fold shows as det F <= ``min_det_f`` (a failed run).
        """
        if layer is None:
            return None, None
        ngs = self.ngs
        mesh = self.mesh
        on_interface = np.zeros(mesh.nv, dtype=bool)
        for el in mesh.Elements(ngs.BND):
            if el.mat == "interface":
                on_interface[[v.nr for v in el.vertices]] = True
        if not on_interface.any():
            raise ForwardModelError(
                "mesh_motion_layer: the mesh has no interface boundary", "bad_mesh"
            )
        from scipy.spatial import cKDTree

        points = np.array([v.point for v in mesh.vertices], dtype=float)
        near, _ = cKDTree(points[on_interface]).query(points, distance_upper_bound=layer)
        near_vertex = np.isfinite(near)  # inf beyond the bound
        moving, fixed = ngs.BitArray(mesh.ne), ngs.BitArray(mesh.ne)
        moving.Clear()
        fixed.Clear()
        for el in mesh.Elements(ngs.VOL):
            if el.mat != FLUID:
                continue
            if near_vertex[[v.nr for v in el.vertices]].any():
                moving.Set(el.nr)
            else:
                fixed.Set(el.nr)
        return moving, fixed

    def _build_forms(self, transient: bool) -> None:
        """The residual of the coupled problem (thesis eqs. 2.19-2.30) as one nonlinear form.

        Transient: one-step-theta, ``M (x - x_old)/dt + theta A(x) + (1 - theta) A(x_old)``
        for the viscous, convective and elastic terms, the pressure, the incompressibility and
        the mesh motion implicit; the ALE convective velocity ``c = v - (d - d_old)/dt``.
        Quasi-static: the solid at rest, its balance tested with ``psi`` (module docstring).
        """
        ngs = self.ngs
        s = self.settings
        (v, d, p), (phi, psi, q) = self.fes.TnT()
        I2 = ngs.Id(self.dim)
        rho_f, mu_f, rho_s = s.fluid_density, s.fluid_viscosity, s.solid_density
        v_old, d_old, _ = self.gfu_old.components
        theta = s.theta if transient else 1.0
        outcomes: list[NativeCode] = []  # of each integrand (fem.native)

        def fluid_integrand(disp: Any, disp_old: Any) -> Any:
            """Eq. 2.19 pulled back by the ALE map of ``disp`` (None: the mesh does not move,
            F = I, as beyond the motion layer)."""
            moves = disp is not None
            mesh_velocity = (disp - disp_old) / self.dt if transient and moves else None

            def kinematics(dd: Any) -> tuple[Any, Any, Any]:
                if dd is None:
                    return I2, 1.0, I2
                F = I2 + ngs.Grad(dd)
                return F, ngs.Det(F), ngs.Inv(F)

            def fluid_terms(vv: Any, dd: Any) -> Any:
                """Viscous and convective terms of eq. 2.19a on the reference domain."""
                F, J, Finv = kinematics(dd)
                grad_v = ngs.Grad(vv) * Finv  # spatial velocity gradient
                sigma_v = mu_f * (grad_v + grad_v.trans)  # eq. 2.20-2.21 without the pressure
                c = vv if mesh_velocity is None else vv - mesh_velocity  # ALE convective vel.
                return J * ngs.InnerProduct(sigma_v * Finv.trans, ngs.Grad(phi)) + rho_f * J * (
                    ngs.InnerProduct(grad_v * c, phi)
                )

            F, J, Finv = kinematics(disp)
            fluid = theta * fluid_terms(v, disp)
            fluid += -p * J * ngs.InnerProduct(Finv.trans, ngs.Grad(phi))  # pressure, implicit
            fluid += -J * ngs.Trace(ngs.Grad(v) * Finv) * q  # eq. 2.19b
            if transient:
                fluid += rho_f * J * ngs.InnerProduct((v - v_old) / self.dt, phi)
                if theta < 1.0:
                    fluid += (1.0 - theta) * fluid_terms(v_old, disp_old)
            compiled, outcome = compile_integrand(fluid, s.native_code)
            outcomes.append(outcome)
            return compiled

        self._fluid_form = ngs.BilinearForm(self.fes, symmetric=False)
        form = ngs.BilinearForm(self.fes, symmetric=False)
        moving, fixed = self._fluid_parts
        parts = [(fluid_integrand(d, d_old), moving)]
        if fixed is not None:
            parts.append((fluid_integrand(None, None), fixed))
        for integrand, elements in parts:
            where = ngs.dx(FLUID) if elements is None else ngs.dx(FLUID, definedonelements=elements)
            self._fluid_form += integrand * where
            form += integrand * where  # the mesh motion is added as a fixed matrix
        # the solid's terms alone as well: the only ones that depend on the Lame constants
        self._solid_form = ngs.BilinearForm(self.fes, symmetric=False)
        gravity = [float(c) for c in s.gravity][: self.dim]
        g = ngs.CoefficientFunction(tuple(gravity + [0.0] * (self.dim - len(gravity))))
        for region in self.solids:
            mu, lam = self._mu[region], self._lam[region]

            def solid_terms(dd: Any, test: Any, mu: Any = mu, lam: Any = lam) -> Any:
                """First Piola-Kirchhoff stress F S (eq. 2.25) and the body force."""
                Fd = I2 + ngs.Grad(dd)
                S = stress_pk2(s.material, Fd, mu, lam)
                return ngs.InnerProduct(Fd * S, ngs.Grad(test)) - rho_s * ngs.InnerProduct(g, test)

            if transient:
                solid = theta * solid_terms(d, phi)
                # eq. 2.25 and dd/dt = v, both by one-step-theta
                solid += rho_s * ngs.InnerProduct((v - v_old) / self.dt, phi)
                v_mid = theta * v + (1.0 - theta) * v_old
                solid += ngs.InnerProduct((d - d_old) / self.dt - v_mid, psi)
                if theta < 1.0:
                    solid += (1.0 - theta) * solid_terms(d_old, phi)
                bonus = 0
            else:
                # at rest: the solid balance in the psi rows (see the module docstring).  NGSolve
                # picks the quadrature order from the proxies' orders (here only gradients: 2);
                # +2 gives the order of the transient form (4: the SVK integrand on straight P2
                # elements exactly), so that both modes solve the same discrete problem.
                solid = solid_terms(d, psi)
                bonus = 2
            compiled, outcome = compile_integrand(solid, s.native_code)
            outcomes.append(outcome)
            form += compiled * ngs.dx(region, bonus_intorder=bonus)
            self._solid_form += compiled * ngs.dx(region, bonus_intorder=bonus)
        self.form = form
        self.transient = transient
        #: how the integrands were compiled (``native_code``; fem.native)
        self.native = NativeCode.of_all(outcomes)
        self._on_new_forms()
        self._positions: dict[str, Any] | None = None  # CSR positions, after the 1st assembly
        self._set_free_dofs(transient)

    def _build_motion(self) -> None:
        """The pseudo-solid mesh-motion operator (linear in d, fixed coefficients), assembled once.

        Harmonic or linear-elastic extension of the displacement into the fluid, stiffened by the
        inverse reference element area (Jacobian-based stiffening, exponent ``mesh_stiffening``)
        and weighted by ``mesh_weight`` so that it does not disturb the interface rows.
        """
        ngs = self.ngs
        s = self.settings
        mesh = self.mesh
        d, psi = self.fes.TrialFunction()[1], self.fes.TestFunction()[1]
        area = ngs.GridFunction(ngs.L2(mesh, order=0))
        vols = np.asarray(ngs.Integrate(1.0, mesh, element_wise=True))
        area.vec.FV().NumPy()[:] = vols
        stiff = s.mesh_weight * (float(vols.max()) / area) ** s.mesh_stiffening
        if s.mesh_motion == "harmonic":
            motion = stiff * ngs.InnerProduct(ngs.Grad(d), ngs.Grad(psi))
        elif s.mesh_motion == "elastic":
            eps_d = ngs.Sym(ngs.Grad(d))
            motion = stiff * (
                2.0 * ngs.InnerProduct(eps_d, ngs.Sym(ngs.Grad(psi)))
                + ngs.Trace(eps_d) * ngs.div(psi)
            )
        else:
            raise ValueError(f"unknown mesh motion {s.mesh_motion!r}")
        self._area = area
        self._motion = ngs.BilinearForm(self.fes, symmetric=False)
        moving = self._fluid_parts[0]
        self._motion += motion * (
            ngs.dx(FLUID) if moving is None else ngs.dx(FLUID, definedonelements=moving)
        )
        self._motion.Assemble()

    def _set_free_dofs(self, transient: bool) -> None:
        """Free dofs of the Newton system; quasi-static: without the velocity on the solid."""
        ngs = self.ngs
        free = np.array(self.fes.FreeDofs(), dtype=bool)
        r_v, r_d = self.fes.Range(0), self.fes.Range(1)
        V = self.fes.components[0]
        solid_v = np.flatnonzero(np.array(V.GetDofs(self.mesh.Materials("|".join(self.solids)))))
        self._v_solid = r_v.start + solid_v  # velocity dofs of the solid (interface included)
        if not transient:
            free[self._v_solid] = False
        fixed = self._fluid_parts[1]
        if fixed is not None:  # the mesh beyond the motion layer stays where it is
            D = self.fes.components[1]
            on_fixed = np.zeros(D.ndof, dtype=bool)
            for nr in np.flatnonzero(np.array(fixed, dtype=bool)):
                dofs = [k for k in D.GetDofNrs(ngs.ElementId(ngs.VOL, int(nr))) if k >= 0]
                on_fixed[dofs] = True
            free[r_d.start + np.flatnonzero(on_fixed)] = False
        if self.settings.motion_order == 1 and self.settings.order > 1:
            free[r_d.start + self._high_order_fluid_motion()] = False
        # interface dofs whose displacement is free: their fluid-momentum rows (phi) are added
        # to their displacement rows (psi) in quasi-static mode
        iface = np.flatnonzero(np.array(V.GetDofs(self.mesh.Boundaries("interface"))))
        iface = iface[free[r_d.start + iface]]
        self._iface_rows = (r_v.start + iface, r_d.start + iface)
        self._free_np = free
        self._free = ngs.BitArray(free.tolist())

    def _high_order_fluid_motion(self) -> NDArray[np.int64]:
        """The displacement's edge and face unknowns that belong to no solid element.

        Fixed at zero (``mesh_motion_order = 1``), they leave the ALE map in the fluid
        piecewise linear, except along the edges and faces it shares with the solid, which keep
        the full order: the interface moves with the solid's displacement exactly as before.
        NGSolve's H1 basis is hierarchical (vertex hats, then edge and face bubbles), so fixing
        the bubbles is the same as a lower-order space away from the solid.  Like the layer's,
        the extension is arbitrary (eq. 2.24): the solution moves at the size of the
        discretisation error, and the factorisation loses the unknowns.
        """
        ngs = self.ngs
        D = self.fes.components[1]
        keep = np.zeros(D.ndof, dtype=bool)
        keep[np.array(D.GetDofs(self.mesh.Materials("|".join(self.solids))), dtype=bool)] = True
        for v in self.mesh.vertices:
            keep[[k for k in D.GetDofNrs(ngs.NodeId(ngs.VERTEX, v.nr)) if k >= 0]] = True
        return np.flatnonzero(~keep)

    # -- parameters and state ----------------------------------------------------------------
    def set_materials(self, materials: dict[str, tuple[float, float]]) -> None:
        """Young's modulus (Pa) and Poisson's ratio per solid region (eq. 2.16)."""
        for region in self.solids:
            E, nu = materials[region]
            mu, lam = lame(E, nu)
            self._mu[region].Set(mu)
            self._lam[region].Set(lam)
        self.materials = dict(materials)

    def lame_parameter(self, region: str, which: str) -> Any:
        """The NGSolve ``Parameter`` of a solid region's Lamé constant ``which`` (``"mu"`` or
        ``"lam"``), which :meth:`set_materials` sets and the tangents perturb; the residual
        is linear in each (:mod:`fbia.plugins.ale_fsi.sensitivities`)."""
        return (self._mu if which == "mu" else self._lam)[region]

    def preconditioner_blocks(self) -> list[Any]:
        """Free dofs of the displacement block, then of the fluid block (velocity, pressure):
        the blocks of the Gauss-Seidel preconditioner of ``linear_solver = "block_gmres"``."""
        out = []
        for fields in ((1,), (0, 2)):
            mask = np.zeros_like(self._free_np)
            for i in fields:
                r = self.fes.Range(i)
                mask[r.start : r.stop] = True
            out.append(self.ngs.BitArray((mask & self._free_np).tolist()))
        return out

    @property
    def ndof(self) -> int:
        """Unknowns of the Newton system (quasi-static: without the solid's velocity)."""
        return int(self._free_np.sum())

    def state(self) -> NDArray[np.float64]:
        """A copy of the solution vector (velocity, displacement, pressure dofs)."""
        return np.array(self.gfu.vec.FV().NumPy(), copy=True)

    def set_state(self, vec: NDArray[np.float64] | None) -> None:
        if vec is None:
            self.gfu.vec[:] = 0.0
        else:
            self.gfu.vec.FV().NumPy()[:] = vec

    def set_inflow(self, rate: float) -> None:
        """Set the inflow Dirichlet values; every other dof is left untouched (warm starts)."""
        ngs = self.ngs
        V = self.fes.components[0]
        tmp = ngs.GridFunction(V)
        tmp.Set(self.inflow.profile(rate), definedon=self.mesh.Boundaries("inflow"))
        dofs = np.flatnonzero(np.array(V.GetDofs(self.mesh.Boundaries("inflow")), dtype=bool))
        self.velocity.vec.FV().NumPy()[dofs] = tmp.vec.FV().NumPy()[dofs]
        self.inflow_rate.Set(rate)

    def fill_with_inflow(self) -> None:
        """Set the fluid's free velocity unknowns to the inflow profile at the current rate,
        carried unchanged along the flow (``inflow.carried``: the profile depends on the
        cross-section's coordinates only, Poiseuille flow in a straight duct, zero beside the
        inflow's span); the solid's velocity, the walls' (where the profile vanishes) and every
        other unknown are left as they are.  A start for Newton's method from rest in a 3-D
        cell (:meth:`fbia.plugins.ale_fsi.solver.AleFsiSolver.newton`)."""
        if not isinstance(self.inflow, InflowFace):
            raise ValueError("fill_with_inflow needs a 3-D cell's inflow face")
        ngs = self.ngs
        V = self.fes.components[0]
        tmp = ngs.GridFunction(V)
        tmp.Set(
            self.inflow.carried(float(self.inflow_rate.Get())),
            definedon=self.mesh.Materials(FLUID),
        )
        r = self.fes.Range(0)
        free = self._free_np[r.start : r.stop]
        self.gfu.vec.FV().NumPy()[r.start : r.stop][free] = tmp.vec.FV().NumPy()[free]

    # -- checks ------------------------------------------------------------------------------
    def min_det_f(self) -> tuple[float, float]:
        """Smallest det F of the ALE map (fluid) and of the solid deformation.

        Evaluated at the vertices, edge midpoints and centroid of every element, where the
        quadratic polynomial det F of a P2 displacement takes its characteristic values.
        """
        ngs = self.ngs
        detf = ngs.Det(ngs.Id(self.dim) + ngs.Grad(self.displacement))
        vals = np.asarray(detf(self._det_points))[:, 0]
        fl = self._region_of_point
        return float(vals[fl].min()), float(vals[~fl].min())

    def check_state(self, where: str) -> dict[str, float]:
        """Raise :class:`ForwardModelError` unless the current state is admissible; the
        figures it checked (see :class:`~fbia.plugins.ale_fsi.checks.StateChecks`)."""
        return self._checks.check(where)

    # -- Newton ------------------------------------------------------------------------------
    def scales(self) -> NDArray[np.float64]:
        """Per-dof scales of the Newton correction: velocity, displacement and pressure.

        Each field's largest value, at least a physical floor: the mean inflow speed, its
        dynamic plus viscous pressure, and for the displacement 1e-6 of the inflow width -- far
        below any resolvable deformation, yet above the rounding noise of a nearly rigid solid
        (Turek-Hron CFD1, E = 1e15 Pa, moves 3e-9 mm).
        """
        s = self.settings
        w = self.length_scale
        u_ref = abs(self.inflow.mean_speed(float(self.inflow_rate.Get()))) + 1e-9 * w  # mm/s
        p_ref = s.fluid_density * u_ref**2 + s.fluid_viscosity * u_ref / w + 1e-12
        x = self.gfu.vec.FV().NumPy()
        out = np.empty_like(x)
        for i, floor in enumerate((u_ref, 1e-6 * w, p_ref)):
            r = self.fes.Range(i)
            block = np.abs(x[r.start : r.stop])
            out[r.start : r.stop] = max(float(block.max(initial=0.0)), floor)
        return out

    def _csr_positions(self) -> dict[str, Any]:
        """Where the mesh-motion entries and the interface row sums go in the Jacobian's CSR.

        Of the mesh motion (displacement rows and columns only) just the entries that couple
        two free dofs: the fixed displacement dofs are zero in every vector the solvers
        multiply the Jacobian with (updates, tangents, the load direction, which moves inflow
        velocities only), and the factorisation reads the free block.  With the linear mesh
        motion most of the motion's entries are in the fluid's fixed edge and face unknowns
        (the 3-D dome's recommended settings: 1.5 M of 6.4 M entries kept; with the pattern's
        column indices read in place, the positions 0.28-0.34 s instead of 1.2 s).  The interface
        row sums keep every column: a velocity row may couple to a Dirichlet inflow dof, on
        which the load direction is not zero."""
        if self._positions is None:
            mat = self.form.mat
            free = self._free_np
            # the column indices as NGSolve stores them (int32: a copy of 21.6 M as int64 alone
            # took 0.17 s), the row pointers as int64
            _, cols, ptr = (np.asarray(a) for a in mat.CSR())
            ptr = ptr.astype(np.int64)
            shape = (mat.height, mat.width)
            _, mcols, mptr = (np.asarray(a) for a in self._motion.mat.CSR())
            mptr = mptr.astype(np.int64)
            mrows = np.repeat(np.arange(self._motion.mat.height, dtype=np.int64), np.diff(mptr))
            keep = np.flatnonzero(free[mrows] & free[mcols])
            pos = {"motion_entries": keep}
            pos["motion"] = csr_positions(ptr, cols, shape, mrows[keep], mcols[keep])
            if not self.transient:
                src_rows, dst_rows = self._iface_rows
                counts = ptr[src_rows + 1] - ptr[src_rows]
                starts = np.repeat(ptr[src_rows] - np.cumsum(counts) + counts, counts)
                src = starts + np.arange(int(counts.sum()), dtype=np.int64)
                pos["iface_src"] = src
                dst = np.repeat(dst_rows, counts)
                pos["iface_dst"] = csr_positions(ptr, cols, shape, dst, cols[src])
            self._positions = pos
        return self._positions

    def residual(self, res: Any) -> None:
        """The residual of the Newton system at the current state, into ``res``."""
        with self.ngs.TaskManager():
            self.form.Apply(self.gfu.vec, res)
        self._motion.mat.MultAdd(1.0, self.gfu.vec, res)
        if not self.transient:
            r = res.FV().NumPy()
            src, dst = self._iface_rows
            r[dst] += r[src]

    def solid_residual(self, res: Any) -> None:
        """The solid regions' terms of the residual alone, into ``res``: every term that
        depends on the Lame constants (the fluid, the mesh motion and the interface row sums
        do not), for the tangents' dR/dmu and dR/dlambda at a fraction of a residual's cost."""
        with self.ngs.TaskManager():
            self._solid_form.Apply(self.gfu.vec, res)

    def assemble_jacobian(self) -> None:
        """Assemble the consistent Jacobian at the current state into ``self.form.mat``."""
        with self.ngs.TaskManager():
            self.form.AssembleLinearization(self.gfu.vec)
        pos = self._csr_positions()
        data = self.form.mat.AsVector().FV().NumPy()
        data[pos["motion"]] += self._motion.mat.AsVector().FV().NumPy()[pos["motion_entries"]]
        if not self.transient:
            data[pos["iface_dst"]] += data[pos["iface_src"]]

    # -- what NewtonSolver needs (fbia.plugins.fem.newton.NonlinearSystem) ----------------------
    @property
    def vector(self) -> Any:
        return self.gfu.vec

    @property
    def matrix(self) -> Any:
        return self.form.mat

    @property
    def free(self) -> Any:
        return self._free

    @property
    def free_mask(self) -> NDArray[np.bool_]:
        return self._free_np

    def admissible(self) -> bool:
        """No element of the ALE map or of the solid is inverted (det F > 0)."""
        return min(self.min_det_f()) > 0.0

    # -- what ArclengthContinuation needs (fbia.plugins.fem.continuation.LoadedSystem) -------
    @property
    def load(self) -> float:
        """The inflow rate (mm^2/s)."""
        return float(self.inflow_rate.Get())

    def set_load(self, value: float) -> None:
        self.set_inflow(value)

    def field_blocks(self) -> list[slice]:
        """Velocity, displacement and pressure dofs."""
        return [slice(self.fes.Range(i).start, self.fes.Range(i).stop) for i in range(3)]

    def load_direction(self) -> NDArray[np.float64]:
        """Derivative of the state's Dirichlet values with respect to the inflow rate."""
        if self._dxd_rate is None:
            x = self.state()
            rate = float(self.inflow_rate.Get())
            self.gfu.vec[:] = 0.0
            self.set_inflow(1.0)
            self._dxd_rate = self.state()
            self.set_state(x)
            self.inflow_rate.Set(rate)
        return self._dxd_rate

    def failure_note(self) -> str:
        """Where the current state compresses the solid most (for failure messages)."""
        ngs = self.ngs
        detf = ngs.Det(ngs.Id(self.dim) + ngs.Grad(self.displacement))
        vals = np.asarray(detf(self._det_points))[:, 0]
        solid = np.flatnonzero(~self._region_of_point)
        k = solid[np.argmin(vals[solid])]
        at = ", ".join(
            f"{float(np.asarray(c(self._det_points)).ravel()[k]):.3f}"
            for c in (ngs.x, ngs.y, ngs.z)[: self.dim]
        )
        note = f"the solid is compressed to det F = {vals[k]:.2g} at ({at}) mm"
        if self.settings.material == "svk" and vals[k] < 1.0 / 3.0:
            # plane strain SVK under volumetric compression F = s I: P = (lam + mu)(s^2 - 1) s
            # has its extremum at s^2 = det F = 1/3; below it the material softens
            note += " (Saint Venant-Kirchhoff softens under compression beyond det F = 1/3)"
        return note

    def _on_new_forms(self) -> None:
        """Called when the forms (or the free dofs) change: a solver drops its factorisation."""


def csr_positions(
    ptr: NDArray[np.int64],
    cols: NDArray[np.integer[Any]],
    shape: tuple[int, int],
    rows: NDArray[np.int64],
    wanted: NDArray[np.int64],
) -> NDArray[np.int64]:
    """The positions in a CSR pattern (``ptr``, ``cols``) of the entries (``rows[k]``,
    ``wanted[k]``), in the order given; a RuntimeError if one is not in the pattern.

    scipy's element-wise product of the pattern (its entries numbered) with the wanted
    entries does the search in compiled code, on the rows asked for only: 0.13 s against
    1.6 s of ``np.searchsorted`` over row-major keys for the 3-D dome's 6.4 M mesh-motion
    entries in 21.6 M; the 0.5 M entries of the interface rows 0.04 s against 0.18 s when
    the product ran over the whole pattern (one thread).
    """
    import scipy.sparse as sp

    sel = np.unique(rows)  # the rows asked for, and their entries in the pattern
    counts = ptr[sel + 1] - ptr[sel]
    sub_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    entry = np.repeat(ptr[sel] - sub_ptr[:-1], counts) + np.arange(sub_ptr[-1], dtype=np.int64)
    sub_shape = (len(sel), shape[1])
    numbered = sp.csr_matrix(
        (np.arange(1, len(entry) + 1, dtype=np.float64), cols[entry], sub_ptr), shape=sub_shape
    )
    query = sp.coo_matrix(
        (
            np.arange(1, len(rows) + 1, dtype=np.float64),
            (np.searchsorted(sel, rows), wanted),
        ),
        shape=sub_shape,
    ).tocsr()
    query.sort_indices()
    found = numbered.multiply(query.astype(bool)).tocsr()
    found.sort_indices()
    if (
        query.nnz != len(rows)
        or found.nnz != query.nnz
        or not np.array_equal(found.indices, query.indices)
        or not np.array_equal(found.indptr, query.indptr)
    ):
        raise RuntimeError("ale_fsi: unexpected sparsity pattern of the Jacobian")
    out = np.empty(len(rows), dtype=np.int64)
    out[query.data.astype(np.int64) - 1] = entry[found.data.astype(np.int64) - 1]
    return out
