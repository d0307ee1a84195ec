"""GMRes with a block Gauss-Seidel preconditioner: the Newton systems of 3-D problems.

A sparse direct solver on the whole monolithic Jacobian stops scaling in 3-D (fill-in grows
like ``n^(4/3)`` in memory and ``n^2`` in time for a 3-D mesh).  :class:`BlockGMResInverse`
acts like the factorised Jacobian that :class:`~fbia.plugins.fem.newton.NewtonSolver` uses
(``inverse * res`` and ``Update()``), but solves ``J du = res`` on the free dofs by GMRes
(NGSolve's :class:`~ngsolve.krylovspace.GMResSolver`), preconditioned by one sweep of block
Gauss-Seidel over the given blocks of dofs, each block's diagonal solved by the sparse direct
solver: for ``ale_fsi`` the displacement block (solid elasticity, interface traction, mesh
motion) first, then the fluid block (velocity and pressure) with the displacement's
contribution moved to the right-hand side -- the block-triangular preconditioner of
monolithic FSI solvers (Heil 2004; Gee, Küttler & Wall 2011).
Each block is factorised once per Jacobian, like the whole matrix would be, but the blocks
are smaller: less fill-in, less memory.

>>> inv = BlockGMResInverse(matrix, [disp_free, fluid_free], free, "pardiso")  # doctest: +SKIP
>>> du.data = inv * res                                                       # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

__all__ = ["BlockGMResInverse"]


def _block_gauss_seidel(matrix: Any, inverses: list[Any]) -> Any:
    """One forward block Gauss-Seidel sweep as an NGSolve operator."""
    import ngsolve as ngs

    class Sweep(ngs.BaseMatrix):
        def __init__(self) -> None:
            super().__init__()
            self.rest = matrix.CreateColVector()
            self.part = matrix.CreateColVector()

        def IsComplex(self) -> bool:
            return False

        def Height(self) -> int:
            return int(matrix.height)

        def Width(self) -> int:
            return int(matrix.width)

        def Mult(self, x: Any, y: Any) -> None:
            y[:] = 0.0
            for k, inv in enumerate(inverses):
                self.rest.data = x
                if k:
                    self.rest.data -= matrix * y
                self.part.data = inv * self.rest
                y.data += self.part

    return Sweep()


class BlockGMResInverse:
    """``inverse * res`` by preconditioned GMRes (see the module docstring).

    Parameters
    ----------
    matrix
        The Jacobian (an NGSolve sparse matrix, assembled in place between Newton steps).
    blocks
        Free dofs of each block (NGSolve BitArrays), in the order of the sweep.
    free
        All free dofs (the union of the blocks).
    direct
        NGSolve's name of the sparse direct solver for the blocks.
    tol, maxiter
        Relative residual at which GMRes stops, and its iteration limit; not converging is a
        :class:`RuntimeError` (the Newton solver turns it into a ``linear_solver`` failure).
    """

    def __init__(
        self,
        matrix: Any,
        blocks: list[Any],
        free: Any,
        direct: str,
        tol: float = 1e-12,
        maxiter: int = 200,
    ) -> None:
        import ngsolve as ngs

        self.matrix = matrix
        self.inverses = [matrix.Inverse(b, inverse=direct) for b in blocks]
        self.projector = ngs.Projector(free, True)
        self.tol = tol
        self.maxiter = maxiter
        #: GMRes iterations of every solve since construction
        self.iterations: list[int] = []

    def Update(self) -> None:  # NGSolve's name
        """Refactorise the blocks after the Jacobian was assembled again."""
        for inv in self.inverses:
            inv.Update()

    def __mul__(self, res: Any) -> Any:
        from ngsolve.krylovspace import GMResSolver

        rhs = res.CreateVector()
        rhs.data = self.projector * res
        operator = self.projector @ self.matrix @ self.projector
        pre = _block_gauss_seidel(self.matrix, self.inverses)
        solver = GMResSolver(mat=operator, pre=pre, tol=self.tol, maxiter=self.maxiter)
        sol = solver.Solve(rhs=rhs)
        self.iterations.append(int(solver.iterations))
        if solver.iterations >= self.maxiter:
            raise RuntimeError(f"GMRes did not converge in {self.maxiter} iterations")
        return sol
