"""The poroelastic skeleton on its own fitted mesh, in the reference configuration.

Unknowns: displacement ``d`` (P2) and porosity ``phi`` (discontinuous, order 1).  Loads: the
pore pressure ``p`` (a field on the skeleton mesh, moved over from the flow solve) and the
fluid shear ``tau`` on the interface.

Steady form of Paper A eq. 10: with eq. 10b, ``mu phi k^-1 (v^pf - v^ps) = -grad_x p``, the
drag and pressure-gradient terms of eq. 10c cancel and the skeleton balance reads
``Div(F S) = 0`` with the total second Piola-Kirchhoff stress of the mixture (after the
formulation of Paper A ref. [20])

    S = S_skel(C) + dpsi_pen/dE |_{J(1-phi)} - p J C^-1,
    S_skel = mu (I - C^-1) + lambda ln(J) C^-1                   (neo-Hooke psi_skel, eq. 12)
    dpsi_pen/dE = eta (1/phi0 - 1/(J phi)) J C^-1                 (eq. 13b)

and the porosity follows from the constitutive relation of the pore pressure,
``p = -dpsi/d(J(1-phi))`` (eq. 12-13):

    p = -kappa (1/(1-phi0) - 1/(J(1-phi))) - eta (1/(J phi) - 1/phi0).

On the interface the traction balance (eq. 14a) with eq. 14b gives the total traction
``sigma^P n = -p n + tau t`` (``n`` out of the biofilm, ``t`` its tangent); in the reference
configuration ``-p J F^-T N dA + tau t |cof(F) N| dA``.  ``solid_fixed`` is clamped.
Newton's method, damped to stay admissible, with NGSolve's symbolic linearisation and a
direct solver.

The pore pressure inside the skeleton can be rebuilt from its values on the interface
(:meth:`Skeleton.extend_pressure`): the steady Darcy problem ``div q = 0`` pulled back to the
reference configuration, where ``J F^-1 k F^-T`` is the Kozeny-Carman ``K`` of eq. 11, reads
``-Div(K Grad p) = 0`` with no flux through ``solid_fixed``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.newton import NewtonFailure, NewtonSolver, sparse_direct_solver


@dataclass(frozen=True)
class SkeletonSettings:
    """Material and numerics of :class:`Skeleton` (stresses in Pa)."""

    kappa: float = 100.0  # bulk modulus of psi_vol, eq. 13a [Pa]
    eta: float = 1.0  # penalty of psi_pen, eq. 13b [Pa]
    order: int = 2
    newton_tol: float = 1e-10  # update relative to the largest displacement
    newton_max_iter: int = 25


class Skeleton:
    """Spaces, residual and Newton solver of the steady poroelastic skeleton.

    Parameters
    ----------
    mesh
        Fitted mesh of the biofilm (reference configuration) with boundaries ``interface``
        (loaded) and ``solid_fixed`` (clamped); further boundaries given in ``fixed_x`` /
        ``fixed_y`` are clamped in one direction (e.g. sliding walls of a column).
    """

    def __init__(
        self,
        mesh: Any,
        settings: SkeletonSettings,
        fixed_x: str = "solid_fixed",
        fixed_y: str = "solid_fixed",
        loaded: str = "interface",
    ) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.mesh = mesh
        self.settings = settings
        self.D = ngs.VectorH1(mesh, order=settings.order, dirichletx=fixed_x, dirichlety=fixed_y)
        self.P = ngs.L2(mesh, order=1)
        self.X = ngs.FESpace([self.D, self.P])
        self.gfx = ngs.GridFunction(self.X)
        # p on this mesh; the interface values are Dirichlet data of extend_pressure
        self.pressure = ngs.GridFunction(ngs.H1(mesh, order=settings.order, dirichlet=loaded))
        self.shear = ngs.GridFunction(ngs.H1(mesh, order=settings.order))  # tau on interface
        self.E = ngs.Parameter(300.0)
        self.nu = ngs.Parameter(0.3)
        self.phi0 = ngs.Parameter(0.25)
        self.loaded = loaded
        self._build()
        self.reset()

    @property
    def displacement(self) -> Any:
        return self.gfx.components[0]

    @property
    def porosity(self) -> Any:
        return self.gfx.components[1]

    @property
    def ndof(self) -> int:
        return int(sum(self.X.FreeDofs()))

    def set_material(self, E: float, nu: float, phi0: float) -> None:
        self.E.Set(E)
        self.nu.Set(nu)
        self.phi0.Set(phi0)

    def reset(self) -> None:
        """Undeformed state: d = 0, phi = phi0."""
        self.gfx.vec[:] = 0.0
        self.porosity.Set(self.phi0)

    def _build(self) -> None:
        ngs = self.ngs
        s = self.settings
        (d, phi), (dd, r) = self.X.TnT()
        E, nu, phi0 = self.E, self.nu, self.phi0
        mu = E / (2 * (1 + nu))
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        eta, kap = s.eta, s.kappa
        p = self.pressure
        F = ngs.Id(2) + ngs.Grad(d)
        J = ngs.Det(F)
        C = F.trans * F
        Ci = ngs.Inv(C)
        S = mu * (ngs.Id(2) - Ci) + lam * ngs.log(J) * Ci  # neo-Hooke (eq. 12)
        S += eta * (1 / phi0 - 1 / (J * phi)) * J * Ci  # eq. 13b
        S += -p * J * Ci  # pore pressure in the total stress
        sol = J * (1 - phi)  # J(1 - phi)
        constitutive = p + kap * (1 / (1 - phi0) - 1 / sol) + eta * (1 / (J * phi) - 1 / phi0)
        N = ngs.specialcf.normal(2)
        Fb = ngs.Id(2) + ngs.Grad(d).Trace()
        cofN = ngs.Det(Fb) * ngs.Inv(Fb).trans * N  # Nanson: n da = J F^-T N dA
        t_da = ngs.CoefficientFunction((-cofN[1], cofN[0]))  # tangent times da
        a = ngs.BilinearForm(self.X, symmetric=False)
        a += (ngs.InnerProduct(F * S, ngs.Grad(dd)) + constitutive * r) * ngs.dx
        a += -(-p * cofN + self.shear * t_da) * dd * ngs.ds(self.loaded)
        self.form = a
        # steady Darcy in the reference configuration, scaled by 1/K0 (eq. 10b, 11)
        pp, ww = self.pressure.space.TnT()
        Jh = ngs.Det(ngs.Id(2) + ngs.Grad(self.displacement))
        darcy = ngs.BilinearForm(self.pressure.space, symmetric=True)
        darcy += kozeny_carman(Jh, self.porosity, phi0) * ngs.grad(pp) * ngs.grad(ww) * ngs.dx
        self._darcy = darcy
        self._darcy_inverse: Any = None
        self._free = np.array(self.X.FreeDofs(), dtype=bool)
        self._nd = self.D.ndof  # the displacement dofs come first
        pts = np.array([v.point for v in self.mesh.vertices])
        self._length = float(np.max(np.ptp(pts, axis=0)))  # extent of the mesh [mm]
        self._violation: ForwardModelError | None = None  # why the last state was rejected
        self._newton = NewtonSolver(
            self,
            s.newton_tol,
            s.newton_max_iter,
            sparse_direct_solver(),
            max_halvings=8,
            inadmissible="skeleton_admissible",
        )
        self._check_points: Any = None
        self.J = ngs.Det(ngs.Id(2) + ngs.Grad(self.displacement))

    def extend_pressure(self) -> None:
        """The pore pressure inside from its values on the interface (the Dirichlet data held
        by :attr:`pressure` there): ``-Div(K Grad p) = 0`` with the Kozeny-Carman ``K`` of the
        current state, no flux through the other boundaries."""
        ngs = self.ngs
        p = self.pressure
        with ngs.TaskManager():
            self._darcy.Assemble()
            if self._darcy_inverse is None:
                self._darcy_inverse = self._darcy.mat.Inverse(
                    p.space.FreeDofs(), inverse="sparsecholesky"
                )
            else:
                self._darcy_inverse.Update()
            res = p.vec.CreateVector()
            res.data = -(self._darcy.mat * p.vec)
            p.vec.data += self._darcy_inverse * res

    def solve(self, where: str = "skeleton", tol: float | None = None) -> int:
        """Newton from the current state with the shared
        :class:`~fbia.plugins.fem.newton.NewtonSolver`; returns the number of iterations.

        Converged when the update (max norm; displacements relative to the largest
        displacement, porosities absolute), or the error left that the contraction of the
        last updates predicts, is below ``tol`` (default ``settings.newton_tol``).  Updates
        are halved, up to 8 times, until the state is admissible (0 < phi < 1, J > 0): the
        penalty and volumetric energies (eq. 13) are barriers at J phi = 0 and
        J (1 - phi) = 0, which a full Newton step can jump.  The sparsity pattern never
        changes, so the factorisation is analysed once and only refactored.
        """
        self._violation = None
        try:
            return self._newton.solve(where, tol).iterations
        except NewtonFailure as fail:
            if fail.reason == "skeleton_admissible" and self._violation is not None:
                raise ForwardModelError(
                    f"{where}: every damped Newton update is inadmissible: {self._violation}",
                    self._violation.reason,
                ) from fail
            prefix = "" if "skeleton" in where else "skeleton: "
            raise ForwardModelError(f"{prefix}{fail}", "skeleton_newton") from fail

    # -- the nonlinear system (fbia.plugins.fem.newton.NonlinearSystem) ------------------------
    @property
    def vector(self) -> Any:
        return self.gfx.vec

    @property
    def matrix(self) -> Any:
        return self.form.mat

    @property
    def free(self) -> Any:
        return self.X.FreeDofs()

    @property
    def free_mask(self) -> NDArray[np.bool_]:
        return self._free

    def residual(self, res: Any) -> None:
        with self.ngs.TaskManager():
            self.form.Apply(self.gfx.vec, res)

    def assemble_jacobian(self) -> None:
        with self.ngs.TaskManager():
            self.form.AssembleLinearization(self.gfx.vec)

    def scales(self) -> NDArray[np.float64]:
        out = np.ones(len(self._free))  # porosities: absolute
        d = self.gfx.vec.FV().NumPy()[: self._nd]
        out[: self._nd] = max(float(np.max(np.abs(d), initial=0.0)), self._length * 1e-12)
        return out

    def admissible(self) -> bool:
        try:
            self.check("skeleton")
        except ForwardModelError as err:
            self._violation = err
            return False
        return True

    def _ranges(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Porosity and J at the element vertices and centres."""
        ngs = self.ngs
        if self._check_points is None:
            ir = ngs.IntegrationRule([(0, 0), (1, 0), (0, 1), (1 / 3, 1 / 3)], [0.0] * 4)
            self._check_points = self.mesh.MapToAllElements(ir, ngs.VOL)
        pts = self._check_points
        return np.asarray(self.porosity(pts)).ravel(), np.asarray(self.J(pts)).ravel()

    def check(self, where: str) -> None:
        """Raise unless 0 < phi < 1 and J > 0 at the element vertices and centres."""
        phi, J = self._ranges()
        if not np.all(np.isfinite(phi)) or phi.min() <= 0.0 or phi.max() >= 1.0:
            raise ForwardModelError(
                f"{where}: porosity left (0, 1): range [{phi.min():.3g}, {phi.max():.3g}]",
                "porosity_out_of_range",
            )
        if J.min() <= 0.0:
            raise ForwardModelError(f"{where}: inverted skeleton (min J = {J.min():.3g})", "det_f")

    def state(self) -> NDArray[np.float64]:
        return np.array(self.gfx.vec.FV().NumPy(), copy=True)

    def set_state(self, vec: NDArray[np.float64]) -> None:
        self.gfx.vec.FV().NumPy()[:] = vec


def kozeny_carman(J: Any, phi: Any, phi0: Any) -> Any:
    """Kozeny-Carman permeability over the reference value K0 (eq. 11):
    ``(1 - phi0^2) / phi0^3 * (J phi)^3 / (1 - (J phi)^2)``, 1 in the reference state."""
    Jphi = J * phi
    return (1 - phi0**2) / phi0**3 * Jphi**3 / (1 - Jphi**2)


def timed(fn: Any, *args: Any) -> tuple[Any, float]:
    """``fn(*args)`` and its wall time in s."""
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0
