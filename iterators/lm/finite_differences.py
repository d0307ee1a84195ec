"""Finite-difference stencils of the Levenberg–Marquardt Jacobian (Paper A eq. 21-23).

Pure functions: they say *where* the residuals are needed and how the columns of J follow
from them; :class:`fbia.iterators.lm.chains.LMChain` asks the evaluator for the points.

Forward differences (eq. 22-23) cost n_x runs and are accurate to O(δx) + O(η/δx), where η
is the relative noise of the residuals (round-off, or the tolerance of a forward solver);
δx = α + β|x| with β ≈ √η balances the two, which gives J to about √η (MINPACK's choice for
a function computed to machine precision is β = √ε).  Near the optimum of a badly
conditioned problem that is not enough: a Gauss–Newton step computed from J to √η lands
only cond(J)·√η close to the optimum, whatever the residuals allow (NIST Lanczos3: LRE 4-6
with forward, 6-9 with central differences from the same point).  Central differences are
accurate to O(δx²) + O(η/δx); the step that balances those is η^(1/3) = β^(2/3), i.e. the
forward step times β^(-1/3) (Dennis & Schnabel 1996, sec. 5.6; Nocedal & Wright 2006,
sec. 8.1).  Where the box leaves room on one side only, the second-order one-sided
three-point formula is used instead (as scipy's ``approx_derivative(method='3-point')``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def forward_steps(
    x: FloatArray,
    alpha: FloatArray,
    beta: float,
    lower: FloatArray,
    upper: FloatArray,
    signed: bool = False,
) -> FloatArray:
    """Perturbations δx_i = α + β·x_i (eq. 21), turned round where they leave the bounds.

    ``signed=True`` uses x_i as written (Paper A: a negative x_i shrinks or flips δx_i);
    otherwise |x_i|, so that δx_i never vanishes.  A step that fits on neither side becomes
    half the room on the roomier side.
    """
    d = alpha + beta * (x if signed else np.abs(x))
    d = np.where(d == 0.0, np.where(alpha > 0, alpha, beta), d)  # x_i = 0 with α = 0
    for i in range(len(x)):
        if not lower[i] <= x[i] + d[i] <= upper[i]:
            d[i] = -d[i]
            if not lower[i] <= x[i] + d[i] <= upper[i]:
                room_up, room_down = upper[i] - x[i], x[i] - lower[i]
                d[i] = 0.5 * room_up if room_up >= room_down else -0.5 * room_down
    return d


def perturbed(x: FloatArray, d: FloatArray, cols: range | list[int]) -> list[FloatArray]:
    """x + δx_i e_i for every i in ``cols``."""
    out = []
    for i in cols:
        xi = x.copy()
        xi[i] += d[i]
        out.append(xi)
    return out


def central_factor(beta: float) -> float:
    """Factor from the forward to the central-difference step: β^(-1/3) for 0 < β < 1 (the
    step η^(1/3) for the noise level η = β² that β = √η was chosen for), else 1."""
    return float(beta ** (-1.0 / 3.0)) if 0.0 < beta < 1.0 else 1.0


@dataclass(frozen=True)
class CentralStencil:
    """Two points per parameter and how column i of J follows from their residuals.

    Column i is ``(c0[i]·r(x) + c1[i]·r(points[2i]) + c2[i]·r(points[2i+1])) / h[i]``:
    central ``(r(x+h) − r(x−h)) / 2h``, or one-sided ``(−3r(x) + 4r(x+h) − r(x+2h)) / 2h``
    (h negative: the backward variant) where the box has room on one side only.
    """

    points: list[FloatArray]
    h: FloatArray
    c0: FloatArray
    c1: FloatArray
    c2: FloatArray

    def column(self, i: int, r0: FloatArray, r1: FloatArray, r2: FloatArray) -> FloatArray:
        col: FloatArray = (self.c0[i] * r0 + self.c1[i] * r1 + self.c2[i] * r2) / self.h[i]
        return col


def central_stencil(
    x: FloatArray,
    alpha: FloatArray,
    beta: float,
    lower: FloatArray,
    upper: FloatArray,
) -> CentralStencil:
    """The second-order stencil at x, with steps h_i = β^(-1/3)·(α_i + β|x_i|)."""
    n = len(x)
    h = central_factor(beta) * (alpha + beta * np.abs(x))
    h = np.where(h == 0.0, np.where(alpha > 0, alpha, beta), h)
    c0, c1, c2 = np.zeros(n), np.full(n, 0.5), np.full(n, -0.5)
    points: list[FloatArray] = []
    for i in range(n):
        hi = float(h[i])
        if lower[i] <= x[i] - hi and x[i] + hi <= upper[i]:
            offsets = (hi, -hi)
        else:
            if not x[i] + 2.0 * hi <= upper[i]:
                if lower[i] <= x[i] - 2.0 * hi:
                    hi = -hi
                else:  # no room for 2h on either side: half the roomier side's room
                    up, down = upper[i] - x[i], x[i] - lower[i]
                    hi = 0.5 * up if up >= down else -0.5 * down
            offsets = (hi, 2.0 * hi)
            h[i], c0[i], c1[i], c2[i] = hi, -1.5, 2.0, -0.5
        for off in offsets:
            xi = x.copy()
            xi[i] += off
            points.append(xi)
    return CentralStencil(points=points, h=h, c0=c0, c1=c1, c2=c2)
