"""The numba kernels of :mod:`fbia.iterators.smc.table` (a module of their own so that numba,
part of the ``bayes`` extra, is imported only when a table is used): the cubic B-spline of
the tabulated L, the 1-D log-prior tables and the Metropolis-Hastings moves of every particle
in one parallel pass."""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["moves", "prior_many", "spline_many"]


# -- kernels -----------------------------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def _bspline_weights(t: float, w: np.ndarray) -> None:
    """The four cubic B-spline weights of the coefficients i-1, i, i+1, i+2 at x = i + t."""
    s = 1.0 - t
    t2 = t * t
    t3 = t2 * t
    w[0] = s * s * s / 6.0
    w[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    w[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    w[3] = t3 / 6.0


@numba.njit(cache=True)
def _spline(coeffs, shape, grid_lower, inv_step, lower, upper, x, base, w) -> float:
    """The spline at ``x`` (-inf outside the box); ``base`` (d,) int and ``w`` (d, 4) are
    scratch arrays (no allocation per call)."""
    d = x.shape[0]
    for j in range(d):
        if not (lower[j] <= x[j] <= upper[j]):
            return -np.inf
    for j in range(d):
        u = (x[j] - grid_lower[j]) * inv_step[j]
        i = int(math.floor(u))
        if i > shape[j] - 3:  # the last cell (never reached inside the box)
            i = shape[j] - 3
        base[j] = i - 1
        _bspline_weights(u - i, w[j])
    total = 0.0
    if d == 1:
        for a in range(4):
            total += w[0, a] * coeffs[base[0] + a]
    elif d == 2:
        n1 = shape[1]
        for a in range(4):
            row = (base[0] + a) * n1 + base[1]
            s = 0.0
            for b in range(4):
                s += w[1, b] * coeffs[row + b]
            total += w[0, a] * s
    else:
        n1, n2 = shape[1], shape[2]
        for a in range(4):
            s1 = 0.0
            for b in range(4):
                row = ((base[0] + a) * n1 + base[1] + b) * n2 + base[2]
                s2 = 0.0
                for c in range(4):
                    s2 += w[2, c] * coeffs[row + c]
                s1 += w[1, b] * s2
            total += w[0, a] * s1
    return total


@numba.njit(cache=True)
def _prior(values, lower, inv_step, x) -> float:
    total = 0.0
    m = values.shape[1]
    for j in range(x.shape[0]):
        u = (x[j] - lower[j]) * inv_step[j]
        if not (0.0 <= u <= m - 1):
            return -np.inf
        i = min(int(u), m - 2)
        t = u - i
        a, b = values[j, i], values[j, i + 1]
        if a == -np.inf or b == -np.inf:
            v = a if t < 0.5 else b
        else:
            v = a + t * (b - a)
        total += v
    return total


@numba.njit(cache=True, parallel=True)
def spline_many(coeffs, shape, grid_lower, inv_step, lower, upper, x, out) -> None:
    d = x.shape[1]
    for i in numba.prange(x.shape[0]):
        base = np.empty(d, dtype=np.int64)
        w = np.empty((d, 4))
        out[i] = _spline(coeffs, shape, grid_lower, inv_step, lower, upper, x[i], base, w)


@numba.njit(cache=True, parallel=True)
def prior_many(values, lower, inv_step, x, out) -> None:
    for i in numba.prange(x.shape[0]):
        out[i] = _prior(values, lower, inv_step, x[i])


@numba.njit(cache=True, parallel=True)
def moves(
    coeffs, shape, grid_lower, inv_step, lower, upper, prior_values, prior_inv_step, factor,
    z, e, gamma, x, loglik, log_prior, accepted,
) -> None:  # fmt: skip
    n, m, d = z.shape
    for i in numba.prange(n):
        xi = x[i].copy()
        prop = np.empty(d)
        base = np.empty(d, dtype=np.int64)
        w = np.empty((d, 4))
        lli = loglik[i]
        lpi = log_prior[i]
        count = 0
        for k in range(m):
            for r in range(d):
                s = xi[r]
                for c in range(d):
                    s += factor[r, c] * z[i, k, c]
                prop[r] = s
            lpn = _prior(prior_values, lower, prior_inv_step, prop)
            if lpn == -np.inf:
                continue
            if gamma == 0.0:
                log_alpha = lpn - lpi
                lln = _spline(coeffs, shape, grid_lower, inv_step, lower, upper, prop, base, w)
            else:
                lln = _spline(coeffs, shape, grid_lower, inv_step, lower, upper, prop, base, w)
                if lln == -np.inf:
                    continue
                log_alpha = gamma * (lln - lli) + (lpn - lpi)
            if -e[i, k] < log_alpha:
                for r in range(d):
                    xi[r] = prop[r]
                lli = lln
                lpi = lpn
                count += 1
        for r in range(d):
            x[i, r] = xi[r]
        loglik[i] = lli
        log_prior[i] = lpi
        accepted[i] = count
