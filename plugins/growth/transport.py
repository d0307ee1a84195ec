"""Nutrient transport on the ALE mesh of ``ale_fsi`` (Paper A, eq. 5-8).

One continuous scalar Phi [mol/mm^3] (H1, order 2 by default) on the whole mesh, with
piecewise coefficients:

* fluid (eq. 5a): ``dPhi/dt|_X + c . grad Phi - div(D_fluid grad Phi) = 0`` with the ALE
  convective velocity ``c = v - w`` (v: fluid velocity, w: mesh velocity);
* biofilm (eq. 5b): ``dPhi/dt|_X + Phi div w - div(D_biofilm grad Phi) + R(Phi) = 0``; the
  mesh moves with the biofilm there (w = v^S), so the ALE time derivative is the material one,
  and the Monod consumption of eq. 6 is ``R = K1R Phi / (K2R + |Phi|)``: the discrete Phi may
  undershoot zero by a little where the biofilm consumes it all, and R then stays defined,
  bounded and smooth (C^1), with the sign that pulls Phi back to zero.  (``max(Phi, 0)``
  instead leaves R flat below zero, and Newton cycles across that kink.);
* continuity of value and flux across the interface (eq. 8) is natural for one continuous
  field; ``Phi = phi_in`` on ``inflow``, no diffusive flux through every other boundary.

**Configuration.** The forms are pulled back to the reference mesh with ``F = I + Grad d``,
``J = det F`` (``grad_x = F^-T Grad``, ``dx = J dX``, ``n ds = cof(F) N dS``), as ``ale_fsi``
does; the mesh itself is never deformed (``mesh.SetDeformation`` would also move the FSI
solver that shares it).  ``dPhi/dt|_X`` is the change at a fixed reference point.

**Time stepping.** Backward Euler on the moving mesh, everything (d, v, w, J) at the new
time: ``(Phi - Phi_old)/dt`` in the non-conservative ALE form, which keeps constants exactly.
The steady solve (the quasi-steady variant) drops the time derivative.

**Stabilisation.** SUPG (Brooks & Hughes 1982) in the fluid with the strong residual
``(Phi - Phi_old)/dt + c . grad_x Phi - D lap_x Phi`` and ``tau = ((2/dt)^2 + (2|c|/h)^2
+ (12 D/h^2)^2)^(-1/2)`` (the smooth switch of Shakib, Hughes & Johan 1991 / Tezduyar &
Osawa 2000; ``tau -> h/(2|c|)`` for large and ``h^2/(12 D)`` for small mesh Peclet numbers,
so it fades out where diffusion resolves the layer), ``h`` = element size in the current
configuration over the order.  ``lap_x Phi`` is the exact pull-back of the Laplacian,
including the second derivatives of the mesh displacement (:meth:`NutrientTransport._lap_x`),
so SUPG stays consistent on a curved mesh motion and P2 keeps its L2 rate h^3.

**Nonlinear solve.** The shared :class:`~fbia.plugins.fem.newton.NewtonSolver` with the
consistent Jacobian.  Only the Monod term is nonlinear: the residual is ``A Phi + b + r_R(Phi)``
with A and b (everything else, SUPG included) assembled once per solve and only ``r_R``
linearised again (NGSolve's symbolic linearisation), which is 4-6 times cheaper per time step
than linearising the whole form (same values to round-off).  Updates are scaled by ``phi_in`` and
halved while they take Phi below ``-0.05 phi_in`` at a biofilm vertex (or deepen an
undershoot more than twofold).  If Newton still fails, the
half-saturation K2R is lowered to its value in stages from ``4 phi_in`` (a continuation), which
handles the near-step Monod law of ``K2R << phi_in``.  Failures are
:class:`fbia.ForwardModelError` with reasons ``transport_newton_divergence``,
``transport_negative``, ``transport_linear_solver`` or ``transport_nan``.

**Interface flux** (eq. 7), :meth:`NutrientTransport.interface_flux`: the consistent
boundary flux with a lumped interface mass (Carey, Chow & Seager 1985; Melbo & Kvamsdal
2003).  The residual of the biofilm-side terms alone (diffusion, consumption, storage),
tested with the vertex (P1 hat) function psi_i of an interface vertex, equals
``int_Gamma h psi_i ds`` with ``h = D_biofilm grad Phi . n_S``, since every other biofilm
boundary is no-flux; ``h_i = r_S(psi_i) / int_Gamma psi_i ds`` (current configuration).  The
total ``sum_i h_i int psi_i ds`` is exactly the biofilm's uptake (consumption + storage).
Measured on a two-layer slab (P2): vertex values converge as h^2 (1.3e-2, 3.7e-3, 1.1e-3,
3.0e-4 relative for 2 ... 16 elements over the biofilm), 3-8 times closer than solving with
the full P2 trace mass, whose vertex values oscillate about the (superconvergent) mean.

**Balance**, :meth:`NutrientTransport.balance`: the advective fluxes through ``inflow`` and
``outflow`` (``Phi c . n``), the diffusive flux through ``inflow`` as the consistent flux of
the full residual (tested with the inflow vertex functions), the consumption ``int R``, the
storage rate ``d/dt int Phi dx = int (dPhi/dt|_X + Phi div w) dx``; the residual
``inflow - outflow - consumption - storage (+ source)`` is what the discrete divergence of the
velocity (``int Phi div v_h`` in the fluid) and the walls leave, and shrinks with the mesh.

>>> from fbia.plugins.growth.transport import TransportSettings
>>> TransportSettings().k1r
3e-11
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.flow_cell import FLUID, solid_regions
from ..fem.newton import NewtonFailure, NewtonSolver, sparse_direct_solver

__all__ = ["NutrientTransport", "TransportReport", "TransportSettings"]

#: Newton updates are halved while Phi at a vertex lies below -NEGATIVE_LIMIT * phi_in
NEGATIVE_LIMIT = 0.05


@dataclass(frozen=True)
class TransportSettings:
    """Coefficients (Paper A Table 6; mm, s, mol) and numerics of :class:`NutrientTransport`."""

    d_fluid: float = 2.5e-3  # mm^2/s
    d_biofilm: float = 2.5e-3  # mm^2/s
    k1r: float = 3e-11  # mol/(mm^3 s), eq. 6
    k2r: float = 3e-12  # mol/mm^3, eq. 6
    phi_in: float = 2.5e-11  # mol/mm^3
    order: int = 2
    stabilise: bool = True
    newton_tol: float = 1e-10  # Newton update relative to phi_in (max norm)


@dataclass
class TransportReport:
    """What one steady solve or time step did."""

    iterations: int = 0
    jacobians: int = 0
    seconds: float = 0.0
    phi_min: float = 0.0  # over the vertices [mol/mm^3]
    phi_max: float = 0.0


class NutrientTransport:
    """Spaces, forms, solves and post-processing of Phi (see the module docstring).

    Parameters
    ----------
    mesh
        A mesh named per :mod:`fbia.plugins.fem.flow_cell` (region ``fluid``, solid regions
        ``solid`` / ``solid_k``; boundary ``inflow`` Dirichlet, ``interface`` for the flux;
        every other boundary no-flux).  A mesh without fluid or without solid works too.
    settings
        Coefficients and numerics.
    source, inflow_value
        Verification hooks (manufactured solutions): a volume source [mol/(mm^3 s)] and the
        inflow value instead of ``phi_in``, both CoefficientFunctions of the *reference*
        coordinates (compose with the mesh motion yourself); NGSolve Parameters in them may
        change between solves.
    """

    def __init__(
        self,
        mesh: Any,
        settings: TransportSettings,
        *,
        source: Any = None,
        inflow_value: Any = None,
    ) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.mesh = mesh
        self.settings = settings
        s = settings
        materials = set(mesh.GetMaterials())
        self.fluid = FLUID if FLUID in materials else None
        self.solids = solid_regions(mesh)
        bnds = set(mesh.GetBoundaries())
        self._has_inflow = "inflow" in bnds
        self._has = {b: b in bnds for b in ("outflow", "interface")}
        self.fes = ngs.H1(mesh, order=s.order, dirichlet="inflow" if self._has_inflow else "")
        self.phi = ngs.GridFunction(self.fes)
        self.phi_old = ngs.GridFunction(self.fes)
        self._dirichlet = ngs.GridFunction(self.fes)
        V = ngs.VectorH1(mesh, order=s.order)
        self.velocity = ngs.GridFunction(V)
        self.displacement = ngs.GridFunction(V)
        self.mesh_velocity = ngs.GridFunction(V)
        self.inv_dt = ngs.Parameter(0.0)  # 0: steady
        self.k2r = ngs.Parameter(s.k2r)  # raised temporarily by the continuation in _solve
        self.source = source
        self.inflow_value = ngs.CF(s.phi_in) if inflow_value is None else inflow_value
        self._build()
        self._free = np.array(self.fes.FreeDofs(), dtype=bool)
        self._nv = mesh.nv
        if self._has_inflow:
            inflow_dofs = np.array(self.fes.GetDofs(mesh.Boundaries("inflow")), dtype=bool)
            self._inflow_vertices = np.flatnonzero(inflow_dofs[: self._nv])
        else:
            self._inflow_vertices = np.zeros(0, dtype=int)
        if self.solids:
            biofilm = self.fes.GetDofs(mesh.Materials("|".join(self.solids)))
            self._biofilm_vertices = np.flatnonzero(np.array(biofilm, dtype=bool)[: self._nv])
        else:
            self._biofilm_vertices = np.zeros(0, dtype=int)
        self._floor = -NEGATIVE_LIMIT * abs(s.phi_in)
        self._newton = NewtonSolver(
            self, s.newton_tol, 25, sparse_direct_solver(), inadmissible="transport_negative"
        )
        self.phi.Set(s.phi_in)
        self.phi_old.vec.data = self.phi.vec

    # -- forms -----------------------------------------------------------------------------------
    def _kinematics(self, boundary: bool = False) -> tuple[Any, Any, Any]:
        ngs = self.ngs
        grad_d = ngs.Grad(self.displacement)
        F = ngs.Id(2) + (grad_d.Trace() if boundary else grad_d)
        return F, ngs.Det(F), ngs.Inv(F)

    def _build(self) -> None:
        ngs = self.ngs
        s = self.settings
        u, psi = self.fes.TnT()
        F, J, Finv = self._kinematics()
        self._J = J

        def grad_x(f: Any) -> Any:
            return Finv.trans * ngs.Grad(f)

        v, w = self.velocity, self.mesh_velocity
        div_w = ngs.Trace(ngs.Grad(w) * Finv)
        c = v - w  # ALE convective velocity (eq. 5a)
        rate = self.inv_dt * (u - self.phi_old)
        f = 0.0 if self.source is None else self.source
        self._c, self._div_w = c, div_w
        k2r = self.k2r

        def monod(phi: Any) -> Any:  # eq. 6, extended oddly to Phi < 0
            return s.k1r * phi / (k2r + ngs.IfPos(phi, phi, -phi))

        reaction = monod(u)

        fluid = (rate + c * grad_x(u) - f) * psi + s.d_fluid * grad_x(u) * grad_x(psi)
        tau: Any = None
        lap: Any = None
        if s.stabilise:
            h = ngs.specialcf.mesh_size * ngs.sqrt(J) / s.order  # current size over the order
            speed2 = c * c
            tau = 1.0 / ngs.sqrt(
                (2.0 * self.inv_dt) ** 2 + 4.0 * speed2 / h**2 + (12.0 * s.d_fluid / h**2) ** 2
            )
            lap = ngs.Trace(Finv.trans * u.Operator("hesse") * Finv) - grad_x(u) * self._lap_x()
            strong = rate + c * grad_x(u) - s.d_fluid * lap - f
            fluid += tau * (c * grad_x(psi)) * strong  # SUPG (Brooks & Hughes 1982)
        solid = (rate + u * div_w + reaction - f) * psi + s.d_biofilm * grad_x(u) * grad_x(psi)

        self.form = ngs.BilinearForm(self.fes, symmetric=False)
        self.solid_form = ngs.BilinearForm(self.fes, symmetric=False)
        if self.fluid is not None:
            self.form += (J * fluid).Compile() * ngs.dx(self.fluid)
        if self.solids:
            solid_cf = (J * solid).Compile()
            self.form += solid_cf * ngs.dx("|".join(self.solids))
            self.solid_form += solid_cf * ngs.dx("|".join(self.solids))
            # int R psi_i with the quadrature of the forms: summed over the vertex functions
            # (a partition of unity) it is the consumption that the residual balances exactly
            self._consumption = ngs.BilinearForm(self.fes, symmetric=False)
            self._consumption += (J * reaction * psi).Compile() * ngs.dx("|".join(self.solids))

        # Newton's split of the same residual: A u + b + r_R(u), with A (linear in u) and b
        # (Phi_old, source) assembled once per solve; only the Monod term is linearised again
        old = self.inv_dt * self.phi_old + f
        fluid_lin = (self.inv_dt * u + c * grad_x(u)) * psi + s.d_fluid * grad_x(u) * grad_x(psi)
        fluid_aff = -old * psi
        if s.stabilise:
            supg = tau * (c * grad_x(psi))
            fluid_lin += supg * (self.inv_dt * u + c * grad_x(u) - s.d_fluid * lap)
            fluid_aff += -supg * old
        solid_lin = (self.inv_dt * u + u * div_w) * psi + s.d_biofilm * grad_x(u) * grad_x(psi)
        self._linear = ngs.BilinearForm(self.fes, symmetric=False)
        self._affine = ngs.LinearForm(self.fes)
        self._reaction_form: Any = None
        if self.fluid is not None:
            self._linear += (J * fluid_lin).Compile() * ngs.dx(self.fluid)
            self._affine += (J * fluid_aff).Compile() * ngs.dx(self.fluid)
        if self.solids:
            solids = "|".join(self.solids)
            self._linear += (J * solid_lin).Compile() * ngs.dx(solids)
            self._affine += (J * -old * psi).Compile() * ngs.dx(solids)
            # on the whole mesh (zero in the fluid), so that its matrix has the graph of A
            chi = self.mesh.MaterialCF({name: 1.0 for name in self.solids}, default=0.0)
            self._reaction_form = ngs.BilinearForm(self.fes, symmetric=False)
            self._reaction_form += (chi * J * reaction * psi).Compile() * ngs.dx
        self._jacobian: Any = None
        self._linear_values: Any = None

        # current length element and normal times length on boundaries: n ds = cof(F) N dS
        Fb, _, _ = self._kinematics(boundary=True)
        N = ngs.specialcf.normal(2)
        t = Fb * ngs.CF((-N[1], N[0]))
        self._n_ds = ngs.CF((t[1], -t[0]))
        self._ds = ngs.sqrt(t * t)
        # lumped interface mass: int psi_i ds of the vertex (P1) functions, current configuration
        self._p1 = ngs.H1(self.mesh, order=1)
        self._interface_weight: Any = None
        self._gamma_vertices = np.zeros(0, dtype=int)
        if self._has["interface"]:
            psi1 = self._p1.TestFunction()
            self._interface_weight = ngs.LinearForm(self._p1)
            self._interface_weight += self._ds * psi1 * ngs.ds("interface")
            on = np.array(self._p1.GetDofs(self.mesh.Boundaries("interface")), dtype=bool)
            self._gamma_vertices = np.flatnonzero(on)

    def _lap_x(self) -> Any:
        """The vector q with ``lap_x f = tr(F^-T Hess_X f F^-1) - grad_x f . q``: from
        ``d(F^-1)/dX_l = -F^-1 (dF/dX_l) F^-1``, ``q_m = sum_nl d^2 d_m/dX_n dX_l (F^-1 F^-T)_ln``
        (the second derivatives of the mesh displacement)."""
        ngs = self.ngs
        _, _, Finv = self._kinematics()
        G = Finv * Finv.trans
        H = self.displacement.Operator("hesse")  # (2, 4): d^2 d_m / dX_n dX_l at [m, 2n + l]
        return ngs.CF(
            tuple(
                sum(H[m, 2 * n + k] * G[k, n] for n in range(2) for k in range(2)) for m in range(2)
            )
        )

    # -- inputs ------------------------------------------------------------------------------------
    def set_flow(self, velocity: Any, displacement: Any = None, mesh_velocity: Any = None) -> None:
        """The fluid velocity v [mm/s], ALE displacement d [mm] and mesh velocity w [mm/s] at
        the time of the next solve: CoefficientFunctions or GridFunctions on the reference
        mesh (copied exactly when their space matches, else interpolated); None = 0."""
        for gf, value in (
            (self.velocity, velocity),
            (self.displacement, displacement),
            (self.mesh_velocity, mesh_velocity),
        ):
            if value is None:
                gf.vec[:] = 0.0
            elif (
                isinstance(value, self.ngs.GridFunction)
                and value.space.mesh is self.mesh
                and value.space.ndof == gf.space.ndof
                and value.space.globalorder == gf.space.globalorder
            ):
                gf.vec.data = value.vec
            else:
                gf.Set(value)

    # -- solves ------------------------------------------------------------------------------------
    def solve_steady(self, where: str = "transport") -> TransportReport:
        """The steady (quasi-steady) Phi for the current flow, Newton from the current Phi."""
        self.inv_dt.Set(0.0)
        self.phi_old.vec.data = self.phi.vec
        return self._solve(where)

    def step(self, dt: float, where: str = "transport") -> TransportReport:
        """One backward-Euler step of length ``dt`` [s] from the current Phi to the flow,
        displacement and mesh velocity last given to :meth:`set_flow` (the new time)."""
        if not dt > 0.0:
            raise ValueError(f"time step must be positive, got {dt!r}")
        self.inv_dt.Set(1.0 / dt)
        self.phi_old.vec.data = self.phi.vec
        return self._solve(where)

    def _solve(self, where: str) -> TransportReport:
        t0 = time.perf_counter()
        start = self.phi.vec.CreateVector()
        start.data = self.phi.vec
        self._set_inflow()
        self._prepare()
        try:
            try:
                rep = self._newton.solve(where)
            except NewtonFailure:
                if not self.solids or self.settings.k2r >= self.settings.phi_in:
                    raise
                self.phi.vec.data = start
                self._set_inflow()
                rep = self._continuation(where)
        except NewtonFailure as fail:
            self.phi.vec.data = start
            tag = "transport_nan" if fail.reason in ("newton_nan", "transport_nan") else None
            raise ForwardModelError(
                f"nutrient transport: {fail}", tag or f"transport_{fail.reason}"
            ) from fail
        finally:
            self.k2r.Set(self.settings.k2r)
        values = self.phi.vec.FV().NumPy()[: self._nv]  # vertex dofs: nodal values
        if not np.all(np.isfinite(self.phi.vec.FV().NumPy())):
            self.phi.vec.data = start
            raise ForwardModelError(f"{where}: nutrient field is not finite", "transport_nan")
        return TransportReport(
            iterations=rep.iterations,
            jacobians=rep.jacobians,
            seconds=time.perf_counter() - t0,
            phi_min=float(values.min()),
            phi_max=float(values.max()),
        )

    def _set_inflow(self) -> None:
        """Phi = inflow value on the Dirichlet dofs only (``Set`` on a boundary clears the
        other dofs, which must keep the current state as Newton's start)."""
        if not self._has_inflow:
            return
        ngs = self.ngs
        self._dirichlet.Set(self.inflow_value, ngs.BND, definedon=self.mesh.Boundaries("inflow"))
        fixed = ~self._free
        self.phi.vec.FV().NumPy()[fixed] = self._dirichlet.vec.FV().NumPy()[fixed]

    def _continuation(self, where: str) -> Any:
        """Newton for a half-saturation K2R lowered from phi_in to its value by factors of 4.

        With K2R << phi_in the Monod law (eq. 6) is nearly a step at Phi = 0 and Newton from a
        distant state cycles across the consumption front; with K2R >= phi_in it is nearly
        linear.  Each stage starts from the last, where the front has moved little."""
        target = self.settings.k2r
        k2r = 4.0 * self.settings.phi_in
        iterations = jacobians = 0
        while True:
            k2r = max(k2r / 4.0, target)
            self.k2r.Set(k2r)
            rep = self._newton.solve(f"{where} (K2R continuation at {k2r:.3g})")
            iterations += rep.iterations
            jacobians += rep.jacobians
            if k2r <= target:
                rep.iterations, rep.jacobians = iterations, jacobians
                return rep

    # -- the nonlinear system (fbia.plugins.fem.newton.NonlinearSystem) ----------------------------
    @property
    def vector(self) -> Any:
        return self.phi.vec

    @property
    def matrix(self) -> Any:
        return self._jacobian

    @property
    def free(self) -> Any:
        return self.fes.FreeDofs()

    @property
    def free_mask(self) -> NDArray[np.bool_]:
        return self._free

    def _prepare(self) -> None:
        """Assemble the parts of the residual that are fixed during a solve: A and b."""
        ngs = self.ngs
        with ngs.TaskManager():
            self._linear.Assemble()
            self._affine.Assemble()
        values = self._linear.mat.AsVector().FV().NumPy()
        self._linear_values = np.array(values, copy=True)
        if self._jacobian is None:
            self._jacobian = self._linear.mat.CreateMatrix()
            self._tmp = self.phi.vec.CreateVector()
        if self._jacobian.AsVector().FV().NumPy().shape != values.shape:
            raise RuntimeError("transport: the Monod and transport matrices differ in graph")

    def residual(self, res: Any) -> None:
        with self.ngs.TaskManager():
            res.data = self._linear.mat * self.phi.vec
            res.data += self._affine.vec
            if self._reaction_form is not None:
                self._reaction_form.Apply(self.phi.vec, self._tmp)
                res.data += self._tmp
        # the floor of admissible(): the state Newton steps from is always admissible
        self._floor = min(-NEGATIVE_LIMIT * abs(self.settings.phi_in), 2.0 * self._biofilm_min())

    def assemble_jacobian(self) -> None:
        """A plus the linearised Monod term (the same graph, added value by value)."""
        jac = self._jacobian.AsVector().FV().NumPy()
        jac[:] = self._linear_values
        if self._reaction_form is not None:
            with self.ngs.TaskManager():
                self._reaction_form.AssembleLinearization(self.phi.vec)
            jac += self._reaction_form.mat.AsVector().FV().NumPy()

    def scales(self) -> NDArray[np.float64]:
        return np.full(len(self._free), abs(self.settings.phi_in) or 1.0)

    def _biofilm_min(self) -> float:
        values = self.phi.vec.FV().NumPy()[self._biofilm_vertices]
        return float(values.min()) if values.size else 0.0

    def admissible(self) -> bool:
        """Finite, and in the biofilm at no vertex below ``-NEGATIVE_LIMIT * phi_in`` or,
        if Phi already undershoots, twice the current undershoot: the damping that makes
        Newton converge from ``Phi = phi_in`` (the saturated Monod law has a small derivative
        there, so the first full updates overshoot far below zero).  The fluid, where the
        problem is linear (and where an unstabilised Galerkin solution may oscillate), is
        not damped."""
        if not np.all(np.isfinite(self.phi.vec.FV().NumPy())):
            return False
        return self._biofilm_min() >= self._floor

    # -- post-processing ---------------------------------------------------------------------------
    def flux_field(self) -> Any:
        """The interface flux h = D_biofilm grad Phi . n_S [mol/(mm^2 s)] at the interface
        vertices, as a P1 GridFunction (zero off the interface); see the module docstring."""
        ngs = self.ngs
        h = ngs.GridFunction(self._p1)
        if self._interface_weight is None:
            return h
        res = self.phi.vec.CreateVector()
        with ngs.TaskManager():
            self.solid_form.Apply(self.phi.vec, res)  # biofilm-side residual: int h psi_i ds
            self._interface_weight.Assemble()  # int psi_i ds, current configuration
        weight = self._interface_weight.vec.FV().NumPy()
        on = self._gamma_vertices
        h.vec.FV().NumPy()[on] = res.FV().NumPy()[: self._nv][on] / weight[on]
        return h

    def interface_flux(self, vertices: Sequence[int]) -> NDArray[np.float64]:
        """h = D_biofilm grad Phi . n_S [mol/(mm^2 s)] at the given mesh vertex numbers
        (interface vertices), n_S the unit normal out of the biofilm in the deformed
        configuration; > 0 where nutrient enters the biofilm (eq. 7)."""
        idx = np.asarray(vertices, dtype=int)
        if idx.size and (idx.min() < 0 or idx.max() >= self._nv):
            raise IndexError(f"vertex numbers must lie in [0, {self._nv})")
        h = self.flux_field().vec.FV().NumPy()
        return np.array(h[idx], dtype=float)

    def balance(self) -> dict[str, float]:
        """Nutrient balance of the last solve [mol/s]: ``inflow`` (advective + consistent
        diffusive flux in through ``inflow``), ``outflow`` (advective out through
        ``outflow``), ``consumption`` (int R over the biofilm), ``storage`` (d/dt of the
        content, 0 for a steady solve with a fixed mesh), ``source`` (verification hook),
        ``uptake`` (the interface flux h integrated over ``interface``: what enters the
        biofilm, = its consumption + storage for a mesh with the biofilm off the inflow) and
        ``residual`` = inflow - outflow - consumption - storage + source."""
        ngs = self.ngs
        mesh = self.mesh
        order = 2 * self.settings.order + 2
        phi, J = self.phi, self._J
        cn = self._c * self._n_ds
        out: dict[str, float] = {}
        adv_in = diff_in = 0.0
        if self._has_inflow:
            adv_in = -ngs.Integrate(
                phi * cn, mesh, definedon=mesh.Boundaries("inflow"), order=order
            )
            res = phi.vec.CreateVector()
            with ngs.TaskManager():
                self.form.Apply(phi.vec, res)
            diff_in = float(np.sum(res.FV().NumPy()[self._inflow_vertices]))
        out["inflow"] = float(adv_in + diff_in)
        outflow = 0.0
        if self._has["outflow"]:
            outflow = ngs.Integrate(
                phi * cn, mesh, definedon=mesh.Boundaries("outflow"), order=order
            )
        out["outflow"] = float(outflow)
        consumption = 0.0
        if self.solids:
            res = phi.vec.CreateVector()
            with ngs.TaskManager():
                self._consumption.Apply(phi.vec, res)
            consumption = float(np.sum(res.FV().NumPy()[: self._nv]))
        out["consumption"] = float(consumption)
        storage = ngs.Integrate(
            (self.inv_dt * (phi - self.phi_old) + phi * self._div_w) * J, mesh, order=order
        )
        out["storage"] = float(storage)
        source = 0.0 if self.source is None else ngs.Integrate(self.source * J, mesh, order=order)
        out["source"] = float(source)
        uptake = 0.0
        if self._interface_weight is not None:
            h = self.flux_field().vec.FV().NumPy()
            uptake = float(np.dot(h, self._interface_weight.vec.FV().NumPy()))
        out["uptake"] = uptake
        out["residual"] = (
            out["inflow"] - out["outflow"] - out["consumption"] - out["storage"] + out["source"]
        )
        return out
