"""Compiled GP posterior mean k(x*, X) alpha for many points at once (Paper B, eq. 28a).

SMC on the surrogate evaluates the mean at N = 10 000 particles against n = 2000 training
points in every Metropolis-Hastings step: 1.4e8 kernel factors in 7-D per call, nearly all of
the run time at the paper's settings. :func:`fused_kernels` builds (on first use: numba
imports slowly) parallel loops that never form the (M, n) cross-covariance matrix:

* ``product_means``, the product of 1-D Matérn 3/2 kernels (Remark 9). exp(-|a - b|) =
  min(e^-a e^b, e^a e^-b): with the exponentials of every particle and training coordinate
  precomputed, the pair loop has no exp left and vectorises (numba has no vectorised exp
  without Intel's SVML). Four particles share each pass over the training points, so every
  training coordinate loaded serves four of them: 1.8x faster than one particle per pass
  (0.035 s instead of 0.063 s of one core for the 7-D, 2000-point mean at 10 000 points).
  Scaled inputs beyond :data:`EXP_FREE_RANGE` (length scales near their lower bound) would
  overflow e^a: such a GP takes a loop with one exp per pair.
* ``single_mean``, one Matérn 3/2 kernel of the scaled Euclidean distance (one exp per pair).

Both give the numbers of the numpy blocks in :mod:`.gp` up to round-off.

:func:`fused_means` evaluates the means of several GPs with product kernels on the same inputs
in one compiled call: the residual emulator's principal components
(:mod:`.residuals`) at every particle of an SMC move, without one Python call, one
standardisation and one thread launch per component (issue 30).  A GP hands its part over as
:class:`KernelTerms` (:meth:`GpSurrogate.kernel_terms <.gp.GpSurrogate.kernel_terms>`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: The Matérn-3/2 kernel's factor, k(r) = (1 + √3 r/l) exp(-√3 r/l) (also gp.py, kernels.py).
SQRT3 = math.sqrt(3.0)
#: Largest |scaled input| for the exp-free product-kernel loop (e^a e^-b stays far from
#: overflow and underflow: e^(2 * 300) ~ 1e260).
EXP_FREE_RANGE = 300.0
#: particles per parallel block of the compiled loops
BLOCK = 32
#: numba's fast-math flags of the compiled loops (here and in :mod:`.kernels`): every one
#: but ``reassoc``.  With ``reassoc`` LLVM may reorder the sums, and a parallel loop's sums
#: came out in another order when numba loaded it from its cache than when it compiled it
#: (numba 0.68, measured 2026-11-30: the 2-D mean of a 965-run GP at 3000 points differed in
#: the last bits, and a gp_smc posterior's MAP moved 400.08 -> 399.86 Pa between a study's
#: first run and its rerun from the store).  Without it a run gives the same bits compiled or
#: cached, at the same speed (``tests/iterators/surrogates/test_compiled_loops.py``).
FASTMATH = {"nnan", "ninf", "nsz", "arcp", "contract", "afn"}


@dataclass(frozen=True)
class KernelTerms:
    """A trained GP's posterior mean (eq. 28a) as the compiled loops take it: the mean at
    standardised inputs u is ``factor * sum_i alpha_i k(u * scale, xt_t[:, i])`` with the
    Matérn 3/2 kernel of unit length scale (a product of 1-D ones when ``product``)."""

    product: bool
    scale: FloatArray  # sqrt(3) / length scale per standardised input, (d,)
    xt_t: FloatArray  # scaled standardised training inputs, (d, n), C-contiguous
    alpha: FloatArray  # (K + sigma_n^2 I)^-1 (y - m) / (output scale), (n,)
    factor: float  # output scale * signal variance

    @classmethod
    def of(
        cls, product: bool, lengthscale: FloatArray, xs_train: FloatArray, alpha: FloatArray,
        factor: float,
    ) -> KernelTerms:  # fmt: skip
        d = xs_train.shape[1]
        ell = np.asarray(lengthscale, dtype=float)
        scale = SQRT3 / (ell if product else np.full(d, ell[0]))
        xt_t = np.ascontiguousarray((xs_train * scale).T)
        return cls(product, scale, xt_t, np.ascontiguousarray(alpha, dtype=float), float(factor))

    @functools.cached_property
    def exps(self) -> tuple[FloatArray, FloatArray]:
        """exp(+xt_t), exp(-xt_t): the training half of the exp-free product loop."""
        return np.exp(self.xt_t), np.exp(-self.xt_t)

    @functools.cached_property
    def span(self) -> float:
        return float(np.abs(self.xt_t).max(initial=0.0))


def fused_mean(terms: KernelTerms, xs: FloatArray) -> FloatArray:
    """``factor * k(xs, X) alpha`` at standardised inputs ``xs`` (M, d) by the compiled loops."""
    if terms.product:
        return np.asarray(fused_means([terms], xs)[:, 0])
    a = np.ascontiguousarray(xs * terms.scale)
    return np.asarray(terms.factor * fused_kernels()[1](a, terms.xt_t, terms.alpha, BLOCK))


def fused_means(terms: Sequence[KernelTerms], xs: FloatArray) -> FloatArray:
    """:func:`fused_mean` of several GPs with product kernels and training sets of one size
    on the same standardised inputs ``xs`` (M, d), as (M, len(terms)), in one compiled call.
    A GP whose scaled inputs reach :data:`EXP_FREE_RANGE` (very short length scales) takes
    the loop with one exp per pair instead of the exp-free one."""
    if not terms or not all(t.product for t in terms) or len({t.xt_t.shape for t in terms}) > 1:
        raise ValueError("fused_means: GPs with product kernels and one training size")
    a = np.stack([xs * t.scale for t in terms])  # (C, M, d)
    reach = np.abs(a).max(axis=(1, 2), initial=0.0)
    span = np.array([t.span for t in terms])
    wide = (reach >= EXP_FREE_RANGE) | (span >= EXP_FREE_RANGE)
    safe = np.where(wide[:, None, None], 0.0, a)  # no e^a of the wide ones (unused, finite)
    xt = np.stack([t.xt_t for t in terms])
    ones = np.ones_like(xt[0])
    ep_t = np.stack([ones if w else t.exps[0] for t, w in zip(terms, wide, strict=True)])
    em_t = np.stack([ones if w else t.exps[1] for t, w in zip(terms, wide, strict=True)])
    alpha = np.stack([t.alpha * t.factor for t in terms])
    raw = fused_kernels()[0](a, xt, np.exp(safe), np.exp(-safe), ep_t, em_t, alpha, wide, BLOCK)
    return np.ascontiguousarray(raw.T)


@functools.cache
def fused_kernels() -> Any:
    """(product_means, single_mean), JIT-compiled."""
    import numba

    @numba.njit(fastmath=FASTMATH, cache=True)
    def product_rows(xs, xt_t, ep_s, em_s, ep_t, em_t, alpha, start, stop, out, p, e):
        """out[i] = sum_k alpha_k prod_j (1 + r_j) exp(-sum_j r_j), i in [start, stop)."""
        d = xs.shape[1]
        n = xt_t.shape[1]
        p0, p1, p2, p3 = p[0], p[1], p[2], p[3]
        e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
        for i0 in range(start, stop, 4):
            # the last group of a block repeats its last particle (same value written)
            i1, i2, i3 = min(i0 + 1, stop - 1), min(i0 + 2, stop - 1), min(i0 + 3, stop - 1)
            p[:] = 1.0
            e[:] = 1.0
            for j in range(d):
                x0, ep0, em0 = xs[i0, j], ep_s[i0, j], em_s[i0, j]
                x1, ep1, em1 = xs[i1, j], ep_s[i1, j], em_s[i1, j]
                x2, ep2, em2 = xs[i2, j], ep_s[i2, j], em_s[i2, j]
                x3, ep3, em3 = xs[i3, j], ep_s[i3, j], em_s[i3, j]
                row, rp, rm = xt_t[j], ep_t[j], em_t[j]
                for k in range(n):
                    r, a, c = row[k], rp[k], rm[k]
                    p0[k] *= 1.0 + abs(x0 - r)
                    e0[k] *= min(em0 * a, ep0 * c)
                    p1[k] *= 1.0 + abs(x1 - r)
                    e1[k] *= min(em1 * a, ep1 * c)
                    p2[k] *= 1.0 + abs(x2 - r)
                    e2[k] *= min(em2 * a, ep2 * c)
                    p3[k] *= 1.0 + abs(x3 - r)
                    e3[k] *= min(em3 * a, ep3 * c)
            acc0 = acc1 = acc2 = acc3 = 0.0
            for k in range(n):
                acc0 += alpha[k] * p0[k] * e0[k]
                acc1 += alpha[k] * p1[k] * e1[k]
                acc2 += alpha[k] * p2[k] * e2[k]
                acc3 += alpha[k] * p3[k] * e3[k]
            out[i0], out[i1], out[i2], out[i3] = acc0, acc1, acc2, acc3

    @numba.njit(fastmath=FASTMATH, cache=True)
    def product_rows_exp(xs, xt_t, alpha, start, stop, out, p, e):
        """product_rows with one exp per pair: any scaled inputs."""
        d = xs.shape[1]
        n = xt_t.shape[1]
        p0, e0 = p[0], e[0]
        for i in range(start, stop):
            p0[:] = 1.0
            e0[:] = 0.0
            for j in range(d):
                x0 = xs[i, j]
                row = xt_t[j]
                for k in range(n):
                    t = abs(x0 - row[k])
                    p0[k] *= 1.0 + t
                    e0[k] += t
            acc = 0.0
            for k in range(n):
                acc += alpha[k] * p0[k] * np.exp(-e0[k])
            out[i] = acc

    @numba.njit(parallel=True, fastmath=FASTMATH, cache=True)
    def product_means(xs, xt_t, ep_s, em_s, ep_t, em_t, alpha, wide, block):
        """The product-kernel means of C GPs: xs, ep_s, em_s (C, M, d); xt_t, ep_t, em_t
        (C, d, n); alpha (C, n); wide (C,): the loop with exps; out (C, M)."""
        n_c, m = xs.shape[0], xs.shape[1]
        n = xt_t.shape[2]
        out = np.empty((n_c, m))
        n_blocks = (m + block - 1) // block
        for b in numba.prange(n_blocks):
            p = np.empty((4, n))  # prod_j (1 + r_j) of four particles
            e = np.empty((4, n))  # exp(-sum_j r_j) of the same four
            stop = min(m, (b + 1) * block)
            for c in range(n_c):
                if wide[c]:
                    product_rows_exp(xs[c], xt_t[c], alpha[c], b * block, stop, out[c], p, e)
                else:
                    product_rows(
                        xs[c], xt_t[c], ep_s[c], em_s[c], ep_t[c], em_t[c], alpha[c],
                        b * block, stop, out[c], p, e,
                    )  # fmt: skip
        return out

    @numba.njit(parallel=True, fastmath=FASTMATH, cache=True)
    def single_mean(xs, xt_t, alpha, block):
        m, d = xs.shape
        n = xt_t.shape[1]
        out = np.empty(m)
        n_blocks = (m + block - 1) // block
        for b in numba.prange(n_blocks):
            r2 = np.empty(n)
            for i in range(b * block, min(m, (b + 1) * block)):
                r2[:] = 0.0
                for j in range(d):
                    xij = xs[i, j]
                    row = xt_t[j]
                    for k in range(n):
                        t = xij - row[k]
                        r2[k] += t * t
                acc = 0.0
                for k in range(n):
                    r = np.sqrt(r2[k])
                    acc += alpha[k] * (1.0 + r) * np.exp(-r)
                out[i] = acc
        return out

    return product_means, single_mean
