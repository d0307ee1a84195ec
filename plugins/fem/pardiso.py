"""MKL Pardiso without weighted matching, with it where pivots need perturbing.

NGSolve's Python wrapper of MKL Pardiso (``ngsolve.solvers.mkl_pardiso.MKLPardiso``) turns on
Pardiso's nonsymmetric weighted matching and scaling (``iparm[12] = 1``, Intel's default for
nonsymmetric matrices) for every nonsymmetric matrix.  Matching permutes large entries onto
the diagonal before the fill-reducing ordering, so that a matrix with zero or tiny diagonal
entries factorises without perturbed pivots; on a matrix whose diagonal pivots are sound
already it costs a maximum-weight matching in the analysis and a worse ordering for fill.

:class:`PardisoUnmatched` factorises without it and looks at what Pardiso reports
(``iparm[13]``, the number of perturbed pivots, after every numerical factorisation): if a
pivot had to be perturbed -- the factors are then those of a nearby matrix, and without
iterative refinement (fbia's Newton turns it off) the solves would be inaccurate -- it
analyses and factorises the same matrix again with matching, and keeps matching from then on.
A solver that needed no perturbed pivot solves with the exact LU factors of the matrix, as
the matched one does: Newton's iterates are the same to round-off.

Registered with NGSolve as the inverse type :data:`UNMATCHED` when MKL Pardiso is available
(:func:`unmatched_pardiso`); ``NewtonSolver(matching=False)`` uses it.
Why and where fbia uses it, with its figures: ``ale_fsi``'s 3-D direct solve (``solver.py``),
the CHANGELOG (issue 47).
"""

from __future__ import annotations

from typing import Any

from ngsolve import la as ngla
from ngsolve.solvers import mkl_pardiso

__all__ = ["UNMATCHED", "PardisoUnmatched", "unmatched_pardiso"]

#: NGSolve's name of the inverse type (``BaseMatrix.Inverse(freedofs, inverse=UNMATCHED)``).
UNMATCHED = "pardiso_unmatched"

#: Pardiso's ``iparm`` entries (0-based, as NGSolve's wrapper keeps them in ``_params``)
MATCHING = 12
PERTURBED_PIVOTS = 13


class PardisoUnmatched(mkl_pardiso.MKLPardiso):
    """NGSolve's ``MKLPardiso`` without weighted matching until a pivot is perturbed."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        #: whether Pardiso matches (False until a factorisation perturbed a pivot)
        self.matching = False
        #: the pivots the unmatched factorisation perturbed when matching was turned on
        self.perturbed = 0
        super().__init__(*args, **kwargs)

    def _call_pardiso(self, phase: int) -> None:
        if phase in (11, 12, 13) and not self.matching:  # an analysis decides the matching;
            self._params[MATCHING] = 0  # with it, NGSolve's own setting stands
        super()._call_pardiso(phase)

    def Factor(self) -> None:  # noqa: N802 (NGSolve's name)
        super().Factor()
        if not self.matching and self._params[PERTURBED_PIVOTS] > 0:
            self.matching = True
            self.perturbed = int(self._params[PERTURBED_PIVOTS])
            self.Analyze()  # analysis and factorisation (phase 12), now with matching
            super().Factor()  # marks the factorisation current, computes nothing


def unmatched_pardiso() -> bool:
    """Register :class:`PardisoUnmatched` as :data:`UNMATCHED` (again: harmless); False if MKL
    Pardiso is not available (the caller keeps its solver)."""
    if getattr(mkl_pardiso, "_pardiso", None) is None:
        return False
    ngla.RegisterInverseType(UNMATCHED, PardisoUnmatched)
    return True
