"""Arclength continuation of a steady problem in a load parameter (the local
parametrisation of Rheinboldt & Burkardt 1983), on top of
:class:`~fbia.plugins.fem.newton.NewtonSolver`.

The problem (:class:`LoadedSystem`) adds to a :class:`~fbia.plugins.fem.newton.NonlinearSystem`
a scalar load (``ale_fsi``: the inflow rate) that enters through Dirichlet values: its
current value, how to set it, the derivative of the state's Dirichlet values with respect to
it, the state on all dofs, the dof blocks of its fields (for scaling) and a sentence that says
where a failing state is worst.  :class:`ArclengthContinuation` follows the branch of
solutions from the current state to a requested load, through limit points of the state, and
reports a limit point of the load (a fold: no solution on the branch beyond it) as
:class:`fbia.ForwardModelError` with reason ``"limit_point"``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from .newton import NewtonFailure, NewtonSolver, NonlinearSystem, StepReport

__all__ = ["ArclengthContinuation", "LoadedSystem"]


class LoadedSystem(NonlinearSystem, Protocol):
    """A :class:`~fbia.plugins.fem.newton.NonlinearSystem` with a scalar load."""

    @property
    def load(self) -> float:
        """The current value of the load parameter."""

    def set_load(self, value: float) -> None:
        """Set the load (and the Dirichlet values that follow it)."""

    def load_direction(self) -> NDArray[np.float64]:
        """d(state)/d(load) of the Dirichlet values (zero elsewhere)."""

    def state(self) -> NDArray[np.float64]:
        """A copy of the state on all dofs."""

    def set_state(self, vec: NDArray[np.float64] | None) -> None:
        """Set the state on all dofs."""

    def field_blocks(self) -> list[slice]:
        """The dof ranges of the fields (each is scaled by its own size)."""

    def failure_note(self) -> str:
        """Where the current state is worst, for failure messages."""


class ArclengthContinuation:
    """Continuation along the branch of steady states (see :meth:`follow`).

    Parameters
    ----------
    system
        The problem.
    solver
        Its Newton solver (the factorisation is shared).
    newton
        The full Newton solve at a fixed load (the system's own, which may prepare the state).
    min_fraction
        Smallest step, relative to the first; below it the continuation fails.
    unit
        The load's unit, for messages.
    """

    #: A corrector ends, its step too long, when the chord update right after a fresh Newton
    #: step is at least this multiple of that step's update: Deuflhard's natural monotonicity
    #: test (Deuflhard 2004, ch. 3), the chord update being his simplified Newton correction,
    #: and his continuation's cue to shorten the step (ch. 5).  On ``ale_fsi``'s failed runs
    #: every corrector step that ended so also failed under the older rule alone (a third
    #: fresh Newton step that does not halve the update), after two more Jacobians; the
    #: corrector steps that converged had ratios of 0.5 at most
    #: (``benchmarks/bench_lm_vs_scipy.py``).
    max_chord_ratio: float = 1.0

    def __init__(
        self,
        system: LoadedSystem,
        solver: NewtonSolver,
        newton: Callable[[str], StepReport],
        min_fraction: float,
        unit: str = "",
    ) -> None:
        self.system = system
        self.solver = solver
        self.newton = newton
        self.min_fraction = min_fraction
        self.unit = unit

    def follow(self, rate: float, where: str, total: StepReport) -> StepReport:
        """Follow the branch from the current state to load ``rate`` (Rheinboldt's local
        parametrisation); adds the Newton work to ``total`` and returns it.

        The unknowns are the free dofs ``y`` and the load parameter ``mu`` (rate = start + mu
        (rate - start), so ``mu`` runs from 0 to 1); the Dirichlet inflow values follow ``mu``.
        All are measured in scaled units: each field relative to its size over the whole jump.
        Each step predicts along the tangent ``t`` of the branch (``J dy/dmu = -dR/dmu``), scaled
        to a largest component of 1, by a step ``ds`` and corrects with Newton's method on
        ``R(y, mu) = 0`` with that largest component held at its predicted value -- ``mu``
        itself far from a limit point (plain continuation in the rate), a state dof near one,
        so the corrector passes limit points, also local ones such as the collapse of a single
        corner element.  The bordered Newton system is solved with two back-substitutions of
        the factorised Jacobian.  ``ds`` is halved after a failed corrector and grows after an
        easy one; the continuation fails when it falls below ``continuation_min_fraction`` of
        the first step.  A tangent whose ``mu`` component changes sign marks a limit point
        (fold): the branch turns back there.
        """
        free = self.system.free_mask
        lam0 = self.system.load
        jump = rate - lam0
        dy_dmu = self._branch_derivative(jump, where)
        # per-field size over the jump: the state, its linear prediction or a physical floor
        full = np.zeros(len(free))
        full[free] = dy_dmu
        size = np.maximum(np.abs(self.system.state()), np.abs(full))
        floor = self.system.scales()
        scale = np.empty(len(free))
        for blk in self.system.field_blocks():
            scale[blk] = max(float(size[blk].max(initial=0.0)), float(floor[blk].max()))
        scale = scale[free]

        def unit(dy: NDArray[np.float64]) -> NDArray[np.float64]:
            """The tangent (dy/dmu, 1) in scaled units, largest component 1 in size."""
            t = np.append(dy / scale, 1.0)
            return t / np.abs(t).max()

        t = unit(dy_dmu)
        z = np.append(self.system.state()[free] / scale, 0.0)  # scaled (y, mu)
        ds = 0.5 / abs(t[-1])  # the first prediction goes half way
        ds_min = self.min_fraction * ds
        history = [(0.0, self.system.state())]
        while True:
            z_pred = z + ds * t
            lead = int(np.argmax(np.abs(t)))
            label = f"{where} (continuation near {lam0 + z_pred[-1] * jump:.4g} {self.unit})"
            try:
                its, dy_dmu = self._corrector(z_pred, lead, scale, lam0, jump, label, total)
            except NewtonFailure as fail:
                self.system.set_state(history[-1][1])
                self.system.set_load(lam0 + z[-1] * jump)
                ds *= 0.5
                if ds < ds_min:
                    raise ForwardModelError(
                        f"{where}: continuation failed at {lam0 + z[-1] * jump:.4g} {self.unit} "
                        f"({fail}); there {self.system.failure_note()}",
                        fail.reason,
                    ) from None
                continue
            x_new = self.system.state()
            mu_new = (self.system.load - lam0) / jump
            t_new = unit(dy_dmu)
            if t_new[lead] * t[lead] < 0.0:
                t_new = -t_new  # keep the orientation along the branch
            if mu_new >= 1.0:
                # passed the requested rate: Newton there from the state interpolated on the branch
                mu_prev, x_prev = history[-1]
                theta = (1.0 - mu_prev) / (mu_new - mu_prev)
                self.system.set_state(x_prev + theta * (x_new - x_prev))
                self.system.set_load(rate)
                try:
                    rep = self.newton(where)
                except NewtonFailure as fail:
                    total.iterations += len(fail.norms)
                    total.jacobians += fail.jacobians
                    self.system.set_state(x_prev)
                    self.system.set_load(lam0 + mu_prev * jump)
                    ds *= 0.5
                    if ds < ds_min:
                        raise ForwardModelError(str(fail), fail.reason) from None
                    continue
                total.iterations += rep.iterations
                total.jacobians += rep.jacobians
                return total
            history.append((mu_new, x_new))
            if t_new[-1] <= 0.0:
                mu_max = max(m for m, _ in history)
                self.system.set_state(max(history, key=lambda h: h[0])[1])
                raise ForwardModelError(
                    f"{where}: no steady state -- the branch of steady states turns back at a "
                    f"limit point near {lam0 + mu_max * jump:.4g} {self.unit} (continuation from "
                    f"{lam0:g} {self.unit}); there {self.system.failure_note()}",
                    "limit_point",
                )
            z, t = np.append(x_new[free] / scale, mu_new), t_new
            ds *= 2.0 if its <= 2 else (1.25 if its <= 3 else (1.0 if its <= 4 else 0.6))

    def _branch_derivative(self, jump: float, where: str) -> NDArray[np.float64]:
        """``dy/dmu = -J^-1 dR/dmu`` at the current state (free dofs), with a fresh Jacobian."""
        self.system.assemble_jacobian()
        self.solver.factorise(where)
        self.solver.chord_ok = False
        return -self._solve_rate_derivative(jump, where)

    def _solve_rate_derivative(self, jump: float, where: str) -> NDArray[np.float64]:
        """``J^-1 dR/dmu`` with the factorised Jacobian; ``dR/dmu = K g jump``."""
        g = self.system.vector.CreateVector()
        g.FV().NumPy()[:] = self.system.load_direction() * jump
        kg = self.system.vector.CreateVector()
        self.system.matrix.Mult(g, kg)
        out = self.system.vector.CreateVector()
        self.solver.linear_solve(out, kg, where)
        return np.array(out.FV().NumPy()[self.system.free_mask], copy=True)

    def _corrector(
        self,
        z_pred: NDArray[np.float64],
        lead: int,
        scale: NDArray[np.float64],
        lam0: float,
        jump: float,
        where: str,
        total: StepReport,
    ) -> tuple[int, NDArray[np.float64]]:
        """Newton on one continuation step, component ``lead`` of ``z`` held at ``z_pred``.

        ``z = (y / scale, mu)``.  The Newton system ``J dy + dR/dmu dmu = -R`` with the
        constraint ``dz[lead] = z_pred[lead] - z[lead]`` is solved by block elimination: with
        ``a = J^-1 R`` and ``b = J^-1 dR/dmu``, ``dy = -a - dmu b``.  As in :meth:`newton`,
        after the first step the factorised Jacobian is tried again (chord step) and kept if
        the update contracts by 4x.  Converged at a scaled update below 1e-8 (the point at the
        requested rate is then solved by :meth:`newton` to the full tolerance).  The step was
        too long, and the corrector gives up at once, when the chord update right after a fresh
        Newton step is not smaller than that step's update (:attr:`max_chord_ratio`), or when
        a third fresh Newton step does not halve the update.  Returns (fresh Jacobians, dy/dmu
        at the solution); raises NewtonFailure.
        """
        free_np = self.system.free_mask
        x_np = self.system.vector.FV().NumPy()
        x_np[free_np] = z_pred[:-1] * scale
        mu = float(z_pred[-1])
        self.system.set_load(lam0 + mu * jump)
        res = self.system.vector.CreateVector()
        du = self.system.vector.CreateVector()
        norms: list[float] = []
        jacobians = 0
        fresh_last = False  # whether norms[-1] is a fresh Jacobian's update
        self.solver.chord_ok = False

        def update(fresh: bool) -> tuple[NDArray[np.float64], float, NDArray[np.float64], float]:
            t0 = time.perf_counter()
            if fresh:
                self.system.assemble_jacobian()
                self.solver.factorise(where)
            t1 = time.perf_counter()
            self.solver.linear_solve(du, res, where)
            a = np.array(du.FV().NumPy()[free_np], copy=True)
            if not np.all(np.isfinite(a)):
                raise NewtonFailure(f"{where}: the linear solve returned NaN", "newton_nan")
            b = self._solve_rate_derivative(jump, where)
            self.solver.timings["assembly"] += t1 - t0
            self.solver.timings["solve"] += time.perf_counter() - t1
            y = x_np[free_np]
            if lead == len(z_pred) - 1:  # mu held: a plain Newton step at fixed rate
                dmu = z_pred[-1] - mu
            else:  # y[lead] held: dy[lead] = -a[lead] - dmu b[lead] = target - y[lead]
                dmu = (a[lead] + z_pred[lead] * scale[lead] - y[lead]) / -b[lead]
            dy = -a - dmu * b
            norm = max(float(np.max(np.abs(dy) / self.system.scales()[free_np])), abs(dmu))
            return dy, dmu, b, norm

        for it in range(1, 4 * self.solver.max_jacobians + 1):
            self.system.residual(res)
            total.iterations += 1
            accepted = False
            if it > 1:  # chord step with the last factorisation
                dy, dmu, b, norm = update(fresh=False)
                accepted = norm <= min(0.25 * norms[-1], 0.1)
                if fresh_last and norm >= self.max_chord_ratio * norms[-1]:
                    raise NewtonFailure(
                        f"{where}: the continuation step does not converge (a chord update of "
                        f"{norm:.2g} after a Newton update of {norms[-1]:.2g})",
                        "newton_divergence",
                    )
            if not accepted:
                if jacobians >= self.solver.max_jacobians // 2:
                    break
                dy, dmu, b, norm = update(fresh=True)
                jacobians += 1
                total.jacobians += 1
                if jacobians >= 3 and norm > 0.5 * norms[-1]:
                    # from a predictor on the tangent Newton contracts at once; if not, a
                    # smaller step is cheaper than more iterations
                    raise NewtonFailure(
                        f"{where}: the continuation step does not converge (scaled updates "
                        f"{', '.join(f'{n:.2g}' for n in [*norms[-2:], norm])})",
                        "newton_divergence",
                    )
            norms.append(norm)
            fresh_last = not accepted
            y0, mu0 = x_np[free_np].copy(), mu
            for _ in range(6):
                x_np[free_np] = y0 + dy
                mu = mu0 + dmu
                self.system.set_load(lam0 + mu * jump)
                if self.system.admissible():
                    break
                dy, dmu = 0.5 * dy, 0.5 * dmu
            else:
                raise NewtonFailure(
                    f"{where}: every damped update inverts elements", "ale_jacobian"
                )
            if norm <= 1e-8:
                return jacobians, -b
        raise NewtonFailure(
            f"{where}: the continuation step did not converge "
            f"(scaled updates {', '.join(f'{n:.2g}' for n in norms[-3:])})",
            "newton_divergence",
        )
