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

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from ..fem.newton import sparse_direct_solver


@dataclass(frozen=True)
class SkeletonSettings:
    """Material and numerics of :class:`Skeleton` (stresses in Pa)."""

    kappa: float = 100.0  # bulk modulus of psi_vol, eq. 13a [Pa]
    eta: float = 1.0  # penalty of psi_pen, eq. 13b [Pa]
    order: int = 2
    newton_tol: float = 1e-10  # relative residual
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
        self._inverse: Any = None  # factorisation of the Newton matrix, analysed once
        self._newton_rate = 0.0  # C of e_(k+1) <= C e_k^2, the largest seen so far
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
        """Newton from the current state; returns the number of iterations.

        Stops when the energy norm of the Newton correction, or, once the quadratic rate
        ``C`` (``e_(k+1) <= C e_k^2``) has been seen, twice what it predicts for the next
        correction, falls below ``tol`` (default ``settings.newton_tol``) times that of the
        first one.  Steps are damped to stay admissible (:meth:`_step`).  The sparsity
        pattern never changes, so the factorisation is analysed once and only refactored.
        """
        ngs = self.ngs
        s = self.settings
        tol = s.newton_tol if tol is None else tol
        res = self.gfx.vec.CreateVector()
        du = self.gfx.vec.CreateVector()
        r0 = None
        rn_old = math.inf
        for it in range(1, s.newton_max_iter + 1):
            with ngs.TaskManager():
                self.form.Apply(self.gfx.vec, res)
                self.form.AssembleLinearization(self.gfx.vec)
                if self._inverse is None:
                    self._inverse = self.form.mat.Inverse(
                        self.X.FreeDofs(), inverse=sparse_direct_solver()
                    )
                else:
                    self._inverse.Update()
                du.data = self._inverse * res
            rn = float(np.sqrt(abs(ngs.InnerProduct(du, res))))
            if not math.isfinite(rn):
                raise ForwardModelError(f"{where}: Newton produced NaN", "skeleton_newton")
            r0 = rn if r0 is None else r0
            damped = self._step(du, where)
            if it >= 2 and rn < 0.1 * r0 and not damped:  # quadratic: e_(k+1) <= C e_k^2
                self._newton_rate = max(self._newton_rate, rn / rn_old**2)
            predicted = 2.0 * self._newton_rate * rn**2 if self._newton_rate else math.inf
            if min(rn, predicted) <= tol * max(r0, 1e-300) or rn < 1e-14:
                return it
            rn_old = rn
        raise ForwardModelError(
            f"{where}: skeleton Newton did not converge in {s.newton_max_iter} iterations",
            "skeleton_newton",
        )

    def _step(self, du: Any, where: str) -> bool:
        """``x -= alpha du`` with the largest ``alpha`` in 1, 1/2, ..., 1/256 that keeps the
        state admissible (0 < phi < 1, J > 0): the penalty and volumetric energies (eq. 13)
        are barriers at J phi = 0 and J (1 - phi) = 0, which a full Newton step can jump.
        Returns whether the step was damped; raises when no step length is admissible."""
        x0 = self.gfx.vec.CreateVector()
        x0.data = self.gfx.vec
        alpha = 1.0
        for _ in range(9):
            self.gfx.vec.data = x0 - alpha * du
            phi, J = self._ranges()
            if np.all(np.isfinite(phi)) and 0.0 < phi.min() and phi.max() < 1.0 and J.min() > 0:
                return alpha < 1.0
            alpha *= 0.5
        self.check(where)
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
