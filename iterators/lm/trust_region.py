"""The step of the robust Levenberg–Marquardt mode: eq. 18 with μ from a trust region.

Pure numerics on (J, r, D), shared by the chain in :mod:`fbia.iterators.lm.chains`:

* :func:`lm_step` solves p = −(JᵀJ + μD²)⁻¹Jᵀr for a given μ, or for the μ ≥ 0 that makes
  ‖Dp‖ ≈ radius (Moré 1978, the strategy of MINPACK's ``lmpar``; μ = 0, the Gauss–Newton
  step, when that is short enough), from an SVD of the column-scaled J;
* :func:`predicted_reduction` gives the reduction of ‖r‖² that the linear model predicts,
  without the cancellation of ‖r‖² − ‖r + Jp‖² (MINPACK's ``prered``);
* :func:`step_back` stops a step that would cross a bound from farther than
  :data:`NEAR_BOUND` of the parameter's range :data:`STEP_BACK` of the way to it;
* :func:`within_bounds` turns a step that leaves the box into its projection or its
  shortening, whichever the linear model prefers.

Moré, J. J. (1978): The Levenberg–Marquardt algorithm: implementation and theory.  In
G. A. Watson (ed.), Numerical Analysis, Lecture Notes in Mathematics 630, Springer, 105-116.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: A step that would cross a bound from farther than this fraction of the parameter's range
#: goes only :data:`STEP_BACK` of the way to it; nearer, it may reach the bound (projection),
#: so that an optimum on a bound is reached in a few halvings.  A Gauss-Newton step from far
#: away lands on a bound where a forward model often cannot be solved: on the flow cell
#: (``benchmarks/bench_lm_vs_scipy.py``) Table 1's black start (1000 Pa, 0.4) stepped to the
#: E bound, 100 Pa, where the biofilm has no steady state (a failed run of ~1 s, ten times a
#: solved one); halfway it lands at 550 Pa.  scipy's ``trf`` keeps its iterates strictly inside
#: the bounds for the same reason (Coleman-Li scaling).
NEAR_BOUND = 0.1
STEP_BACK = 0.5


def lm_step(
    J: FloatArray,
    r: FloatArray,
    D: FloatArray,
    free: BoolArray,
    mu: float | None = None,
    radius: float | None = None,
    mu_guess: float = 0.0,
) -> tuple[FloatArray, float]:
    """The step of eq. 18 over the free parameters and the μ it was computed with.

    Give ``mu``, or ``radius`` (then μ ≥ 0 is chosen so that ‖Dp‖ is within 10 % of it, by
    a safeguarded Newton iteration on ‖q(μ)‖ started from ``mu_guess``).  Singular values
    below max(shape)·ε·s_max are dropped (the minimum-norm step in the scaled variables).
    """
    p = np.zeros(J.shape[1])
    if not np.any(free):
        return p, 0.0 if mu is None else mu
    U, sv, Vt = np.linalg.svd(J[:, free] / D[free], full_matrices=False)
    c = U.T @ r
    rank = sv > sv.max(initial=0.0) * max(J.shape) * np.finfo(float).eps
    sc2 = (sv * c) ** 2

    def weights(lam: float) -> FloatArray:
        with np.errstate(divide="ignore", invalid="ignore"):
            w: FloatArray = np.where(rank, sv * c / (sv**2 + lam), 0.0)
        return w

    if mu is None:
        assert radius is not None
        mu = 0.0
        if np.linalg.norm(weights(0.0)) > 1.1 * radius:
            lo, hi = 0.0, math.sqrt(float(np.sum(sc2))) / radius
            lam = min(max(mu_guess if math.isfinite(mu_guess) else 0.0, 1e-3 * hi), hi)
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


def predicted_reduction(
    J: FloatArray, r: FloatArray, p: FloatArray, D: FloatArray, mu: float, exact: bool
) -> tuple[float, float]:
    """(pred, dirder): the reduction of ‖r‖² the linear model predicts for the step p, and
    the directional derivative rᵀJp, both relative to ‖r‖².

    For the step of eq. 18 itself (``exact``), ‖r‖² − ‖r + Jp‖² = ‖Jp‖² + 2μ‖Dp‖² and
    rᵀJp = −(‖Jp‖² + μ‖Dp‖²): sums of squares, accurate to round-off however small the step
    (MINPACK's ``prered``, ``dirder``).  For a step changed by the bounds,
    −(2r + Jp)ᵀJp, which is still free of the cancellation of ‖r‖² − ‖r + Jp‖².
    """
    rr = float(r @ r)
    Jp = J @ p
    jp2 = float(Jp @ Jp)
    if exact:
        dp2 = float(np.sum((D * p) ** 2))
        return (jp2 + 2.0 * mu * dp2) / rr, -(jp2 + mu * dp2) / rr
    rjp = float(r @ Jp)
    return -(2.0 * rjp + jp2) / rr, rjp / rr


def step_back(x: FloatArray, p: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """The step ``p`` from ``x`` shortened, along its direction, to :data:`STEP_BACK` of the
    way to the first bound it would cross from farther than :data:`NEAR_BOUND` of that
    parameter's range; ``p`` itself (the same object) when it crosses no such bound.  A step
    that stays inside the box, or crosses only near bounds, is left to :func:`within_bounds`.
    A parameter with an infinite bound has an infinite range: no bound of it is ever "far"
    (its steps are projected or shortened as before the step-back)."""
    xt = x + p
    width = upper - lower
    with np.errstate(invalid="ignore"):  # inf - inf of an unbounded parameter: not far
        far_lo = (xt < lower) & (x - lower > NEAR_BOUND * width)
        far_hi = (xt > upper) & (upper - x > NEAR_BOUND * width)
    if not np.any(far_lo | far_hi):
        return p
    with np.errstate(divide="ignore", invalid="ignore"):
        to_bound = np.where(far_lo, (lower - x) / p, np.where(far_hi, (upper - x) / p, np.inf))
    return STEP_BACK * float(np.min(to_bound)) * p


def within_bounds(
    x: FloatArray,
    p: FloatArray,
    r: FloatArray,
    J: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
) -> FloatArray:
    """A step that leaves the box becomes the better (by the linear model) of its
    projection onto the box and the step shortened to the box; others are returned as
    they are."""
    xt = x + p
    if np.all(xt >= lower) and np.all(xt <= upper):
        return p
    projected = np.clip(xt, lower, upper) - x
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(p > 0, (upper - x) / p, np.where(p < 0, (lower - x) / p, 1.0))
    shortened = float(np.clip(np.min(room), 0.0, 1.0)) * p
    model = [float(np.sum((r + J @ q) ** 2)) for q in (projected, shortened)]
    return projected if model[0] <= model[1] else shortened
