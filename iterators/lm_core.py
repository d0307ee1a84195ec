"""One Levenberg–Marquardt run from one initial guess (Paper A eq. 16-29), as a generator.

A :class:`LMChain` knows nothing about forward models or evaluators: its :meth:`LMChain.run`
generator *yields* the batch of parameter vectors it needs evaluated and *receives* one
:class:`Outcome` per vector (the residual vector r of eq. 19, or a failure).  The iterator in
:mod:`fbia.iterators.levenberg_marquardt` drives several chains at once (multi-start) and sends
their batches to the evaluator together, so the n_x + 1 runs of one Jacobian, and the runs of
all starts, execute concurrently on a pool.

>>> import numpy as np
>>> from fbia.iterators.lm_core import LMChain, LMSettings, Outcome
>>> t = np.linspace(0.0, 1.0, 8)
>>> fun = lambda x: x[0] * np.exp(-x[1] * t) - 2.0 * np.exp(-0.5 * t)
>>> chain = LMChain(0, np.array([1.0, 1.0]), np.full(2, -np.inf), np.full(2, np.inf),
...                 LMSettings.for_mode("robust", 2, alpha=1e-8, beta=1e-8), ["a", "k"])
>>> gen = chain.run()
>>> batch = next(gen)
>>> while True:
...     try:
...         batch = gen.send([Outcome(fun(x)) for x in batch])
...     except StopIteration:
...         break
>>> chain.status, np.round(chain.x, 6).tolist()
('converged_step', [2.0, 0.5])

Two modes share the finite-difference Jacobian (eq. 21-23) and the error measures (eq. 24-25):

``paper``
    Paper A as published: every step of eq. 18 is taken; μ is updated by eq. 26 only when
    eq. 27 holds (the new μ applies from the next step on, as in QUEENS, where the paper's
    algorithm was implemented); a step that leaves the bounds (eq. 28) is declined and μ
    doubled; the run ends without result when μ > μ0·1e6 or when a forward run fails, and
    with the iterate of lowest err_res on eq. 29a-c.  One deliberate difference from QUEENS:
    after a declined step the new step is computed from the same J, where QUEENS re-ran the
    n_x + 1 runs at the unchanged point (same iterates, fewer runs).
``robust``
    The same step (eq. 18), made robust.  A step is taken only if it reduces ‖r‖ (by at least
    1e-4 of the reduction the linear model predicts); otherwise μ grows and a new step is
    computed from the same J, without new runs.  μ is chosen by a trust region on ‖D Δx‖
    (Moré 1978, the strategy of MINPACK): μ = 0, a Gauss–Newton step, whenever that step is
    short enough, which makes the last iterations converge fast even when J is badly
    conditioned.  D is the largest Jacobian column norms seen so far, so parameters of very
    different magnitude (E ~ 400 Pa, ν ~ 0.3, growth factors 1e4 and 1e-2) are treated alike.
    A step that leaves the bounds is projected onto them or shortened to them (whichever the
    linear model prefers), and a parameter stays at its bound while the gradient pushes it
    outward.  A failed forward run is a declined step (the trust region shrinks); a failed
    perturbed run is repeated on the other side of x, and a parameter whose column still fails
    is held fixed for one step.  Relative criteria on the reduction of ‖r‖ (ftol), on the
    step (xtol) and on the angle between r and the columns of J (gtol) complement eq. 29.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fbia.core.errors import ConfigError

FloatArray = NDArray[np.float64]

#: A step is taken (robust mode) when the actual reduction of ‖r‖² is at least this fraction of
#: the reduction the linear model predicts (MINPACK's 1e-4).
GAIN_MIN = 1e-4

#: Factor on the trust region after a failed run (no residual to judge the step by).
FAILED_SHRINK = 0.5

#: Stop tags of a chain and whether they count as success.
SUCCESS = {"converged_gradient": True, "converged_residual": True, "converged_step": True}


@dataclass(frozen=True)
class Outcome:
    """What one evaluation gave a chain: the residual vector r (eq. 19), or None if it failed."""

    residuals: FloatArray | None
    message: str = ""

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
    eps_grad: float  # eq. 29a
    eps_res: float  # eq. 29b
    max_iter: int  # eq. 29c
    ftol: float = 1e-8
    xtol: float = 1e-8
    gtol: float = 1e-8
    scaling: str = "adaptive"
    speculative: bool = False

    @classmethod
    def for_mode(cls, mode: str, n: int, **kw: Any) -> LMSettings:
        """Settings for experiments with a chain (eq. 29a off, μ0 = 1); the iterator builds
        its own from its Options."""
        alpha = np.broadcast_to(np.asarray(kw.pop("alpha", 1e-5), dtype=float), (n,)).copy()
        base: dict[str, Any] = {
            "beta": 1e-3,
            "mu0": 1.0,
            "mu_limit": 1e6,
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
        if self.settings.mode == "paper":
            yield from self._paper()
        else:
            yield from self._robust()

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
        """Perturbations δx_i = α + β·x_i (eq. 21), turned round where they leave the bounds.

        Paper mode uses x_i as written (a negative x_i shrinks or flips δx_i); robust mode uses
        |x_i| so that δx_i never vanishes.
        """
        s = self.settings
        d = s.alpha + s.beta * (x if s.mode == "paper" else np.abs(x))
        d = np.where(d == 0.0, np.where(s.alpha > 0, s.alpha, s.beta), d)  # x_i = 0, α = 0
        for i in range(len(x)):
            if not self.lower[i] <= x[i] + d[i] <= self.upper[i]:
                d[i] = -d[i]
                if not self.lower[i] <= x[i] + d[i] <= self.upper[i]:
                    room_up, room_down = self.upper[i] - x[i], x[i] - self.lower[i]
                    d[i] = 0.5 * room_up if room_up >= room_down else -0.5 * room_down
        return d

    def _perturbed(self, x: FloatArray, d: FloatArray, cols: Sequence[int]) -> list[FloatArray]:
        out = []
        for i in cols:
            xi = x.copy()
            xi[i] += d[i]
            out.append(xi)
        return out

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
                outs = yield from self._ask(self._perturbed(x, d2, retry))
                for i, o in zip(retry, outs, strict=True):
                    if o.ok:
                        assert o.residuals is not None
                        J[:, i] = (self._check_length(o.residuals) - r0) / d2[i]
                        bad.remove(i)
        return J, bad

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

    def _converged_at_point(self, g: FloatArray, free: NDArray[np.bool_]) -> bool:
        """Eq. 29a/29b, and (robust mode) the scale-free angle criterion gtol."""
        s = self.settings
        assert self.r is not None and self.J is not None
        grad = float(np.linalg.norm(g[free])) if s.mode != "paper" else self.err_grad
        if grad < s.eps_grad:
            self._stop(
                "converged_gradient",
                f"converged on the gradient: err_grad = {grad:.3e} < eps_grad = {s.eps_grad:g} "
                "(eq. 29a)",
            )
            return True
        if self.err_res < s.eps_res:
            self._stop(
                "converged_residual",
                f"converged on the residual: err_res = {self.err_res:.3e} < eps_res = "
                f"{s.eps_res:g} (eq. 29b)",
            )
            return True
        if s.mode == "paper":
            return False
        rnorm = float(np.linalg.norm(self.r))
        if rnorm == 0.0:
            self._stop("converged_residual", "converged: the residuals are exactly zero")
            return True
        cols = np.linalg.norm(self.J, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = np.where(cols > 0, np.abs(g) / (cols * rnorm), 0.0)
        worst = float(np.max(cosine[free], initial=0.0))
        if worst <= s.gtol:
            self._stop(
                "converged_gradient",
                f"converged on the gradient: r is orthogonal to every column of J within "
                f"gtol = {s.gtol:g} (largest |cos| = {worst:.2e})",
            )
            return True
        return False

    # -- Paper A, as published -----------------------------------------------------------------
    def _paper(self) -> Generator[list[FloatArray], list[Outcome], None]:
        s = self.settings
        x = self.x0.astype(float).copy()
        self.mu = s.mu0
        best: tuple[float, FloatArray, FloatArray, FloatArray] | None = None
        prev: tuple[float, float] | None = None
        while True:
            d = self._deltas(x)
            outs = yield from self._ask([x, *self._perturbed(x, d, range(len(x)))])
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
            if self._converged_at_point(J.T @ r, np.ones(len(x), dtype=bool)):
                break
            if self.iterations >= s.max_iter:
                self._stop(
                    "iteration_limit",
                    f"iteration limit: {s.max_iter} iterations without convergence (eq. 29c)",
                )
                break
            # eq. 18 with the bounds check of eq. 28: a step out of bounds is declined, μ doubled
            A = J.T @ J
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
                self._record(xt, None, False, "out of bounds: mu doubled (eq. 28)")
                if self.mu > s.mu0 * s.mu_limit:
                    self.x_last, self.x = x, None
                    self._stop(
                        "damping_limit",
                        f"damping limit: steps keep leaving the bounds and mu = {self.mu:.3g} "
                        f"> mu0 * {s.mu_limit:g}; no parameter result (Paper A, eq. 28)",
                    )
                    return
            # eq. 26 under condition eq. 27 (the update applies to the next step)
            if prev is not None and self.err_grad < prev[0] and self.err_res < prev[1]:
                self.mu *= self.err_grad / prev[0]
            prev = (self.err_grad, self.err_res)
            x = xt
            self.iterations += 1
        # QUEENS, the code of Paper A, reports the iterate with the lowest err_res
        assert best is not None
        self.err_res, x_best, r_best, J_best = best
        self.x, self.r, self.J, self.jac_x = x_best, r_best, J_best, x_best
        self.err_grad = float(np.linalg.norm(J_best.T @ r_best))

    # -- robust mode -------------------------------------------------------------------------------
    def _free(self, x: FloatArray, g: FloatArray, frozen: Sequence[int]) -> NDArray[np.bool_]:
        """Parameters free to move: not frozen and not held at a bound by the gradient."""
        at_lower = (x <= self.lower) & (g > 0)
        at_upper = (x >= self.upper) & (g < 0)
        free = ~(at_lower | at_upper)
        free[list(frozen)] = False
        return free

    def _diag(self, J: FloatArray) -> FloatArray:
        """D of the damping term μ‖D p‖² (eq. 18 has D² = diag(JᵀJ)): the current column norms
        of J ('marquardt') or the largest ones seen so far ('adaptive', Moré 1978)."""
        if self.settings.scaling == "marquardt" or self._scale is None:
            D = np.linalg.norm(J, axis=0)
        else:
            D = self._scale.copy()
        D[D == 0.0] = 1.0
        return D

    def _lm_step(
        self,
        J: FloatArray,
        r: FloatArray,
        D: FloatArray,
        free: NDArray[np.bool_],
        mu: float | None = None,
        radius: float | None = None,
    ) -> tuple[FloatArray, float]:
        """The step of eq. 18, p = −(JᵀJ + μD²)⁻¹Jᵀr over the free parameters, for a given μ
        or with μ ≥ 0 chosen so that ‖Dp‖ ≈ radius (Moré's trust region; μ = 0, the
        Gauss–Newton step, when that is shorter).  Solved by an SVD of the column-scaled J."""
        p = np.zeros(J.shape[1])
        if not np.any(free):
            return p, 0.0 if mu is None else mu
        U, sv, Vt = np.linalg.svd(J[:, free] / D[free], full_matrices=False)
        c = U.T @ r
        rank = sv > sv.max(initial=0.0) * max(J.shape) * np.finfo(float).eps
        sc2 = (sv * c) ** 2

        def weights(lam: float) -> FloatArray:
            with np.errstate(divide="ignore", invalid="ignore"):
                w = np.where(rank, sv * c / (sv**2 + lam), 0.0)
            return w

        if mu is None:
            assert radius is not None
            mu = 0.0
            if np.linalg.norm(weights(0.0)) > 1.1 * radius:
                lo, hi = 0.0, math.sqrt(float(np.sum(sc2))) / radius
                lam = min(max(self.mu if math.isfinite(self.mu) else 0.0, 1e-3 * hi), hi)
                for _ in range(30):  # safeguarded Newton iteration on 1/‖q(μ)‖ (Moré 1978)
                    f = float(np.linalg.norm(weights(lam)))
                    phi = f - radius
                    if abs(phi) <= 0.1 * radius:
                        break
                    if phi > 0:
                        lo = lam
                    else:
                        hi = lam
                    df = -float(np.sum(np.where(rank, sc2 / (sv**2 + lam) ** 3, 0.0))) / f
                    new = lam - (phi / df) * (f / radius)
                    lam = new if lo < new < hi else (0.5 * (lo + hi) if lo > 0 else 0.1 * hi)
                mu = lam
        p[free] = -(Vt.T @ weights(mu)) / D[free]
        return p, mu

    def _radius_small(
        self, radius: float, D: FloatArray, x: FloatArray, free: NDArray[np.bool_]
    ) -> bool:
        """Step criterion: no step in the trust region ‖D p‖ ≤ radius changes a free parameter
        by more than xtol·(|x_i| + α_i/β), i.e. radius/D_i ≤ xtol·(|x_i| + α_i/β)."""
        typical = np.where(self.settings.typical > 0, self.settings.typical, 1e-300)
        reach = radius / D[free]
        return bool(np.all(reach <= self.settings.xtol * (np.abs(x[free]) + typical[free])))

    def _within_bounds(
        self, x: FloatArray, p: FloatArray, r: FloatArray, J: FloatArray
    ) -> FloatArray:
        """A step that leaves the box becomes the better (by the linear model) of its
        projection onto the box and the step shortened to the box."""
        xt = x + p
        if np.all(xt >= self.lower) and np.all(xt <= self.upper):
            return p
        projected = np.clip(xt, self.lower, self.upper) - x
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(p > 0, (self.upper - x) / p, np.where(p < 0, (self.lower - x) / p, 1.0))
        shortened = float(np.clip(np.min(room), 0.0, 1.0)) * p
        model = [float(np.sum((r + J @ q) ** 2)) for q in (projected, shortened)]
        return projected if model[0] <= model[1] else shortened

    def _robust(self) -> Generator[list[FloatArray], list[Outcome], None]:
        """Levenberg–Marquardt with μ chosen by a trust region on ‖D Δx‖ (Moré 1978, the
        strategy of MINPACK), projected steps at the bounds, failed runs as declined steps."""
        s = self.settings
        x = self.x0.astype(float).copy()
        d = self._deltas(x)
        outs = yield from self._ask([x, *self._perturbed(x, d, range(len(x)))])
        if not outs[0].ok:
            self.x_last = x
            self._stop(
                "start_failed",
                f"the forward run at the initial guess failed ({outs[0].message}); "
                "Levenberg-Marquardt needs a start where the model can be solved",
            )
            self._record(x, None, False, "run failed")
            return
        assert outs[0].residuals is not None
        r = self._check_length(outs[0].residuals)
        J, frozen = yield from self._jacobian(x, r, d, outs[1:])
        self._set_point(x, r, J)
        self.mu = s.mu0
        self._record(x, r, True, "start")
        radius = math.nan
        while True:
            assert self.J is not None
            J = self.J
            g = J.T @ r
            free = self._free(x, g, frozen)
            if self._converged_at_point(g, free):
                return
            if not np.any(free):
                self._stop(
                    "converged_gradient",
                    "converged on the gradient: every parameter is held at a bound by the "
                    "gradient (a corner of the box is the optimum)",
                )
                return
            if self.iterations >= s.max_iter:
                self._stop(
                    "iteration_limit",
                    f"iteration limit: {s.max_iter} iterations without convergence (eq. 29c)",
                )
                return
            D = self._diag(J)
            if not math.isfinite(radius):  # the first step is eq. 18 with μ = μ0
                p0, _ = self._lm_step(J, r, D, free, mu=s.mu0)
                radius = float(np.linalg.norm(D * p0)) or 1.0
            rr = float(r @ r)
            while True:  # find a step that reduces ‖r‖
                full, self.mu = self._lm_step(J, r, D, free, radius=radius)
                p = self._within_bounds(x, full, r, J)
                pnorm = float(np.linalg.norm(D * p))
                # a step cut by the bounds is judged by the length the model asked for
                plen = float(np.linalg.norm(D * full))
                Jp = J @ p
                pred = (rr - float(np.sum((r + Jp) ** 2))) / rr  # predicted reduction
                dirder = float(r @ Jp) / rr
                xt = x + p
                rt: FloatArray | None = None
                if pred > 0.0 and pnorm > 0.0:
                    dt = self._deltas(xt) if s.speculative else None
                    extra = [] if dt is None else self._perturbed(xt, dt, range(len(x)))
                    outs = yield from self._ask([xt, *extra])
                    if outs[0].ok:
                        assert outs[0].residuals is not None
                        rt = self._check_length(outs[0].residuals)
                    note = "run failed" if rt is None else "err_res increased"
                else:
                    note = "no descent within the bounds"
                if rt is not None and 0.1 * math.sqrt(float(rt @ rt)) < math.sqrt(rr):
                    actual = 1.0 - float(rt @ rt) / rr
                else:
                    actual = -1.0
                ratio = actual / pred if pred > 0.0 else 0.0
                if self.iterations == 0 and plen > 0.0:
                    radius = min(radius, plen)
                # trust-region update of MINPACK's lmdif
                if ratio <= 0.25:
                    shrink = 0.5 if actual >= 0.0 else 0.5 * dirder / (dirder + 0.5 * actual)
                    if rt is None:
                        shrink = FAILED_SHRINK
                    elif 0.1 * math.sqrt(float(rt @ rt)) >= math.sqrt(rr):
                        shrink = 0.1
                    shrink = min(max(shrink, 0.1), 0.5)
                    radius = shrink * (min(radius, plen / 0.1) if plen > 0 else radius)
                elif self.mu == 0.0 or ratio >= 0.75:
                    radius = plen / 0.5
                if ratio >= GAIN_MIN:
                    break
                self._record(xt, rt, False, f"rejected: {note}")
                collapsed = radius <= 1e-15 * float(np.linalg.norm(D * x))
                if self._radius_small(radius, D, x, free) or collapsed:
                    if note != "run failed":
                        self._stop(
                            "converged_step",
                            f"converged on the step: no step that changes a parameter by more "
                            f"than xtol = {s.xtol:g} (relative) reduces err_res any further",
                        )
                    else:
                        self._stop(
                            "damping_limit",
                            f"damping limit: the steps shrank to nothing and still {note} "
                            f"(mu = {self.mu:.3g}); the result is the best point found",
                        )
                    return
            # the step is taken
            assert rt is not None
            self.iterations += 1
            if abs(actual) <= s.ftol and pred <= s.ftol and ratio <= 2.0:
                self._set_point(xt, rt, None)
                self._record(xt, rt, True, "step")
                self._stop(
                    "converged_residual",
                    f"converged on the residual: the last step reduced ‖r‖² by a fraction "
                    f"{actual:.1e} <= ftol = {s.ftol:g}",
                )
                return
            if self._radius_small(radius, D, xt, free):
                self._set_point(xt, rt, None)
                self._record(xt, rt, True, "step")
                self._stop(
                    "converged_step",
                    f"converged on the step: the next step would change no parameter by "
                    f"more than xtol = {s.xtol:g} (relative)",
                )
                return
            if s.speculative:
                assert dt is not None
                J, frozen = yield from self._jacobian(xt, rt, dt, outs[1:])
            else:
                dt = self._deltas(xt)
                outs = yield from self._ask(self._perturbed(xt, dt, range(len(x))))
                J, frozen = yield from self._jacobian(xt, rt, dt, outs)
            x, r = xt, rt
            self._set_point(x, r, J)
            self._record(x, r, True, "step")
