"""The shared Newton solver (fbia.plugins.fem.newton) on its own, on a small nonlinear
problem: -div grad u + u^3 = f on the unit square, u = 0 on the boundary."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

ngs = pytest.importorskip("ngsolve")

from fbia.plugins.fem.newton import NewtonFailure, NewtonSolver  # noqa: E402


class Cubic:
    """-Δu + u³ = f as a NonlinearSystem."""

    def __init__(self, h: float = 0.2, bound: float = np.inf) -> None:
        from ngsolve.meshes import MakeStructured2DMesh

        mesh = MakeStructured2DMesh(quads=False, nx=int(1 / h), ny=int(1 / h))
        self.fes = ngs.H1(mesh, order=2, dirichlet=".*")
        u, v = self.fes.TnT()
        self.form = ngs.BilinearForm(self.fes)
        f = 200.0 * ngs.sin(np.pi * ngs.x) * ngs.sin(np.pi * ngs.y)
        self.form += (ngs.grad(u) * ngs.grad(v) + u**3 * v - f * v) * ngs.dx
        self.gfu = ngs.GridFunction(self.fes)
        self._free = np.array(self.fes.FreeDofs(), dtype=bool)
        self.bound = bound

    vector = property(lambda self: self.gfu.vec)
    matrix = property(lambda self: self.form.mat)
    free = property(lambda self: self.fes.FreeDofs())
    free_mask = property(lambda self: self._free)

    def residual(self, res: Any) -> None:
        self.form.Apply(self.gfu.vec, res)

    def assemble_jacobian(self) -> None:
        self.form.AssembleLinearization(self.gfu.vec)

    def scales(self) -> np.ndarray:
        return np.ones(len(self._free))

    def admissible(self) -> bool:
        return bool(np.max(self.gfu.vec.FV().NumPy()) < self.bound)


def test_newton_with_chord_steps_reaches_ngsolves_own_newton() -> None:
    system = Cubic()
    rep = NewtonSolver(system, 1e-10, 12, "umfpack").solve("cubic")
    assert rep.converged and rep.norms[-1] < 1e-8
    assert rep.jacobians <= 5 < rep.iterations  # chord steps once the updates contract
    anchor = Cubic()
    ngs.solvers.Newton(
        anchor.form,
        anchor.gfu,
        freedofs=anchor.fes.FreeDofs(),
        maxerr=1e-13,
        printing=False,
        inverse="umfpack",
    )
    diff = system.gfu.vec.FV().NumPy() - anchor.gfu.vec.FV().NumPy()
    assert np.max(np.abs(diff)) < 1e-9 * np.max(np.abs(anchor.gfu.vec.FV().NumPy()))


def test_a_converged_factorisation_serves_the_next_solve_as_chord_steps() -> None:
    system = Cubic()
    solver = NewtonSolver(system, 1e-10, 12, "umfpack")
    first = solver.solve()
    system.gfu.vec.FV().NumPy()[:] *= 1.0 + 1e-5  # a nearby start
    second = solver.solve()
    assert second.converged and second.jacobians == 0 < first.jacobians


def test_per_solve_tolerance_stops_earlier() -> None:
    loose = NewtonSolver(Cubic(), 1e-10, 12, "umfpack").solve(tol=1e-2)
    tight = NewtonSolver(Cubic(), 1e-10, 12, "umfpack").solve()
    assert loose.converged and loose.iterations < tight.iterations


def test_inadmissible_updates_are_halved_then_fail_with_the_systems_reason() -> None:
    system = Cubic(bound=1e-3)  # the solution (max about 9) is never admissible
    solver = NewtonSolver(system, 1e-10, 12, "umfpack", max_halvings=3, inadmissible="too_big")
    with pytest.raises(NewtonFailure) as err:
        solver.solve("cubic")
    assert err.value.reason == "too_big"
    assert np.max(system.gfu.vec.FV().NumPy()) < 1e-3  # the last admissible state is kept
