"""Solution algorithms of the monolithic ALE FSI problem: steady states (Newton with
continuation in the inflow rate) and transient runs (one-step-theta).

:class:`AleFsiSolver` is an :class:`~fbia.plugins.ale_fsi.forms.AleFsiProblem` with the shared
:class:`~fbia.plugins.fem.newton.NewtonSolver` and
:class:`~fbia.plugins.fem.continuation.ArclengthContinuation` of :mod:`fbia.plugins.fem`.

>>> from fbia.plugins.fem.flow_cell import build_flow_cell
>>> from fbia.plugins.ale_fsi.solver import AleFsiSolver, SolverSettings
>>> solver = AleFsiSolver(build_flow_cell(mesh_size=0.2), SolverSettings())  # doctest: +SKIP
>>> solver.set_materials({"solid": (400.0, 0.3)})                             # doctest: +SKIP
>>> report = solver.solve_steady(100.0)                                       # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...core.errors import ForwardModelError
from ..fem.continuation import ArclengthContinuation
from ..fem.flow_cell import interface_chains
from ..fem.newton import ChordRule, NewtonFailure, NewtonSolver, StepReport, sparse_direct_solver
from .forms import AleFsiProblem, SolverSettings
from .materials import lame

if TYPE_CHECKING:
    import ngsolve

__all__ = ["AleFsiSolver", "SolverSettings", "interface_chains", "lame"]


class AleFsiSolver(AleFsiProblem):
    """The ALE FSI problem with its solvers (see the module docstring).

    Parameters
    ----------
    mesh
        A mesh named per :mod:`fbia.plugins.fem.flow_cell`.
    settings
        Physics and numerics.
    """

    def __init__(self, mesh: ngsolve.Mesh, settings: SolverSettings) -> None:
        # MKL (Pardiso) reads its thread count when NGSolve first loads it; on a shared
        # machine its spinning threads cost more than they give, so follow ``threads``
        # unless the user has set MKL_NUM_THREADS.
        os.environ.setdefault("MKL_NUM_THREADS", str(max(1, int(settings.threads))))
        self.linear_solver = direct = sparse_direct_solver()
        blocks = None
        if settings.linear_solver == "block_gmres":
            blocks = self.preconditioner_blocks
            self.linear_solver = f"block_gmres({direct})"
        elif settings.linear_solver != "direct":
            raise ValueError(f"unknown linear solver {settings.linear_solver!r}")
        # 3-D with the direct solver: a fresh Jacobian costs tens of chord steps, and the
        # choices below follow from that; 2-D and block_gmres keep NGSolve's and fbia's
        # defaults and their results bit for bit
        costly = mesh.dim == 3 and blocks is None
        self._newton = NewtonSolver(
            self,
            settings.newton_tol,
            settings.newton_max_iter,
            direct,
            blocks=blocks,
            # nested dissection: in 3-D it halved the analysis and factorisation against
            # minimum degree (benchmarks/bench_ale_fsi_3d.py); 2-D keeps NGSolve's ordering
            ordering="metis" if mesh.dim == 3 else None,
            threads=max(1, int(settings.threads)),
            # Pardiso's weighted matching off unless a factorisation perturbs a pivot
            # (fbia.plugins.fem.pardiso): the 3-D dome's Jacobian needs none with a linear
            # mesh motion
            matching=not costly,
        )
        if costly:
            # with the direct solver a fresh Jacobian costs tens of chord steps in 3-D and a
            # few in 2-D, where the rule gained nothing: 2-D keeps the default rule and its
            # results bit for bit; a chord step of block_gmres is a GMRes solve, not a
            # back-substitution, so it keeps the default rule too (the timings:
            # benchmarks/bench_lm_tangents.py and the CHANGELOG)
            self._newton.chord = ChordRule.costly_jacobian()
        #: a solve from rest starts from the inflow profile in the whole fluid (:meth:`newton`)
        self.start_from_inflow = costly
        #: the tangents factorise the Jacobian at the converged state before they solve,
        #: instead of refining with Newton's last factorisation: in 3-D with the direct solver
        #: a refactorisation (0.37-0.39 s on the dome) costs less than the 6-26 refinement
        #: sweeps (a product with the Jacobian and a back-substitution, ~35 ms each) it saves;
        #: in 2-D they cost the same (benchmarks/bench_lm_tangents.py, bench_lm_vs_scipy.py)
        self.tangents_refactorise = costly
        self._continuation = ArclengthContinuation(
            self, self._newton, self.newton, settings.continuation_min_fraction, unit="mm^2/s"
        )
        super().__init__(mesh, settings)

    def _on_new_forms(self) -> None:
        self._newton.reset()

    def newton(self, where: str = "Newton") -> StepReport:
        """Solve the current nonlinear system with :class:`~fbia.plugins.fem.newton.NewtonSolver`
        (consistent Jacobian, chord steps, damping against inverted elements, Pardiso);
        raises NewtonFailure.  Quasi-static: the solid velocity is zero first.

        Where a fresh Jacobian is costly (:attr:`start_from_inflow`: 3-D, direct solver), a
        solve from rest (every free unknown zero) starts from the inflow profile carried
        through the whole fluid
        (:meth:`~fbia.plugins.ale_fsi.forms.AleFsiProblem.fill_with_inflow`): the first
        Jacobian then holds the convection of a flow of the right size (an Oseen step)
        instead of none (a Stokes step).  On the 3-D dome at the recommended settings the
        second Jacobian's update is then 0.68 (1.15 from rest) and its chord steps contract to
        the tolerance (with the costly rule's slower steps near it,
        :data:`~fbia.plugins.fem.newton.COSTLY_STEPS_TO_TOLERANCE`): 2 Jacobians, where from
        rest that Jacobian's first chord update (0.53) calls for a third (CHANGELOG, issue
        47).  2-D keeps the start from rest."""
        if not self.transient:
            x = self.gfu.vec.FV().NumPy()
            x[self._v_solid] = 0.0  # the solid is at rest
            if self.start_from_inflow and not x[self.free_mask].any():
                self.fill_with_inflow()
        return self._newton.solve(where)

    @property
    def newton_solver(self) -> NewtonSolver:
        """The Newton solver, with the factorisation of its last Jacobian (the tangents solve
        with it: :mod:`fbia.plugins.ale_fsi.sensitivities`)."""
        return self._newton

    @property
    def timings(self) -> dict[str, float]:
        """Seconds spent assembling and solving (Newton and continuation), since the last
        reset (assign a fresh dict)."""
        return self._newton.timings

    @timings.setter
    def timings(self, value: dict[str, float]) -> None:
        self._newton.timings = value

    # -- what other models built on this solver read from its state (growth) -----------------
    def interface_nodal_forces(self) -> Any:
        """The fluid's force on each interface vertex (``AleFsiPostprocess``)."""
        from .postprocess import AleFsiPostprocess

        return AleFsiPostprocess(self).interface_nodal_forces()

    def write_vtu(self, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
        """The current state as a VTU file (``output.write_vtu``), with ``extra`` vertex
        fields."""
        from .output import write_vtu

        return write_vtu(self, path, extra)

    # -- quasi-static solution with continuation ---------------------------------------------
    def solve_steady(
        self, rate: float, where: str = "", continuation: bool = True, direct: bool = True
    ) -> StepReport:
        """Steady state at inflow ``rate``: Newton from the current state, then continuation.

        First (if ``direct``) Newton straight at ``rate`` from the current state (rest, a warm
        start or a lower level).  If that fails (or at once, without ``direct``) and
        ``continuation`` is set, the branch of steady states through the current state is
        followed (:meth:`~fbia.plugins.fem.continuation.ArclengthContinuation.follow`, locally
        parametrised so that it can pass limit points)
        until it passes ``rate`` -- then Newton at ``rate`` from the state interpolated on the
        branch -- or turns back at a limit point below ``rate``, which is reported as
        :class:`ForwardModelError` with reason ``"limit_point"``: the steady problem has no
        solution on that branch, whatever the solver.  A branch that cannot be followed any
        further (steps below ``continuation_min_fraction`` of the first) fails with the reason
        of the last Newton failure; both messages say where the solid is compressed most,
        which is where soft Saint Venant-Kirchhoff biofilms lose their stiffness.
        """
        if self.transient:
            self._build_forms(transient=False)
        where = where or f"inflow rate {rate:g} mm^2/s"
        start = float(self.inflow_rate.Get())
        if not direct and continuation and rate != start:
            rep = self._continuation.follow(rate, where, StepReport())
            rep.converged = True
            return rep
        x_start = self.state()
        self.set_inflow(rate)
        try:
            rep = self.newton(where)
        except NewtonFailure as fail:
            self.set_state(x_start)
            self.set_inflow(start)
            if not continuation or rate == start:
                raise ForwardModelError(str(fail), fail.reason) from None
            first = StepReport(iterations=len(fail.norms), jacobians=fail.jacobians)
            rep = self._continuation.follow(rate, where, first)
        rep.converged = True
        return rep

    # -- transient solution (one-step-theta) ----------------------------------------------------
    def solve_transient(
        self,
        rate: float,
        times: list[float],
        time_step: float,
        ramp_time: float,
        ramp_steps: int,
        on_time: Any = None,
    ) -> StepReport:
        """March from rest to the largest of ``times``; call ``on_time(t)`` at each of them.

        The inflow rate follows a cosine ramp in ``ramp_steps`` stairs over ``ramp_time``
        (Paper A: ramped over 10 s, read at 15 s), then stays at ``rate``.
        """
        if not self.transient:
            self._build_forms(transient=True)
        total = StepReport()
        self.set_state(None)
        self.gfu_old.vec[:] = 0.0
        self.inflow_rate.Set(0.0)
        wanted = sorted(set(float(t) for t in times))
        t_end = wanted[-1]
        n = int(math.ceil(t_end / time_step - 1e-9))
        # the uniform grid plus the requested times, so that every snapshot is hit exactly
        grid = sorted({min(i * time_step, t_end) for i in range(1, n + 1)} | set(wanted) - {0.0})
        if 0.0 in wanted:
            self.check_state("time 0 s")
            if on_time is not None:
                on_time(0.0)
        t = 0.0
        for t_new in grid:
            self.dt.Set(t_new - t)
            self.gfu_old.vec.data = self.gfu.vec
            self.set_inflow(rate * ramp(t_new, ramp_time, ramp_steps))
            try:
                rep = self.newton(f"time {t_new:g} s")
            except NewtonFailure as fail:
                raise ForwardModelError(str(fail), fail.reason) from None
            total.iterations += rep.iterations
            total.jacobians += rep.jacobians
            total.assembly_time += rep.assembly_time
            total.solve_time += rep.solve_time
            t = t_new
            if t in wanted:
                self.check_state(f"time {t:g} s")
                if on_time is not None:
                    on_time(t)
        total.converged = True
        return total


def ramp(t: float, ramp_time: float, steps: int) -> float:
    """Cosine ramp of the inflow in ``steps`` stairs over ``ramp_time`` (Paper A), 0 -> 1."""
    if t >= ramp_time or ramp_time <= 0.0:
        return 1.0
    if t <= 0.0:
        return 0.0
    width = ramp_time / steps
    k = min(int(t // width), steps - 1)
    local = (t - k * width) / width
    return (k + 0.5 * (1.0 - math.cos(math.pi * local))) / steps
