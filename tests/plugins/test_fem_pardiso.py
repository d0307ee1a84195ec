"""Pardiso without weighted matching (fbia.plugins.fem.pardiso): exact solves where no pivot
needs perturbing, matching turned on where one does, and Newton's solution unchanged."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

ngs = pytest.importorskip("ngsolve")

from fbia.plugins.fem.newton import NewtonSolver, sparse_direct_solver  # noqa: E402
from fbia.plugins.fem.pardiso import UNMATCHED, unmatched_pardiso  # noqa: E402

pytestmark = pytest.mark.skipif(
    not unmatched_pardiso(), reason="NGSolve's Python MKL Pardiso is not available"
)


def _mesh() -> Any:
    from ngsolve.meshes import MakeStructured2DMesh

    return MakeStructured2DMesh(quads=False, nx=8, ny=8)


def _inverse(matrix: Any, free: Any) -> Any:
    from pyngcore import Flags

    return matrix.Inverse(free, inverse=UNMATCHED, flags=Flags({"refinement": 0}))


def _relative_residual(matrix: Any, inverse: Any, free: Any) -> float:
    """max |b - A x| / max |b| on the free dofs for x = A^-1 b, b random (fixed seed)."""
    mask = np.array(free, dtype=bool)
    b = matrix.CreateColVector()
    rng = np.random.default_rng(7)
    b.FV().NumPy()[:] = np.where(mask, rng.standard_normal(len(mask)), 0.0)
    x = b.CreateVector()
    x.data = inverse * b
    r = b.CreateVector()
    r.data = b - matrix * x
    return float(np.max(np.abs(r.FV().NumPy()[mask])) / np.max(np.abs(b.FV().NumPy())))


def test_a_sound_diagonal_factorises_without_matching_to_round_off() -> None:
    """Convection-diffusion (nonsymmetric, diagonally dominant pivots): no pivot perturbed,
    no matching, after a refactorisation too, and the solve exact to round-off."""
    fes = ngs.H1(_mesh(), order=3, dirichlet=".*")
    u, v = fes.TnT()
    form = ngs.BilinearForm(fes)
    form += (ngs.grad(u) * ngs.grad(v) + ngs.CF((20, 5)) * ngs.grad(u) * v) * ngs.dx
    form.Assemble()
    inverse = _inverse(form.mat, fes.FreeDofs())
    assert not inverse.matching and inverse._params[12] == 0 and inverse._params[13] == 0
    assert _relative_residual(form.mat, inverse, fes.FreeDofs()) < 1e-12
    inverse.Update()
    assert not inverse.matching


def test_a_saddle_point_whose_pivots_get_perturbed_turns_matching_on() -> None:
    """Stokes (a zero pressure block): unmatched, Pardiso perturbs pivots; the solver then
    analyses again with matching, perturbs none, and solves accurately."""
    mesh = _mesh()
    space = ngs.VectorH1(mesh, order=2, dirichlet=".*") * ngs.H1(mesh, order=1)
    (u, p), (v, q) = space.TnT()
    form = ngs.BilinearForm(space)
    form += (
        ngs.InnerProduct(ngs.grad(u), ngs.grad(v))
        - ngs.div(u) * q
        - ngs.div(v) * p
        + 0.3 * u[0] * v[1]  # nonsymmetric
    ) * ngs.dx
    form.Assemble()
    free = space.FreeDofs()
    free.Clear(space.ndof - 1)  # the pressure's constant
    inverse = _inverse(form.mat, free)
    assert inverse.matching and inverse.perturbed > 0
    assert inverse._params[12] == 1 and inverse._params[13] == 0
    assert _relative_residual(form.mat, inverse, free) < 1e-9


def test_a_refactorisation_that_perturbs_pivots_turns_matching_on() -> None:
    """A saddle point stabilised by -eps p q factorises unmatched without perturbed pivots;
    the same pattern with eps = 0, refactorised (``Update``, as Newton does), perturbs some:
    the solver analyses again with matching and solves accurately."""
    mesh = _mesh()
    space = ngs.VectorH1(mesh, order=2, dirichlet=".*") * ngs.H1(mesh, order=1)
    (u, p), (v, q) = space.TnT()
    eps = ngs.Parameter(1.0)
    form = ngs.BilinearForm(space)
    form += (
        ngs.InnerProduct(ngs.grad(u), ngs.grad(v))
        - ngs.div(u) * q
        - ngs.div(v) * p
        + 0.3 * u[0] * v[1]
        - eps * p * q
    ) * ngs.dx
    form.Assemble()
    free = space.FreeDofs()
    free.Clear(space.ndof - 1)
    inverse = _inverse(form.mat, free)
    assert not inverse.matching and inverse._params[13] == 0
    assert _relative_residual(form.mat, inverse, free) < 1e-12
    eps.Set(0.0)
    form.Assemble()
    inverse.Update()
    assert inverse.matching and inverse.perturbed > 0 and inverse._params[13] == 0
    assert _relative_residual(form.mat, inverse, free) < 1e-9


def test_newton_without_matching_reaches_the_matched_solution() -> None:
    """NewtonSolver(matching=False) uses the unmatched inverse and converges to the matched
    solver's solution to the tolerance; matching=True keeps NGSolve's Pardiso."""
    from test_fem_newton import Cubic

    if sparse_direct_solver() != "pardiso":
        pytest.skip("Pardiso is not NGSolve's direct solver here")
    states = []
    for matching in (True, False):
        system = Cubic()
        newton = NewtonSolver(system, 1e-10, 12, "pardiso", matching=matching)
        assert newton.solve().converged
        assert hasattr(newton.inverse, "matching") is not matching
        states.append(system.gfu.vec.FV().NumPy().copy())
    assert np.max(np.abs(states[0] - states[1])) < 1e-9 * np.max(np.abs(states[0]))
