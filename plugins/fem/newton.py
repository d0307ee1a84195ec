"""A generic Newton solver for discretised nonlinear problems on NGSolve.

Modelled on NGSolve's ``NewtonSolver(a, u, freedofs, inverse)`` and dolfinx's
``NonlinearProblem`` + ``NewtonSolver``: the problem (:class:`NonlinearSystem`) gives the
state vector, the residual, the consistent Jacobian, the free dofs, the scale of each dof and
whether a state is admissible; :class:`NewtonSolver` owns the factorisation and the iteration.

The iteration (what ``ale_fsi`` needs, stiff coupled systems solved to a tolerance):

* the update is measured per dof, scaled by :meth:`NonlinearSystem.scales`, in the max norm;
  converged when that scaled update is below ``tol``, or when the error it leaves, estimated
  from the contraction of the last two updates, is;
* after every undamped step the factorised Jacobian is tried again (a chord step: one residual
  and one back-substitution); its update is taken if it is below 0.1 and at most a quarter of
  the previous one, else the Jacobian is assembled afresh at the same point.  A solve that
  starts after a converged one (a warm start) takes the old factorisation's first update if it
  is below 2.5e-4 (:class:`ChordRule`, the default).  Where a fresh Jacobian costs tens of
  chord steps (:meth:`ChordRule.costly_jacobian`) chord steps go on while the updates halve,
  and a warm start's first update is taken up to 0.3 on trust: the second update measures its
  contraction, and if it is larger than the first the first is undone before the fresh
  Jacobian; a chord update that contracts more slowly than a half (up to 0.8,
  :data:`SLOWEST_CHORD`) is still taken when, at its own contraction, it predicts at most eight
  more chord steps to the tolerance (:data:`COSTLY_STEPS_TO_TOLERANCE`): the 3-D dome's cold
  run at the recommended settings then ends on chord steps (contraction 0.51 at 8.6e-5, then
  0.28-0.39 down to 1e-6) instead of a third Jacobian (2026-12-01).  Measured on ``ale_fsi``'s
  3-D dome (order 3, 2 threads) when the rule was made (2026-11-28), a fresh Jacobian cost 1.7
  s of assembly and 5.7 s of factorisation, a chord step ~0.1 s, and with the default rule its
  LM with forward differences assembled a Jacobian in nearly every run (158 s; 75 s with the
  costly-Jacobian rule, ``benchmarks/bench_lm_tangents.py``); since Pardiso factorises on the
  solver's threads with nested dissection and only a layer of the mesh moves, about 1-2 s of
  assembly and 0.75 s of refactorisation against 0.1-0.15 s a chord step
  (``benchmarks/bench_ale_fsi_3d.py``): still ten to twenty chord steps.  On its 2-D flow cell
  (23 and 9 ms against ~3 ms) that rule gained nothing, nor where a chord step is itself an
  iterative solve (``ale_fsi``'s ``block_gmres``: slower).  The converged state meets the
  tolerance either way (a chord-converged one does not overshoot it as a quadratic Newton step
  does);
* an update that leads to an inadmissible state (an inverted element, a porosity outside
  (0, 1)) is halved, up to ``max_halvings`` times (default 5);
* at most ``max_jacobians`` Jacobians are assembled; updates that diverge (1e3 times the
  first) or stagnate (less than 10x in three Jacobians) end the solve early.

Failures raise :class:`NewtonFailure` with a reason tag (``newton_divergence``,
``linear_solver``, ``newton_nan``, and the ``inadmissible`` tag the solver is given, e.g.
``ale_jacobian``), which the plugins turn into :class:`fbia.ForwardModelError`.

Used by ``ale_fsi`` (the monolithic ALE FSI system) and by ``cutfem_fpi`` (the cut
Navier-Stokes/Darcy flow and the poroelastic skeleton).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ChordRule",
    "NewtonFailure",
    "NewtonSolver",
    "NonlinearSystem",
    "StepReport",
    "direct_solver_threads",
    "sparse_direct_solver",
]

#: A chord update larger than this (scaled) is not taken, but for a warm start's first one
#: under :meth:`ChordRule.costly_jacobian` (:data:`COSTLY_WARM_UPDATE`).
CHORD_MAX_UPDATE = 0.1
#: The first update of a warm start taken on trust under :meth:`ChordRule.costly_jacobian`:
#: on the 3-D dome (recommended settings) the first chord updates of warm runs lie near 0.1
#: (0.097-0.13 measured), so at 0.1 a worker whose earlier states lie farther apart than a
#: serial run's assembled a Jacobian (2-3 s) where chord steps (~0.07 s each) converge
#: (benchmarks/bench_dask_3d.py; CHANGELOG, issue 47).
COSTLY_WARM_UPDATE = 0.3
#: Chord steps to the tolerance that :meth:`ChordRule.costly_jacobian` takes at a contraction
#: slower than a half rather than a fresh Jacobian (which costs ten to twenty of them).
COSTLY_STEPS_TO_TOLERANCE = 8
#: The slowest contraction of such a chord step (the converged state's error stays within
#: 4 times the tolerance: the solve ends on an update below it).
SLOWEST_CHORD = 0.8

#: MKL Pardiso's matrix checker, ``iparm[26]`` (0-based) as NGSolve's ``MKLPardiso`` takes it
#: from the inverse's flags: 1 (NGSolve's setting) checks the CSR arrays at every call, each
#: back-substitution too; fbia turns it off (NGSolve's matrices are well formed; the figures
#: are in the CHANGELOG, issue 47).  It changes no result.
PARDISO_MATRIX_CHECK = "iparm26"


@dataclass(frozen=True)
class ChordRule:
    """When :class:`NewtonSolver` takes a step with its last factorisation (module docstring).

    The default suits a system whose fresh Jacobian costs a few chord steps;
    :meth:`costly_jacobian` one whose Jacobian costs tens of them.
    """

    #: chord steps go on while each update is at most this fraction of the one before
    contraction: float = 0.25
    #: a warm solve takes the old factorisation's first update if it is below this
    warm_update: float = 2.5e-4
    #: and undoes it when the next update is larger (the factorisation was too far off)
    undo_worse: bool = False
    #: a chord update that contracts more slowly than ``contraction`` is still taken while the
    #: chord steps it predicts to the tolerance, at its own contraction, are at most this many
    #: (0: never)
    steps_to_tolerance: int = 0

    @classmethod
    def costly_jacobian(cls) -> ChordRule:
        """Chord steps while the updates halve; a warm first update up to
        :data:`COSTLY_WARM_UPDATE`, undone if the next one is larger."""
        return cls(
            contraction=0.5,
            warm_update=COSTLY_WARM_UPDATE,
            undo_worse=True,
            steps_to_tolerance=COSTLY_STEPS_TO_TOLERANCE,
        )


@dataclass
class StepReport:
    """What one Newton solve did."""

    iterations: int = 0
    jacobians: int = 0
    assembly_time: float = 0.0
    solve_time: float = 0.0
    converged: bool = False
    message: str = ""
    norms: list[float] = field(default_factory=list)


class NewtonFailure(Exception):
    """A Newton solve that did not converge (the plugins turn it into ForwardModelError)."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.norms: list[float] = []  # scaled updates so far
        self.jacobians = 0


class NonlinearSystem(Protocol):
    """What :class:`NewtonSolver` needs from a discretised problem."""

    @property
    def vector(self) -> Any:
        """The state (an NGSolve BaseVector), updated in place."""

    @property
    def matrix(self) -> Any:
        """The Jacobian (an NGSolve BaseMatrix) that :meth:`assemble_jacobian` fills."""

    @property
    def free(self) -> Any:
        """The free dofs (an NGSolve BitArray)."""

    @property
    def free_mask(self) -> NDArray[np.bool_]:
        """The free dofs as a boolean array."""

    def residual(self, res: Any) -> None:
        """The residual at the current state, into ``res``."""

    def assemble_jacobian(self) -> None:
        """The consistent Jacobian at the current state, into :attr:`matrix`."""

    def scales(self) -> NDArray[np.float64]:
        """The scale of each dof's update (positive)."""

    def admissible(self) -> bool:
        """Whether the current state may be kept (e.g. no inverted element)."""


class NewtonSolver:
    """Newton's method with chord steps, damping to admissible states and a sparse direct
    solver (see the module docstring).

    Parameters
    ----------
    system
        The problem.
    tol
        Scaled update (max norm) at which the solve has converged.
    max_jacobians
        Jacobian assemblies per solve (chord steps are extra).
    linear_solver
        NGSolve's name of the sparse direct solver (``pardiso``, ``umfpack``, ``sparsecholesky``).
    max_halvings
        How often an update that leads to an inadmissible state is halved before the solve
        fails.
    inadmissible
        The reason tag of that failure (what an inadmissible state means for the system).
    blocks
        If given, a callable returning the free dofs of each block (NGSolve BitArrays): the
        Jacobian is then solved by GMRes with a block Gauss-Seidel preconditioner whose blocks
        ``linear_solver`` factorises (:class:`~fbia.plugins.fem.krylov.BlockGMResInverse`).
    chord
        When the factorisation is reused (default :class:`ChordRule`).
    ordering
        Pardiso's fill-reducing ordering (``"metis"``, ``"minimum_degree"``); None keeps
        NGSolve's (minimum degree).  Nested dissection (METIS) is the ordering for 3-D meshes.
    threads
        Threads of the direct solver's factorisations and solves (``ngsolve.SetNumThreads``
        must allow as many); 1 keeps them serial (:func:`direct_solver_threads`).
    matching
        Pardiso's weighted matching (NGSolve's setting); False factorises without it until a
        factorisation perturbs a pivot (:mod:`~fbia.plugins.fem.pardiso`).  Other solvers
        ignore it.
    """

    def __init__(
        self,
        system: NonlinearSystem,
        tol: float,
        max_jacobians: int,
        linear_solver: str,
        *,
        max_halvings: int = 5,
        inadmissible: str = "ale_jacobian",
        blocks: Callable[[], list[Any]] | None = None,
        chord: ChordRule | None = None,
        ordering: str | None = None,
        threads: int = 1,
        matching: bool = True,
    ) -> None:
        self.system = system
        self.tol = tol
        self.max_jacobians = max_jacobians
        self.linear_solver = linear_solver
        self.max_halvings = max_halvings
        self.inadmissible = inadmissible
        #: when the factorisation is reused (:class:`ChordRule`)
        self.chord = chord or ChordRule()
        self.blocks = blocks
        self.ordering = ordering
        self.threads = threads
        self.matching = matching
        #: seconds spent assembling and solving, summed over every solve
        self.timings = {"assembly": 0.0, "solve": 0.0}
        #: the factorised Jacobian (None until the first factorisation)
        self.inverse: Any = None
        #: whether the factorisation may serve the next solve (the last one converged)
        self.chord_ok = False

    def reset(self) -> None:
        """Forget the factorisation (after the forms or the free dofs changed)."""
        self.inverse = None
        self.chord_ok = False

    # -- the iteration -------------------------------------------------------------------------
    def solve(self, where: str = "Newton", tol: float | None = None) -> StepReport:
        """Solve ``residual = 0`` from the current state to the scaled update ``tol``
        (default: the solver's); raises :class:`NewtonFailure`."""
        tol = self.tol if tol is None else tol
        system = self.system
        rep = StepReport()
        vec = system.vector
        res = vec.CreateVector()
        du = vec.CreateVector()
        x_np = vec.FV().NumPy()
        try_chord = self.inverse is not None and self.chord_ok
        newton_norms: list[float] = []  # updates of the steps with a fresh Jacobian
        before: NDArray[np.float64] | None = None  # the state before a tentative chord step
        refine = False  # refine every solve, not only those of fresh Jacobians (linear_solve)
        try:
            for it in range(1, 4 * self.max_jacobians + 1):
                rep.iterations = it
                t0 = time.perf_counter()
                system.residual(res)
                chord = False
                if try_chord:  # a step with the last factorised Jacobian
                    self.linear_solve(du, res, where, refine)
                    norm = self.scaled_norm(du)
                    previous = rep.norms[-1] if rep.norms else None
                    chord = self._chord_taken(norm, previous, tol)
                    rep.solve_time += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    if not chord and before is not None and norm > rep.norms[-1]:
                        x_np[:] = before  # the warm first step made it worse: undone
                        system.residual(res)
                    before = None
                if not chord:  # a Newton step with a fresh Jacobian
                    if rep.jacobians >= self.max_jacobians:
                        break
                    system.assemble_jacobian()
                    t1 = time.perf_counter()
                    self.factorise(where)
                    refine = not self.linear_solve(du, res, where, refine=True) or refine
                    rep.assembly_time += t1 - t0
                    rep.solve_time += time.perf_counter() - t1
                    norm = self.scaled_norm(du)
                    rep.jacobians += 1
                    newton_norms.append(norm)
                rep.norms.append(norm)
                step = du.FV().NumPy()
                x0 = x_np.copy()
                if chord and len(rep.norms) == 1 and self.chord.undo_worse:
                    before = x0  # a warm solve's first step, not yet proven
                factor = 1.0
                for _ in range(self.max_halvings + 1):
                    x_np[:] = x0 - factor * step
                    if system.admissible():
                        break
                    factor *= 0.5
                else:
                    x_np[:] = x0
                    raise NewtonFailure(
                        f"{where}: every damped update leads to an inadmissible state",
                        self.inadmissible,
                    )
                contraction = norm / rep.norms[-2] if len(rep.norms) > 1 else 1.0
                left = norm * contraction / (1.0 - contraction) if contraction < 0.5 else norm
                if factor == 1.0 and (norm <= tol or (norm <= 1e-3 and left <= tol)):
                    rep.converged = True
                    break
                if refine and not chord and norm <= 1e-6 and contraction > 0.25:
                    # refined solves, yet a fresh Newton step no longer contracts: the state is
                    # as accurate as the rounding in the linear algebra allows
                    rep.converged = True
                    break
                try_chord = factor == 1.0
                self._check_progress(newton_norms, where)
            if not rep.converged:
                raise NewtonFailure(
                    f"{where}: Newton did not converge with {rep.jacobians} Jacobians "
                    f"(scaled updates {', '.join(f'{n:.2g}' for n in rep.norms[-3:])})",
                    "newton_divergence",
                )
        except NewtonFailure as fail:
            fail.norms, fail.jacobians = list(rep.norms), rep.jacobians
            raise
        finally:
            self.timings["assembly"] += rep.assembly_time
            self.timings["solve"] += rep.solve_time
            # the factorisation may serve the next solve only if this one ended converged
            self.chord_ok = rep.converged
        return rep

    def _chord_taken(self, norm: float, previous: float | None, tol: float) -> bool:
        """Whether a chord update is taken (module docstring)."""
        if previous is None:  # a warm start's first update
            return norm <= self.chord.warm_update
        if norm > CHORD_MAX_UPDATE:
            return False
        if norm <= self.chord.contraction * previous:
            return True
        rate = norm / previous  # slower than the rule's contraction: worth it near the end?
        if self.chord.steps_to_tolerance <= 0 or rate > SLOWEST_CHORD:
            return False
        return norm <= tol or math.log(tol / norm) / math.log(rate) <= self.chord.steps_to_tolerance

    @staticmethod
    def _check_progress(norms: list[float], where: str) -> None:
        """Raise NewtonFailure if the Newton updates (fresh Jacobians) diverge or stagnate."""
        if len(norms) >= 3 and norms[-1] > 1e3 * max(norms[0], 1.0):
            raise NewtonFailure(
                f"{where}: Newton diverges (scaled update {norms[-1]:.3g})", "newton_divergence"
            )
        if len(norms) >= 5 and norms[-1] > 0.1 * norms[-4]:
            raise NewtonFailure(
                f"{where}: Newton stagnates (scaled updates "
                f"{', '.join(f'{n:.2g}' for n in norms[-4:])})",
                "newton_divergence",
            )

    # -- linear algebra ------------------------------------------------------------------------
    def factorise(self, where: str) -> None:
        """(Re)factorise the Jacobian on the free dofs, reusing the symbolic factorisation."""
        from pyngcore import Flags

        try:
            if self.inverse is None and self.blocks is not None:
                from .krylov import BlockGMResInverse

                self.inverse = BlockGMResInverse(
                    self.system.matrix, self.blocks(), self.system.free, self.linear_solver
                )
            elif self.inverse is None:
                flags: dict[str, Any] = {}
                inverse = self.linear_solver
                if inverse == "pardiso" and not self.matching:
                    from .pardiso import UNMATCHED, unmatched_pardiso

                    if unmatched_pardiso():
                        inverse = UNMATCHED
                if self.linear_solver == "pardiso":
                    flags["refinement"] = 0
                    flags[PARDISO_MATRIX_CHECK] = 0  # no check of the arrays at every call
                    if self.ordering is not None:
                        flags["ordering"] = self.ordering
                with direct_solver_threads(self.threads):
                    self.inverse = self.system.matrix.Inverse(
                        self.system.free, inverse=inverse, flags=Flags(flags)
                    )
            else:
                with direct_solver_threads(self.threads):
                    self.inverse.Update()
        except Exception as exc:  # Pardiso/NGSolve report a singular matrix as plain errors
            self.inverse = None
            raise NewtonFailure(f"{where}: factorisation failed: {exc}", "linear_solver") from exc

    def linear_solve(self, du: Any, res: Any, where: str, refine: bool = False) -> bool:
        """``du = J^-1 res`` on the free dofs; ``refine``: with iterative refinement.

        Pardiso runs without iterative refinement (it cost 8x the back-substitution).  With
        ``refine`` the residual of the solve is corrected up to 3 times, until the correction
        is below 1e-6 of the solution (scaled per dof); returns whether the first correction
        was that small, i.e. whether the plain solve was accurate.  Newton refines the solves
        of fresh Jacobians, and all solves once one of them was inaccurate -- as with a nearly
        rigid solid (Turek-Hron CFD1, E = 1e15 Pa, next to a mesh motion of weight 1e-8 Pa).
        """
        try:
            with direct_solver_threads(self.threads):
                du.data = self.inverse * res
                if not refine:
                    return True
                size = self.scaled_norm(du)
                k_du = res.CreateVector()
                r = res.CreateVector()
                correction = res.CreateVector()
                for k in range(3):
                    self.system.matrix.Mult(du, k_du)
                    r.data = res - k_du
                    correction.data = self.inverse * r
                    du.data += correction
                    if self.scaled_norm(correction) <= 1e-6 * max(size, 1e-12):
                        return k == 0
                return False
        except NewtonFailure:
            raise
        except Exception as exc:  # see factorise
            raise NewtonFailure(f"{where}: linear solve failed: {exc}", "linear_solver") from exc

    def scaled_norm(self, du: Any) -> float:
        """Max over the free dofs of |du| / scale."""
        step = du.FV().NumPy()
        if not np.all(np.isfinite(step)):
            raise NewtonFailure("the linear solve returned NaN", "newton_nan")
        free = self.system.free_mask
        return float(np.max(np.abs(step[free]) / self.system.scales()[free]))


@contextmanager
def direct_solver_threads(threads: int) -> Iterator[None]:
    """Run a sparse direct solver's factorisation or solve on NGSolve's threads if
    ``threads`` > 1 (else serially, as before).

    NGSolve's Pardiso wrapper gives MKL the task manager's thread count
    (``pyngcore.GetNumThreads``), which is 1 outside ``ngsolve.TaskManager()``: a solver set to
    two threads factorised on one (Pardiso's own statistics: "running on 1 OpenMP").  Inside
    the task manager it uses ``ngsolve.SetNumThreads``'s count; nested use is harmless.
    """
    if threads <= 1:
        yield
        return
    import ngsolve as ngs

    with ngs.TaskManager():
        yield


def sparse_direct_solver() -> str:
    """``"pardiso"`` if MKL Pardiso is available (``pip install mkl``), else ``"umfpack"``.

    The monolithic Jacobian is non-symmetric with zero diagonal blocks: Cholesky-type solvers
    fail on it.  UMFPACK works but was 2.5-10x slower than Pardiso on the test machine.
    """
    try:
        from ngsolve.solvers import mkl_pardiso
    except ImportError:
        available = False
    else:
        available = getattr(mkl_pardiso, "_pardiso", None) is not None
    if available:
        return "pardiso"
    warnings.warn(
        "MKL Pardiso is not available (pip install mkl); ale_fsi falls back to UMFPACK, "
        "which is several times slower",
        RuntimeWarning,
        stacklevel=2,
    )
    return "umfpack"
