"""The robust Levenberg–Marquardt mode (the default): Paper A's step (eq. 18), made robust.

A step is taken only if it reduces ‖r‖ (by at least
1e-4 of the reduction the linear model predicts); otherwise μ grows and a new step is
computed from the same J, without new runs.  μ is chosen by a trust region on ‖D Δx‖
(Moré 1978, the strategy of MINPACK): μ = 0, a Gauss–Newton step, whenever that step is
short enough, which makes the last iterations converge fast even when J is badly
conditioned.  D is the largest Jacobian column norms seen so far, so parameters of very
different magnitude (E ~ 400 Pa, ν ~ 0.3, growth factors 1e4 and 1e-2) are treated alike.
A step that would cross a bound from farther than a tenth of the range goes halfway to it
(:func:`~fbia.iterators.lm.trust_region.step_back`: a bound is where forward models often have
no solution); a step that leaves the bounds from nearer is projected onto them or shortened to
them (whichever the linear model prefers), and a parameter stays at its bound while the
gradient pushes it outward.  After a declined step the trust region shrinks below that step's
length (MINPACK shrinks from ten times it, so that a declined Gauss-Newton step is asked for
again, unchanged).  A failed forward run is a declined step (the trust region shrinks); a failed
perturbed run is repeated on the other side of x, and a parameter whose column still fails
is held fixed for one step.  Relative criteria on the reduction of ‖r‖ (ftol), on the
step (xtol) and on the angle between r and the columns of J (gtol) complement eq. 29.

The last iterations use a central-difference Jacobian (``final_jacobian = "central"``, see
:mod:`fbia.iterators.lm.finite_differences`), and a run that converges only because a column of
J vanished (a plateau) is tried once more with MINPACK's longer first step, then reported as
``plateau``.

>>> import numpy as np
>>> from fbia.iterators.lm.chains import LMSettings, Outcome
>>> from fbia.iterators.lm.robust import RobustChain
>>> t = np.linspace(0.0, 1.0, 8)
>>> fun = lambda x: x[0] * np.exp(-x[1] * t) - 2.0 * np.exp(-0.5 * t)
>>> chain = RobustChain(0, np.array([1.0, 1.0]), np.full(2, -np.inf), np.full(2, np.inf),
...                     LMSettings.for_mode("robust", 2, alpha=1e-8, beta=1e-8), ["a", "k"])
>>> gen = chain.run()
>>> batch = next(gen)
>>> while True:
...     try:
...         batch = gen.send([Outcome(fun(x)) for x in batch])
...     except StopIteration:
...         break
>>> chain.success, np.round(chain.x, 6).tolist()      # status: which criterion held first
(True, [2.0, 0.5])
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence

import numpy as np
from numpy.typing import NDArray

from .chains import SUCCESS, FloatArray, LMChain, Outcome
from .finite_differences import central_stencil, perturbed
from .trust_region import lm_step, predicted_reduction, step_back, within_bounds

#: A step is taken (robust mode) when the actual reduction of ‖r‖² is at least this fraction of
#: the reduction the linear model predicts (MINPACK's 1e-4).
GAIN_MIN = 1e-4

#: Factor on the trust region after a failed run (no residual to judge the step by).
FAILED_SHRINK = 0.5

#: The first trust region of the second attempt, relative to ‖D x0‖ (MINPACK's ``factor``).
FIRST_RADIUS_RETRY = 100.0

#: A column of J below this fraction of the largest norm it had marks a plateau.
PLATEAU = float(np.sqrt(np.finfo(float).eps))


class RobustChain(LMChain):
    """One run of the robust mode; drive :meth:`run` as :class:`LMChain` says."""

    def _central_jacobian(
        self, x: FloatArray, r0: FloatArray
    ) -> Generator[list[FloatArray], list[Outcome], tuple[FloatArray, list[int]]]:
        """J at x from second-order differences (2 n_x runs in one batch, see
        :mod:`fbia.iterators.lm.finite_differences`).  A column whose runs fail keeps its last
        value and its parameter is held fixed for the next step."""
        s = self.settings
        self._count("central")
        stencil = central_stencil(x, s.alpha, s.beta, self.lower, self.upper)
        outs = yield from self._ask(stencil.points)
        J = np.zeros((len(r0), len(x))) if self.J is None else self.J.copy()
        bad = []
        for i in range(len(x)):
            o1, o2 = outs[2 * i], outs[2 * i + 1]
            if o1.ok and o2.ok:
                assert o1.residuals is not None and o2.residuals is not None
                r1, r2 = self._check_length(o1.residuals), self._check_length(o2.residuals)
                J[:, i] = stencil.column(i, r0, r1, r2)
            else:
                bad.append(i)
        return J, bad

    def _jacobian_at(
        self, x: FloatArray, r0: FloatArray, outs: Sequence[Outcome]
    ) -> Generator[list[FloatArray], list[Outcome], tuple[FloatArray, list[int]]]:
        """J at x: the model's tangents (``jacobian = "tangent"``; ``outs[0]`` is x's run),
        central differences (``"central"``) or forward differences, from ``outs[1:]`` when
        they are x's perturbed runs, else from new runs (a run without tangents, such as one
        stored before, falls back to them)."""
        s = self.settings
        tangent = outs[0].jacobian if s.jacobian == "tangent" else None
        if tangent is not None:
            J = np.asarray(tangent, dtype=float)
            if J.shape != (len(r0), len(x)):
                raise RuntimeError(f"tangent Jacobian of shape {J.shape}, want {(len(r0), len(x))}")
            self._count("tangent")
            return J, []
        if s.jacobian == "central":
            return (yield from self._central_jacobian(x, r0))
        d = self._deltas(x)
        if len(outs) == len(x) + 1:
            return (yield from self._jacobian(x, r0, d, outs[1:]))
        more = yield from self._ask(perturbed(x, d, range(len(x))))
        return (yield from self._jacobian(x, r0, d, more))

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

    def _radius_small(
        self, radius: float, D: FloatArray, x: FloatArray, free: NDArray[np.bool_]
    ) -> bool:
        """Step criterion: no step in the trust region ‖D p‖ ≤ radius changes a free parameter
        by more than xtol·(|x_i| + α_i/β), i.e. radius/D_i ≤ xtol·(|x_i| + α_i/β)."""
        typical = np.where(self.settings.typical > 0, self.settings.typical, 1e-300)
        reach = radius / D[free]
        return bool(np.all(reach <= self.settings.xtol * (np.abs(x[free]) + typical[free])))

    def run(self) -> Generator[list[FloatArray], list[Outcome], None]:
        """The robust mode: one attempt from x0 with the first trust region set by μ0; if it
        ends on a plateau (see :meth:`_plateau`), a second one from x0 with MINPACK's first
        trust region, 100‖D x0‖ (Moré 1978), which takes a longer first step.  A plateau
        again is not a success (status ``plateau``)."""
        yield from self._attempt(None)
        plateau = self._plateau()
        if plateau is None:
            return
        self._record(self.x if self.x is not None else self.x0, self.r, False, plateau)
        self.status, self.message, self.mu = "", "", math.nan
        self.x = self.r = self.J = self.jac_x = self._scale = None
        yield from self._attempt(FIRST_RADIUS_RETRY)
        plateau = self._plateau()
        if plateau is not None:
            self._stop(
                "plateau",
                f"{plateau}, from both first trust regions; not a minimum (the residuals no "
                "longer depend on a parameter): try another initial guess",
            )

    def _plateau(self) -> str | None:
        """A converged run whose result lies where a column of J has vanished (below √ε of
        the largest, non-zero norm it had in the run) ended on a plateau: the gradient is
        zero because the residuals stopped depending on a parameter (an exponential under-
        or overflowed), not at a minimum.  Returns the reason, or None."""
        if not self.success or self.J is None or self._scale is None:
            return None
        lost = (np.linalg.norm(self.J, axis=0) <= PLATEAU * self._scale) & (self._scale > 0)
        if not np.any(lost):
            return None
        names = ", ".join(str(self.names[int(i)]) for i in np.flatnonzero(lost))
        return f"ended on a plateau: the residuals no longer depend on {names}"

    def _attempt(
        self, first_radius: float | None
    ) -> Generator[list[FloatArray], list[Outcome], None]:
        """Levenberg–Marquardt with μ chosen by a trust region on ‖D Δx‖ (Moré 1978, the
        strategy of MINPACK), projected steps at the bounds, failed runs as declined steps.

        Two phases: forward differences (n_x runs per J) until a relative criterion (ftol,
        xtol, gtol) holds, then, with ``final_jacobian = "central"``, central differences
        (2 n_x runs per J) from that point on until a criterion holds again.  The forward
        phase alone stops where its Jacobian's error stops the iteration, which on badly
        conditioned problems is far from what the residuals determine."""
        s = self.settings
        x = self.x0.astype(float).copy()
        # forward differences: x's perturbed runs in the same batch (_jacobian_at uses them)
        batch = perturbed(x, self._deltas(x), range(len(x))) if s.jacobian == "forward" else []
        outs = yield from self._ask([x, *batch])
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
        J, frozen = yield from self._jacobian_at(x, r, outs)
        self._set_point(x, r, J)
        self.mu = s.mu0
        self._record(x, r, True, "start")
        radius = math.nan  # set at the first step
        first_iteration = self.iterations
        # phase 2: central-difference Jacobians (from the start with jacobian = "central")
        central = s.jacobian == "central"
        exact = s.jacobian == "tangent"  # J from tangents: no phase 2

        def final(status: str, message: str) -> bool:
            """Stop here (True), or go on to phase 2 with a central-difference J (False)."""
            if central or exact or s.final_jacobian != "central" or status not in SUCCESS:
                tail = "; J from central differences" if central else ""
                self._stop(status, message + ("; J from tangents" if exact else tail))
                return True
            return False

        sharpen = False  # go on to phase 2 at x: a central-difference J, no step
        while True:
            if sharpen:
                central, sharpen, radius = True, False, math.inf
                J, frozen = yield from self._central_jacobian(x, r)
                self._set_point(x, r, J)
                self._record(x, r, True, "central-difference Jacobian")
            assert self.J is not None
            J = self.J
            g = J.T @ r
            free = self._free(x, g, frozen)
            verdict = self._verdict(g, free)
            if verdict is not None:
                status, message, absolute = verdict
                if absolute:
                    self._stop(status, message + ("; J from tangents" if exact else ""))
                    return
                if final(status, message):
                    return
                sharpen = True
                continue
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
            if math.isnan(radius):
                if first_radius is None:  # the step of eq. 18 with μ = μ0
                    p0, _ = lm_step(J, r, D, free, mu=s.mu0)
                    radius = float(np.linalg.norm(D * p0)) or 1.0
                else:  # MINPACK: a multiple of the scaled length of x
                    radius = first_radius * (float(np.linalg.norm(D * x)) or 1.0)
            rr = float(r @ r)
            while True:  # find a step that reduces ‖r‖
                full, self.mu = lm_step(J, r, D, free, radius=radius, mu_guess=self.mu)
                # a step towards a far bound goes halfway to it (trust_region.NEAR_BOUND)
                asked = step_back(x, full, self.lower, self.upper)
                p = within_bounds(x, asked, r, J, self.lower, self.upper)
                pnorm = float(np.linalg.norm(D * p))
                # a step cut by the bounds is judged by the length the model asked for, or
                # that of the stepped-back step
                plen = float(np.linalg.norm(D * asked))
                pred, dirder = predicted_reduction(J, r, p, D, self.mu, exact=p is full)
                xt = x + p
                rt: FloatArray | None = None
                dt: FloatArray | None = None
                if pred > 0.0 and pnorm > 0.0:
                    speculate = s.speculative and s.jacobian == "forward" and not central
                    dt = self._deltas(xt) if speculate else None
                    extra = [] if dt is None else perturbed(xt, dt, range(len(x)))
                    outs = yield from self._ask([xt, *extra])
                    if outs[0].ok:
                        assert outs[0].residuals is not None
                        rt = self._check_length(outs[0].residuals)
                    note = "run failed" if rt is None else "err_res increased"
                else:
                    note = "no descent within the bounds"
                if rt is not None and 0.1 * math.sqrt(float(rt @ rt)) < math.sqrt(rr):
                    actual = float((r - rt) @ (r + rt)) / rr
                else:
                    actual = -1.0
                ratio = actual / pred if pred > 0.0 else 0.0
                if self.iterations == first_iteration and plen > 0.0:
                    radius = min(radius, plen)
                # trust-region update of MINPACK's lmdif (but for the shrink, below)
                if ratio <= 0.25:
                    shrink = 0.5 if actual >= 0.0 else 0.5 * dirder / (dirder + 0.5 * actual)
                    if rt is None:
                        shrink = FAILED_SHRINK
                    elif 0.1 * math.sqrt(float(rt @ rt)) >= math.sqrt(rr):
                        shrink = 0.1
                    shrink = min(max(shrink, 0.1), 0.5)
                    # shorter than this trial (MINPACK's min(radius, plen / 0.1) asks a
                    # rejected Gauss-Newton step, or one stepped back from a far bound, again
                    # until the region shrinks below it: the same point, the same verdict)
                    radius = shrink * (min(radius, plen) if plen > 0 else radius)
                elif self.mu == 0.0 or ratio >= 0.75:
                    radius = plen / 0.5
                if ratio >= GAIN_MIN:
                    break
                self._record(xt, rt, False, f"rejected: {note}")
                if rt is not None and abs(actual) <= s.ftol and 0.0 < pred <= s.ftol:
                    # MINPACK's ftol test, on declined steps too: no step in reach changes ‖r‖²
                    # by more than ftol, the change it made is round-off
                    if final(
                        "converged_residual",
                        f"converged on the residual: no step reduces ‖r‖² by more than a "
                        f"fraction ftol = {s.ftol:g} (predicted {pred:.1e}, actual {actual:.1e})",
                    ):
                        return
                    sharpen = True
                    break
                collapsed = radius <= 1e-15 * float(np.linalg.norm(D * x))
                if self._radius_small(radius, D, x, free) or collapsed:
                    if note == "run failed":
                        self._stop(
                            "damping_limit",
                            f"damping limit: the steps shrank to nothing and still {note} "
                            f"(mu = {self.mu:.3g}); the result is the best point found",
                        )
                        return
                    if final(
                        "converged_step",
                        f"converged on the step: no step that changes a parameter by more "
                        f"than xtol = {s.xtol:g} (relative) reduces err_res any further",
                    ):
                        return
                    sharpen = True
                    break
            if sharpen:
                continue
            # the step is taken
            assert rt is not None
            self.iterations += 1
            stop: tuple[str, str] | None = None
            if abs(actual) <= s.ftol and pred <= s.ftol and ratio <= 2.0:
                stop = (
                    "converged_residual",
                    f"converged on the residual: the last step reduced ‖r‖² by a fraction "
                    f"{actual:.1e} <= ftol = {s.ftol:g}",
                )
            elif self._radius_small(radius, D, xt, free):
                stop = (
                    "converged_step",
                    f"converged on the step: the next step would change no parameter by "
                    f"more than xtol = {s.xtol:g} (relative)",
                )
            if stop is not None and final(*stop):
                self._set_point(xt, rt, None)
                self._record(xt, rt, True, "step")
                return
            if exact:
                J, frozen = yield from self._jacobian_at(xt, rt, outs)
                note = "step"
            elif stop is not None or central:
                note = "step" if central else "step; central-difference Jacobian from here on"
                central = True
                radius = math.inf if stop is not None else radius
                J, frozen = yield from self._central_jacobian(xt, rt)
            elif dt is not None:
                J, frozen = yield from self._jacobian(xt, rt, dt, outs[1:])
                note = "step"
            else:
                dt = self._deltas(xt)
                outs = yield from self._ask(perturbed(xt, dt, range(len(x))))
                J, frozen = yield from self._jacobian(xt, rt, dt, outs)
                note = "step"
            x, r = xt, rt
            self._set_point(x, r, J)
            self._record(x, r, True, note)
