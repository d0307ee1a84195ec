"""Cut-FEM flow solve: Navier-Stokes outside, primal Darcy inside a level-set-described biofilm.

One background mesh, one level set ``lset`` (negative in the porous biofilm, positive in the
channel fluid), two cut spaces solved monolithically (Paper A "Fluid-poroelastic solid
interaction", eq. 14-15, after the FPI method of its ref. [16]):

* channel fluid ``(u, p)`` -- cut Taylor-Hood P2/P1 on the elements that have a fluid part;
* pore pressure ``p_d`` -- P2 on the elements that have a porous part, Darcy flux
  ``q = phi (v^pf - v^ps) = -(k / mu) grad p_d`` (eq. 10b, steady, skeleton at rest).

With ``n_F`` the unit normal out of the fluid (into the biofilm) and ``t`` the tangent, the
interface conditions enter as natural interface integrals (``dCut(lset, IF)``):

* eq. 14b  ``n_F . sigma n_F = -p_d``  and eq. 14d (Beavers-Joseph)
  ``t . sigma n_F = -(u.t - beta_BJ q.t) / kappa`` replace the fluid traction;
* eq. 14c  ``u . n_F = q . n_F`` replaces the Darcy flux through the interface;

so the coupling terms ``+(p_d, v.n_F)_Gamma`` and ``-(u.n_F, w)_Gamma`` are skew and the
interface mass balance holds to round-off.  The Saffman simplification drops ``beta_BJ q.t``.
The interface permeability is eq. 15, ``kappa = sqrt(tr k) / (alpha_BJ mu sqrt 3)``.  Ghost
penalties (direct facet-patch form) on both sides keep the system well conditioned for any
cut; a second-order :class:`xfem.lsetcurv.LevelSetMeshAdaptation` makes the geometry
third-order accurate.

Small permeability.  The Darcy stiffness ``K/mu`` and the ghost penalty that scales with it
vanish beside the coupling terms once ``K << h^2``: ``p_d`` then acts as the Lagrange
multiplier of ``u.n_F = q.n_F ~ 0`` (eq. 14c), in a space of the same order as the velocity,
and without a K-independent stabilisation its interface values are wrong by O(1) (at
K = 1e-10 mm^2 on the flow cell the skeleton then saw porosities outside (0, 1)).  This is
the discretisation, not round-off: direct solvers with and without equilibration agree on
that solution.  The pore-pressure ghost penalty therefore has the floor
``pore_ghost_floor * gamma / mu`` of the fluid pressure's; its interface values then converge
at second order for any K, like the normal stress they balance (eq. 14b).  Inside the porous
part, where the band of stabilised elements only extrapolates them, ``p_d`` is O(h) for
``K << h^2``; the skeleton takes the interface values and rebuilds the inside by Darcy on its
own mesh (:meth:`.skeleton.Skeleton.extend_pressure`).

Inhomogeneous interface data ``g_mass`` (eq. 14c), ``g_normal`` (14b), ``g_tangent`` (14d) and
volume sources exist for manufactured solutions; the physical problem sets them to zero.

>>> from ngsolve import Mesh, sqrt, x, y                           # doctest: +SKIP
>>> from ngsolve.meshes import MakeStructured2DMesh                # doctest: +SKIP
>>> mesh = MakeStructured2DMesh(quads=False, nx=16, ny=16)         # doctest: +SKIP
>>> flow = CutFlow(mesh, sqrt((x - .5)**2 + (y - .5)**2) - .3, FlowSettings(),
...                dirichlet="left|right|top|bottom")              # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.newton import NewtonFailure, NewtonSolver, sparse_direct_solver


@dataclass(frozen=True)
class FlowSettings:
    """Physics and numerics of :class:`CutFlow` (units mm, s, g)."""

    viscosity: float = 1e-3  # mu^F = mu^pf, g/(mm s)
    density: float = 1e-3  # rho^F, g/mm^3; 0 gives Stokes
    alpha_bj: float = 1.0  # Beavers-Joseph alpha (eq. 15)
    beta_bj: float = 1.0  # Beavers-Joseph beta (eq. 14d)
    saffman: bool = False  # drop beta_BJ q.t in eq. 14d
    order: int = 2  # velocity and pore-pressure order; fluid pressure order - 1
    ghost_penalty: float = 0.1  # gamma of the facet-patch ghost penalties
    # K-independent part of the pore-pressure ghost penalty, in units of the fluid pressure's
    # (gamma / mu): for K << h^2 the pore pressure is the multiplier of eq. 14c and needs it
    pore_ghost_floor: float = 1.0
    lset_order: int = 2  # order of the level-set mesh adaptation
    newton_tol: float = 1e-9  # estimated relative velocity error that ends Newton
    newton_max_iter: int = 20


@dataclass
class FlowReport:
    """What one flow solve did."""

    iterations: int = 0
    ndof: int = 0
    time_setup: float = 0.0
    time_solve: float = 0.0
    norms: list[float] = field(default_factory=list)


class CutFlow:
    """Spaces, forms and solver of the cut Navier-Stokes/Darcy problem on one background mesh.

    Parameters
    ----------
    mesh
        Background mesh (fixed for the whole run).
    lset
        Level set (coefficient function), negative in the porous body.
    settings
        Physics and numerics.
    dirichlet
        Boundaries (``|``-separated regex) with prescribed fluid velocity, or a pair
        ``(x, y)`` per velocity component.
    permeability
        Spatial permeability ``k`` of the porous body in mm^2: a scalar, a scalar coefficient
        function or a 2x2 matrix coefficient function (eq. 11 with ``k = J^-1 F K F^T``).
    """

    def __init__(
        self,
        mesh: Any,
        lset: Any,
        settings: FlowSettings,
        dirichlet: str | tuple[str, str],
        permeability: Any = 1.0,
    ) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.mesh = mesh
        self.settings = settings
        o = settings.order
        dx, dy = (dirichlet, dirichlet) if isinstance(dirichlet, str) else dirichlet
        self._dirichlet = "|".join(b for b in (dx, dy) if b)
        self.V = ngs.VectorH1(mesh, order=o, dirichletx=dx, dirichlety=dy)
        self.Q = ngs.H1(mesh, order=o - 1)
        self.D = ngs.H1(mesh, order=o)
        self.X = ngs.FESpace([self.V, self.Q, self.D], dgjumps=True)  # facet-patch couplings
        self.gfx = ngs.GridFunction(self.X)  # full (uncompressed) state: warm starts survive
        self.sources: dict[str, Any] = {}
        self.lsetadap: Any = None
        self._markers: NDArray[np.bool_] | None = None  # cut element and facet markers
        self._k_source: Any = None
        # forms and Newton solver (with its factorisation) of the cut, built by the first solve
        self._system: tuple[_FlowSystem, NewtonSolver] | None = None
        self.set_permeability(permeability)
        self.set_level_set(lset)

    # -- geometry ----------------------------------------------------------------------------
    def set_level_set(self, lset: Any) -> None:
        """(Re)build the cut geometry for a new level set; the state vector is kept.

        The mesh adaptation and its P1 level set and deformation are updated in place.  When
        the new level set cuts the same elements as the last one (late coupling iterations),
        element and facet markers, active dofs and hence the sparsity pattern are unchanged:
        the forms are kept and only re-assembled, and the factorisation is only refactored.
        """
        import xfem
        from xfem.lsetcurv import LevelSetMeshAdaptation

        ngs = self.ngs
        t0 = time.perf_counter()
        s = self.settings
        if self.lsetadap is None:
            self.lsetadap = LevelSetMeshAdaptation(
                self.mesh, order=s.lset_order, threshold=0.1, discontinuous_qn=True
            )
        self.deformation = self.lsetadap.CalcDeformation(lset)
        self.lsetp1 = self.lsetadap.lset_p1
        self.lset = lset
        ci = xfem.CutInfo(self.mesh, self.lsetp1)
        cut = ci.GetElementsOfType(xfem.IF)
        if sum(cut) == 0:
            raise ForwardModelError("the level set does not cut the background mesh", "geometry")
        # one layer of elements around the cut elements is active on both sides: the ghost
        # penalty extends the discrete fields there, so that values on the skeleton's own
        # interface (which differs from the discrete level set by O(h^2)) are always defined
        near = xfem.GetFacetsWithNeighborTypes(
            self.mesh, a=cut, b=cut, bnd_val_a=False, bnd_val_b=False, use_and=False
        )
        ring = xfem.GetElementsWithNeighborFacets(self.mesh, near)
        els = {
            "fluid": ci.GetElementsOfType(xfem.HASPOS) | ring,
            "porous": ci.GetElementsOfType(xfem.HASNEG) | ring,
            "if": cut,
        }
        facets = {
            side: xfem.GetFacetsWithNeighborTypes(
                self.mesh, a=els[side], b=ring, bnd_val_a=False, bnd_val_b=False, use_and=True
            )
            for side in ("fluid", "porous")
        }
        markers = np.concatenate(
            [np.array(b, dtype=bool) for b in (*els.values(), *facets.values())]
        )
        self.time_geometry = time.perf_counter() - t0
        if self._markers is not None and np.array_equal(markers, self._markers):
            self._stale()  # same cut elements: keep forms, pattern and analysis
            return
        self._markers = markers
        self.els, self.facets = els, facets
        active = np.concatenate(
            [
                np.array(xfem.GetDofsOfElements(sp, els[side]), dtype=bool)
                for sp, side in ((self.V, "fluid"), (self.Q, "fluid"), (self.D, "porous"))
            ]
        )
        self.active = ngs.BitArray(active)
        self.freedofs = ngs.BitArray(np.array(self.X.FreeDofs(), dtype=bool) & active)
        self._system = None  # forms and factorisation of this cut, built by the first solve
        self.time_geometry = time.perf_counter() - t0

    def _stale(self) -> None:
        """Coefficients changed, forms and pattern did not: re-assemble before the next solve."""
        if self._system is not None:
            self._system[0].fresh = False

    def set_permeability(self, k: Any) -> None:
        """Spatial permeability (mm^2): scalar, scalar CF or 2x2 matrix CF (eq. 11)."""
        ngs = self.ngs
        if self._k_source is not None and k is self._k_source:
            self._stale()  # same coefficient function, new values
            return
        self._k_source = k
        self._system = None
        k = ngs.CoefficientFunction(k)
        if k.dim == 1:
            self.k_matrix = k * ngs.Id(2)
        elif k.dim == 4:
            self.k_matrix = k.Reshape((2, 2))
        else:
            raise ValueError(f"permeability must be a scalar or 2x2, got dimension {k.dim}")
        self.k_trace = ngs.Trace(self.k_matrix)

    # -- measures and normals ----------------------------------------------------------------
    def measures(self) -> dict[str, Any]:
        import xfem

        d = self.deformation
        return {
            "dx_f": xfem.dCut(
                self.lsetp1, xfem.POS, deformation=d, definedonelements=self.els["fluid"]
            ),
            "dx_p": xfem.dCut(
                self.lsetp1, xfem.NEG, deformation=d, definedonelements=self.els["porous"]
            ),
            "ds": xfem.dCut(self.lsetp1, xfem.IF, deformation=d, definedonelements=self.els["if"]),
            "dw_f": xfem.dFacetPatch(deformation=d, definedonelements=self.facets["fluid"]),
            "dw_p": xfem.dFacetPatch(deformation=d, definedonelements=self.facets["porous"]),
        }

    def normal_fluid(self) -> Any:
        """Unit normal out of the fluid into the biofilm, ``n_F = -grad lset / |grad lset|``."""
        ngs = self.ngs
        g = ngs.grad(self.lsetp1)
        return -1.0 / ngs.Norm(g) * g

    def kappa(self) -> Any:
        """Interface permeability, eq. 15: sqrt(tr k) / (alpha_BJ mu sqrt 3)  [mm^2 s/g]."""
        s = self.settings
        return self.ngs.sqrt(self.k_trace) / (s.alpha_bj * s.viscosity * math.sqrt(3.0))

    # -- forms -------------------------------------------------------------------------------
    def _forms(self, convection: Any | None) -> tuple[Any, Any]:
        """Bilinear form (linearised at ``convection``) and right-hand side (eq. 1, 10, 14)."""
        ngs = self.ngs
        s = self.settings
        m = self.measures()
        (u, p, pd), (v, q, w) = self.X.TnT()
        mu, rho = s.viscosity, s.density
        h = ngs.specialcf.mesh_size
        nF = self.normal_fluid()
        t = ngs.CoefficientFunction((-nF[1], nF[0]))
        kmu = self.k_matrix / mu
        kappa = self.kappa()
        eps = ngs.Sym

        import xfem

        a = xfem.RestrictedBilinearForm(
            self.X,
            element_restriction=self.els["fluid"] | self.els["porous"],
            facet_restriction=self.facets["fluid"] | self.facets["porous"],
            check_unused=False,
        )
        # channel fluid: (eq. 1a, 1b) with c^F = v^F (fixed grid)
        stokes = 2 * mu * ngs.InnerProduct(eps(ngs.Grad(u)), eps(ngs.Grad(v)))
        stokes += -p * ngs.div(v) - q * ngs.div(u)
        if convection is not None and rho > 0:
            uk = convection
            # Newton for rho (grad u) u: (grad du) u_k + (grad u_k) du; rhs (grad u_k) u_k
            stokes += rho * (ngs.Grad(u) * uk + ngs.Grad(uk) * u) * v
        a += stokes * m["dx_f"]
        # pore fluid: -div(k/mu grad p_d) = g (eq. 10a/10b steady)
        a += ngs.InnerProduct(kmu * ngs.grad(pd), ngs.grad(w)) * m["dx_p"]
        # interface, eq. 14b-d
        a += pd * (v * nF) * m["ds"]
        a += -(u * nF) * w * m["ds"]
        a += (1.0 / kappa) * (u * t) * (v * t) * m["ds"]
        if not s.saffman:
            qd = -kmu * ngs.grad(pd)  # Darcy flux q = phi (v^pf - v^ps)
            a += -(s.beta_bj / kappa) * (qd * t) * (v * t) * m["ds"]
        # ghost penalties (direct facet-patch version) on both sides
        g = s.ghost_penalty
        a += g * mu / h**2 * (u - u.Other()) * (v - v.Other()) * m["dw_f"]
        a += -g / mu * (p - p.Other()) * (q - q.Other()) * m["dw_f"]
        gd = g * (0.5 * self.k_trace / h**2 + s.pore_ghost_floor) / mu
        a += gd * (pd - pd.Other()) * (w - w.Other()) * m["dw_p"]

        f = ngs.LinearForm(self.X)
        if convection is not None and rho > 0:
            f += rho * (ngs.Grad(convection) * convection) * v * m["dx_f"]
        src = self.sources
        if "f" in src:
            f += src["f"] * v * m["dx_f"]
        if "g" in src:
            f += src["g"] * w * m["dx_p"]
        if "g_mass" in src:  # eq. 14c: u.n_F - q.n_F = g_mass
            f += -src["g_mass"] * w * m["ds"]
        if "g_normal" in src:  # eq. 14b: n_F.sigma n_F + p_d = g_normal
            f += src["g_normal"] * (v * nF) * m["ds"]
        if "traction" in src:  # prescribed fluid traction sigma n on an outer boundary
            cf, bnd = src["traction"]
            f += cf * v * ngs.ds(definedon=self.mesh.Boundaries(bnd))
        if "g_tangent" in src:  # eq. 14d: u.t - beta q.t + kappa t.sigma n_F = g_tangent
            f += (src["g_tangent"] / kappa) * (v * t) * m["ds"]
        return a, f

    # -- solve -------------------------------------------------------------------------------
    @property
    def velocity(self) -> Any:
        return self.gfx.components[0]

    @property
    def pressure(self) -> Any:
        return self.gfx.components[1]

    @property
    def pore_pressure(self) -> Any:
        return self.gfx.components[2]

    @property
    def ndof(self) -> int:
        return int(sum(self.freedofs))

    def solve(
        self,
        dirichlet_velocity: Any | None = None,
        where: str = "flow",
        tol: float | None = None,
    ) -> FlowReport:
        """Navier-Stokes (Stokes for ``density = 0``) from the current state with the shared
        :class:`~fbia.plugins.fem.newton.NewtonSolver`; ``dirichlet_velocity`` is set on the
        Dirichlet boundaries first.

        The forms of the current cut are assembled once and re-assembled in place at each
        Newton step; the factorisation is analysed once per cut and only refactored
        afterwards, and a converged solve's factorisation serves the next one as chord steps
        while it contracts.  ``tol`` (default ``settings.newton_tol``) bounds the velocity
        update relative to the largest velocity (max norms), or the error left that the
        contraction of the last updates predicts.  A solve that does not get there in
        ``settings.newton_max_iter`` Jacobians raises :class:`ForwardModelError` (reason
        ``flow_newton``; ``flow_diverged`` for NaN).
        """
        ngs = self.ngs
        s = self.settings
        rep = FlowReport(ndof=self.ndof, time_setup=self.time_geometry)
        vec = self.gfx.vec.FV().NumPy()
        vec[~np.array(self.active, dtype=bool)] = 0.0
        if dirichlet_velocity is not None:
            tmp = ngs.GridFunction(self.V)
            tmp.Set(dirichlet_velocity, definedon=self.mesh.Boundaries(self._dirichlet))
            idx = np.flatnonzero(~np.array(self.V.FreeDofs(), dtype=bool))
            vec[idx] = tmp.vec.FV().NumPy()[idx]
        if self._system is None:
            system = _FlowSystem(self)
            newton = NewtonSolver(system, s.newton_tol, s.newton_max_iter, sparse_direct_solver())
            self._system = (system, newton)
        newton = self._system[1]
        t0 = time.perf_counter()
        try:
            step = newton.solve(where, tol)
        except NewtonFailure as fail:
            reason = "flow_diverged" if fail.reason == "newton_nan" else "flow_newton"
            prefix = "" if "flow" in where else "flow: "
            raise ForwardModelError(f"{prefix}{fail}", reason) from fail
        rep.time_solve = time.perf_counter() - t0
        rep.iterations = step.iterations
        rep.norms = step.norms
        return rep

    # -- post-processing ---------------------------------------------------------------------
    def integrate(self, cf: Any, region: str, order: int = 6) -> float:
        """Integral of ``cf`` over ``fluid``, ``porous`` or ``if`` (the interface)."""
        import xfem

        dom = {"fluid": xfem.POS, "porous": xfem.NEG, "if": xfem.IF}[region]
        lset_dom = {"levelset": self.lsetp1, "domain_type": dom}
        return float(
            xfem.Integrate(
                levelset_domain=lset_dom,
                cf=cf,
                mesh=self.mesh,
                order=order,
                deformation=self.deformation,
            )
        )

    def interface_mass_balance(self) -> tuple[float, float]:
        """(fluid flux u.n_F into the biofilm, Darcy flux q.n_F) through the interface (mm^2/s)."""
        ngs = self.ngs
        nF = self.normal_fluid()
        qd = -self.k_matrix / self.settings.viscosity * ngs.grad(self.pore_pressure)
        return (
            self.integrate(self.velocity * nF, "if"),
            self.integrate(qd * nF, "if"),
        )

    def state(self) -> NDArray[np.float64]:
        return np.array(self.gfx.vec.FV().NumPy(), copy=True)


class _FlowSystem:
    """The cut flow problem of one cut as a :class:`~fbia.plugins.fem.newton.NonlinearSystem`.

    With the Newton linearisation of the convection at ``u_k`` (:meth:`CutFlow._forms`) the
    residual at ``u_k`` is ``a(u_k) u_k - f(u_k)`` and ``a(u_k)`` is the consistent Jacobian,
    so one assembly serves both.  Only the velocity update is measured, relative to the
    largest velocity.
    """

    def __init__(self, flow: CutFlow) -> None:
        import ngsolve as ngs

        self.flow = flow
        self.convective = flow.settings.density > 0
        self.uk = ngs.GridFunction(flow.V)
        self.a, self.f = flow._forms(self.uk if self.convective else None)
        self.fresh = False  # whether a and f are assembled at the current state
        self.nv = flow.V.ndof
        self._free = np.array(flow.freedofs, dtype=bool)

    @property
    def vector(self) -> Any:
        return self.flow.gfx.vec

    @property
    def matrix(self) -> Any:
        return self.a.mat

    @property
    def free(self) -> Any:
        return self.flow.freedofs

    @property
    def free_mask(self) -> NDArray[np.bool_]:
        return self._free

    def _assemble(self) -> None:
        ngs = self.flow.ngs
        self.uk.vec.data = self.flow.gfx.components[0].vec
        with ngs.TaskManager():
            self.a.Assemble()
            self.f.Assemble()
        self.fresh = True

    def residual(self, res: Any) -> None:
        if self.convective or not self.fresh:  # Stokes: the forms do not depend on the state
            self._assemble()
        res.data = self.a.mat * self.vector - self.f.vec

    def assemble_jacobian(self) -> None:
        if not self.fresh:  # else assembled with the residual at this state
            self._assemble()

    def scales(self) -> NDArray[np.float64]:
        out = np.full(len(self._free), np.inf)  # pressures are not measured
        u = self.vector.FV().NumPy()[: self.nv]
        out[: self.nv] = max(float(np.max(np.abs(u), initial=0.0)), 1e-300)
        return out

    def admissible(self) -> bool:
        return True  # a fixed background mesh: every state is admissible
