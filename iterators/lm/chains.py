"""One Levenberg–Marquardt run from one initial guess (Paper A eq. 16-29), as a generator.

A chain knows nothing about forward models or evaluators: its :meth:`LMChain.run`
generator *yields* the batch of parameter vectors it needs evaluated and *receives* one
:class:`Outcome` per vector (the residual vector r of eq. 19, or a failure).  The iterator in
:mod:`fbia.iterators.levenberg_marquardt` drives several chains at once (multi-start) and sends
their batches to the evaluator together, so the n_x + 1 runs of one Jacobian, and the runs of
all starts, execute concurrently on a pool.  Each mode is a subclass: :class:`PaperChain`
(below) and :class:`fbia.iterators.lm.robust.RobustChain`.

Two modes share the finite-difference Jacobian (eq. 21-23) and the error measures (eq. 24-25):

``paper``
    Paper A as published: every step of eq. 18 is taken; μ is updated by eq. 26 only when
    eq. 27 holds (the new μ applies from the next step on, as in QUEENS, where the paper's
    algorithm was implemented); a step that leaves the bounds (eq. 28) is declined and μ
    doubled, and the iteration that follows a declined step keeps the doubled μ (QUEENS
    evaluates the errors at the same point again, so eq. 27 does not hold there), or with
    ``declined_mu = "restored"`` starts from the μ before the doubling (the text doubles
    μ^k for the new proposal and says nothing of μ^(k+1); Table 3's orange start converges
    under this reading only, ``examples/paper_a/heterogeneous/README.md``); the run
    ends without result when μ > μ0·1e6 or when a forward run fails, and with the iterate of
    lowest err_res on eq. 29a-c.  One deliberate difference from QUEENS:
    after a declined step the new step is computed from the same J, where QUEENS re-ran the
    n_x + 1 runs at the unchanged point (same iterates, fewer runs).
``robust``
    The same step, made robust: :mod:`fbia.iterators.lm.robust`.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from .finite_differences import forward_steps, perturbed

FloatArray = NDArray[np.float64]

#: Stop tags of a chain and whether they count as success.
SUCCESS = {"converged_gradient": True, "converged_residual": True, "converged_step": True}


@dataclass(frozen=True)
class Outcome:
    """What one evaluation gave a chain: the residual vector r (eq. 19), or None if it failed."""

    residuals: FloatArray | None
    message: str = ""
    #: dr/dx at the point from the model's tangents (``jacobian = "tangent"``), if it gave them
    jacobian: FloatArray | None = None

    @property
    def ok(self) -> bool:
        return self.residuals is not None


@dataclass(frozen=True)
class LMSettings:
    """The numbers an :class:`LMChain` needs (validated by the iterator's Options)."""

    mode: str
    alpha: FloatArray  # absolute part of the perturbation, per parameter (eq. 21)
    beta: float  # relative part of the perturbation (eq. 21)
    mu0: float
    mu_limit: float  # stop when mu > mu0 * mu_limit
    declined_mu: str  # "kept" | "restored": mu after a declined step (paper mode)
    eps_grad: float  # eq. 29a
    eps_res: float  # eq. 29b
    max_iter: int  # eq. 29c
    ftol: float = 1e-8
    xtol: float = 1e-8
    gtol: float = 1e-8
    scaling: str = "adaptive"
    speculative: bool = False
    final_jacobian: str = "central"
    jacobian: str = "forward"  # "tangent" | "forward" | "central" (robust mode)

    @classmethod
    def for_mode(cls, mode: str, n: int, **kw: Any) -> LMSettings:
        """Settings for experiments with a chain (eq. 29a off, μ0 = 1); the iterator builds
        its own from its Options."""
        alpha = np.broadcast_to(np.asarray(kw.pop("alpha", 1e-5), dtype=float), (n,)).copy()
        base: dict[str, Any] = {
            "beta": 1e-3,
            "mu0": 1.0,
            "mu_limit": 1e6,
            "declined_mu": "kept",
            "eps_grad": 0.0,
            "eps_res": 0.0,
            "max_iter": 100,
        }
        base.update(kw)
        return cls(mode=mode, alpha=alpha, **base)

    @property
    def typical(self) -> FloatArray:
        """Magnitude below which a parameter counts as 'near zero': α/β, where eq. 21 turns
        from a relative into an absolute perturbation."""
        if self.beta > 0:
            return self.alpha / self.beta
        return self.alpha


def err_res_of(r: FloatArray) -> float:
    """err_res = ‖r‖₂ / √n_r (Paper A eq. 25)."""
    return float(np.linalg.norm(r) / math.sqrt(len(r)))


@dataclass
class LMChain:
    """One Levenberg–Marquardt run; drive :meth:`run` with batches of :class:`Outcome`.

    Attributes after the run: ``status`` and ``message`` (why it stopped), ``x`` (the result,
    None when the run gives none), ``r`` and ``J`` (residuals at ``x`` and the last Jacobian,
    computed at ``jac_x``), ``err_res``, ``err_grad``, ``mu``, ``iterations`` (steps taken),
    ``nfev``/``n_failed`` (runs asked for / failed) and ``history`` (one dict per iterate and
    per declined step).
    """

    index: int
    x0: FloatArray
    lower: FloatArray
    upper: FloatArray
    settings: LMSettings
    names: Sequence[str]
    status: str = ""
    message: str = ""
    x: FloatArray | None = None
    r: FloatArray | None = None
    J: FloatArray | None = None
    jac_x: FloatArray | None = None
    err_res: float = math.nan
    err_grad: float = math.nan
    mu: float = math.nan
    iterations: int = 0
    nfev: int = 0
    n_failed: int = 0
    history: list[dict[str, Any]] = field(default_factory=list)
    #: Jacobians computed, by source: "tangent", "forward", "central"
    j_sources: dict[str, int] = field(default_factory=dict)
    #: The last iterate, kept for reports when the run gives no result (paper mode).
    x_last: FloatArray | None = None
    _scale: FloatArray | None = None

    # -- public ------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return bool(self.status)

    @property
    def success(self) -> bool:
        return SUCCESS.get(self.status, False)

    def run(self) -> Generator[list[FloatArray], list[Outcome], None]:
        """The LM iteration: yields batches of parameter vectors, receives their outcomes."""
        raise NotImplementedError  # PaperChain, RobustChain
        yield []  # a generator

    def finish(self, status: str, message: str) -> None:
        """End the run from outside (evaluation budget, stop request, plugin error)."""
        if not self.done:
            self.status, self.message = status, message
            if self.settings.mode == "paper" and status not in SUCCESS and self.x is not None:
                self.x_last = self.x

    # -- shared pieces -----------------------------------------------------------------------
    def _ask(
        self, points: list[FloatArray]
    ) -> Generator[list[FloatArray], list[Outcome], list[Outcome]]:
        outcomes = yield points
        if len(outcomes) != len(points):
            raise RuntimeError(f"asked for {len(points)} evaluations, got {len(outcomes)}")
        self.nfev += len(points)
        self.n_failed += sum(not o.ok for o in outcomes)
        return outcomes

    def _deltas(self, x: FloatArray) -> FloatArray:
        """Perturbations δx_i = α + β·x_i (eq. 21); paper mode uses x_i as written (a negative
        x_i shrinks or flips δx_i), robust mode |x_i| so that δx_i never vanishes."""
        s = self.settings
        return forward_steps(x, s.alpha, s.beta, self.lower, self.upper, s.mode == "paper")

    def _check_length(self, r: FloatArray) -> FloatArray:
        r = np.asarray(r, dtype=float).ravel()
        if self.r is not None and len(r) != len(self.r):
            raise ConfigError(
                f"the residual vector changed length from {len(self.r)} to {len(r)} between "
                "runs; Levenberg-Marquardt needs the same residuals r (eq. 19) in every run"
            )
        if len(r) == 0:
            raise ConfigError("the residual vector is empty: nothing to fit")
        return r

    def _jacobian(
        self, x: FloatArray, r0: FloatArray, d: FloatArray, outcomes: Sequence[Outcome]
    ) -> Generator[list[FloatArray], list[Outcome], tuple[FloatArray, list[int]]]:
        """Forward-difference Jacobian (eq. 22-23).  In robust mode a failed perturbed run is
        repeated once on the other side of x; a column that still fails is returned in the
        list of frozen parameters (held fixed for the next step)."""
        self._count("forward")
        J = np.zeros((len(r0), len(x)))
        bad = []
        for i, o in enumerate(outcomes):
            if o.ok:
                assert o.residuals is not None
                J[:, i] = (self._check_length(o.residuals) - r0) / d[i]
            else:
                bad.append(i)
        if bad and self.settings.mode != "paper":
            retry = [i for i in bad if self.lower[i] <= x[i] - d[i] <= self.upper[i]]
            if retry:
                d2 = -d
                outs = yield from self._ask(perturbed(x, d2, retry))
                for i, o in zip(retry, outs, strict=True):
                    if o.ok:
                        assert o.residuals is not None
                        J[:, i] = (self._check_length(o.residuals) - r0) / d2[i]
                        bad.remove(i)
        return J, bad

    def _count(self, source: str) -> None:
        self.j_sources[source] = self.j_sources.get(source, 0) + 1

    def _set_point(self, x: FloatArray, r: FloatArray, J: FloatArray | None) -> None:
        self.x, self.r = x, r
        if J is not None:
            self.J, self.jac_x = J, x
            norms = np.linalg.norm(J, axis=0)
            self._scale = norms if self._scale is None else np.maximum(self._scale, norms)
        self.err_res = err_res_of(r)
        assert self.J is not None
        self.err_grad = float(np.linalg.norm(self.J.T @ r))  # eq. 24

    def _record(self, x: FloatArray, r: FloatArray | None, accepted: bool, note: str) -> None:
        entry: dict[str, Any] = {
            "chain": self.index,
            "iteration": self.iterations,
            "x": dict(zip(self.names, map(float, x), strict=True)),
            "r": None if r is None else r.tolist(),
            "err_res": None if r is None else err_res_of(r),
            "err_grad": self.err_grad if accepted else None,
            "mu": float(self.mu),
            "accepted": accepted,
            "note": note,
            "nfev": self.nfev,
        }
        self.history.append(entry)

    def _stop(self, status: str, message: str) -> None:
        self.status, self.message = status, message

    def _verdict(self, g: FloatArray, free: NDArray[np.bool_]) -> tuple[str, str, bool] | None:
        """Eq. 29a/29b, and (robust mode) the scale-free angle criterion gtol, at the current
        point: (status, message, absolute) or None.  ``absolute`` marks the user's own
        targets eps_grad / eps_res (eq. 29a/b), which end a run outright; the relative gtol
        depends on how accurate J is and is checked again with a central-difference J."""
        s = self.settings
        assert self.r is not None and self.J is not None
        grad = float(np.linalg.norm(g[free])) if s.mode != "paper" else self.err_grad
        if grad < s.eps_grad:
            # at a bound the gradient is judged on the parameters off it (the result's
            # err_grad is eq. 24 over all of them): say which one the message gives
            whole = s.mode == "paper" or bool(np.all(free))
            which = "err_grad" if whole else "err_grad of the parameters off a bound"
            return (
                "converged_gradient",
                f"converged on the gradient: {which} = {grad:.3e} < eps_grad = {s.eps_grad:g} "
                "(eq. 29a)",
                True,
            )
        if self.err_res < s.eps_res:
            return (
                "converged_residual",
                f"converged on the residual: err_res = {self.err_res:.3e} < eps_res = "
                f"{s.eps_res:g} (eq. 29b)",
                True,
            )
        if s.mode == "paper":
            return None
        rnorm = float(np.linalg.norm(self.r))
        if rnorm == 0.0:
            return "converged_residual", "converged: the residuals are exactly zero", True
        cols = np.linalg.norm(self.J, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = np.where(cols > 0, np.abs(g) / (cols * rnorm), 0.0)
        worst = float(np.max(cosine[free], initial=0.0))
        if worst <= s.gtol:
            return (
                "converged_gradient",
                f"converged on the gradient: r is orthogonal to every column of J within "
                f"gtol = {s.gtol:g} (largest |cos| = {worst:.2e})",
                False,
            )
        return None


class PaperChain(LMChain):
    """Paper A's algorithm as published (mode ``paper``)."""

    def run(self) -> Generator[list[FloatArray], list[Outcome], None]:
        s = self.settings
        x = self.x0.astype(float).copy()
        self.mu = s.mu0
        best: tuple[float, FloatArray, FloatArray, FloatArray] | None = None
        prev: tuple[float, float] | None = None
        while True:
            d = self._deltas(x)
            outs = yield from self._ask([x, *perturbed(x, d, range(len(x)))])
            if not all(o.ok for o in outs):
                failed = next(o for o in outs if not o.ok)
                self.x_last, self.x = x, None
                self._stop(
                    "run_failed",
                    f"a forward run failed ({failed.message}); Paper A's algorithm cannot "
                    "compute the finite differences and ends without result",
                )
                self._record(x, None, False, "run failed")
                return
            assert outs[0].residuals is not None
            r = self._check_length(outs[0].residuals)
            J, _ = yield from self._jacobian(x, r, d, outs[1:])
            self._set_point(x, r, J)
            if best is None or self.err_res < best[0]:
                best = (self.err_res, x, r, J)
            self._record(x, r, True, "start" if prev is None else "step")
            verdict = self._verdict(J.T @ r, np.ones(len(x), dtype=bool))
            if verdict is not None:
                self._stop(*verdict[:2])
                break
            if self.iterations >= s.max_iter:
                self._stop(
                    "iteration_limit",
                    f"iteration limit: {s.max_iter} iterations without convergence (eq. 29c)",
                )
                break
            # eq. 18 with the bounds check of eq. 28: a step out of bounds is declined, μ doubled
            A = J.T @ J
            declined = False
            mu_before = self.mu
            while True:
                try:
                    step = np.linalg.solve(A + self.mu * np.diag(np.diag(A)), -(J.T @ r))
                except np.linalg.LinAlgError:
                    self.x_last, self.x = x, None
                    self._stop(
                        "singular",
                        "J^T J + mu diag(J^T J) is singular (a parameter does not change the "
                        "residuals): Paper A's step (eq. 18) is undefined, no result",
                    )
                    return
                xt = x + step
                if np.all(xt > self.lower) and np.all(xt < self.upper):
                    break
                self.mu *= 2.0
                declined = True
                self._record(xt, None, False, "out of bounds: mu doubled (eq. 28)")
                if self.mu > s.mu0 * s.mu_limit:
                    self.x_last, self.x = x, None
                    self._stop(
                        "damping_limit",
                        f"damping limit: steps keep leaving the bounds and mu = {self.mu:.3g} "
                        f"> mu0 * {s.mu_limit:g}; no parameter result (Paper A, eq. 28)",
                    )
                    return
            # eq. 26 under condition eq. 27 (the update applies to the next step).  After a
            # declined step QUEENS computes the errors at the same point again, so eq. 27
            # compares the point with itself and μ keeps its doubled value for this step.
            if (
                not declined
                and prev is not None
                and self.err_grad < prev[0]
                and self.err_res < prev[1]
            ):
                self.mu *= self.err_grad / prev[0]
            if declined and s.declined_mu == "restored":
                self.mu = mu_before  # the doubling served the proposal only
            prev = (self.err_grad, self.err_res)
            x = xt
            self.iterations += 1
        # QUEENS, the code of Paper A, reports the iterate with the lowest err_res
        assert best is not None
        self.err_res, x_best, r_best, J_best = best
        self.x, self.r, self.J, self.jac_x = x_best, r_best, J_best, x_best
        self.err_grad = float(np.linalg.norm(J_best.T @ r_best))
