"""The weights of adaptive tempered SMC: ESS, resampling and the next gamma (Paper B, eq. 14).

>>> import numpy as np
>>> from fbia.iterators.smc.tempering import EssTempering, ess
>>> loglik = -0.5 * np.random.default_rng(0).normal(size=1000) ** 2 * 100.0
>>> log_w = np.full(1000, -np.log(1000.0))
>>> gamma = EssTempering(zeta=0.9, n=1000).next_gamma(0.0, log_w, loglik, ess_now=1000.0)
>>> round(ess(gamma * loglik) / 1000.0, 6)          # ESS_1 = zeta ESS_0
0.9

Each tempering step solves ESS(gamma_s) = zeta ESS_{s-1} for gamma_s (Algorithm 1). With zeta
close to 1 a run has thousands of steps, so the root finding is most of the bookkeeping:
:class:`EssTempering` runs Newton's method on log ESS in the increment delta = gamma_s -
gamma_{s-1}, with the exact derivative from the same exponential pass, started from the
geometric extrapolation of the previous increments and kept inside a bracket (bisection when a
Newton step leaves it). Two passes over the particles per step are typical, against about ten
for Brent's method on the ESS; the root is the same to round-off (tolerance 1e-10 delta, below
Brent's 1e-10 gamma). Between moves the ESS at gamma = 1 does not change (the weights only gain
multiples of L), so it is computed once per set of particles, not once per step.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: Default step limit, in halvings of the ESS: a step lowers the ESS by the factor zeta, so a
#: run of S steps lowers it by 2^(S log zeta / log 0.5). A 7-D Gaussian likelihood whose
#: posterior is 10^4 times narrower than the prior in every direction needs about 35.
MAX_HALVINGS = 100
#: Lower end of the default step limit (small zeta: few steps that each lose much ESS).
MIN_MAX_STEPS = 1000
#: Relative tolerance of gamma_s (as Brent's method had it: 1e-14 + 1e-10 gamma_s).
GAMMA_RTOL = 1e-10
_MAX_ITER = 100


def logsumexp(a: NDArray[np.float64]) -> float:
    """log sum exp(a) of a 1-D array, -inf when all entries are -inf.

    scipy.special.logsumexp gives the same numbers with ~0.3 ms of array-API overhead per
    call; an SMC run with zeta close to 1 calls this tens of thousands of times.
    """
    m = float(a.max()) if a.size else -math.inf
    if not math.isfinite(m):
        return m
    return m + math.log(float(np.exp(a - m).sum()))


def ess(log_weights: NDArray[np.float64]) -> float:
    """Effective sample size 1 / sum(w_i^2) of normalised weights (eq. 14), from log-weights."""
    m = float(log_weights.max()) if log_weights.size else -math.inf
    if not math.isfinite(m):
        return 0.0
    w = np.exp(log_weights - m)
    return float(w.sum() ** 2 / np.dot(w, w))


def systematic_resample(weights: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.intp]:
    """Indices of a systematic resampling of normalised ``weights`` (one uniform draw)."""
    n = len(weights)
    positions = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    return np.minimum(np.searchsorted(cumulative, positions, side="right"), n - 1)


def cycle_length(zeta: float, ess_min: float) -> float:
    """Tempering steps from one resampling to the next: ESS from N down to ess_min N."""
    return math.log(max(ess_min, 1e-3)) / math.log(zeta)


def default_max_steps(zeta: float) -> int:
    """The step limit that scales with zeta: MAX_HALVINGS halvings of the ESS, at least
    MIN_MAX_STEPS (34 623 steps at zeta = 0.998, 13 829 at 0.995, 1000 at 0.9)."""
    return max(MIN_MAX_STEPS, math.ceil(MAX_HALVINGS * math.log(0.5) / math.log(zeta)))


class EssTempering:
    """The next gamma of adaptive tempering: ESS_s = zeta ESS_{s-1} (Paper B, Algorithm 1).

    Call :meth:`next_gamma` once per step and :meth:`invalidate` whenever the particles move
    or are resampled. ``evaluations`` counts the exponential passes over the particles.

    With f(delta) = log ESS(gamma + delta) - log(zeta ESS_{s-1}), f(0) = -log zeta is known,
    and so are f' and f'' at 0: the previous step ended there (or the weights are equal, f' =
    0, f'' = -2 Var L). The root of the quadratic model is the start of Halley's iteration
    (f, f', f'' from one exponential pass), usually one pass from the root.
    """

    def __init__(self, zeta: float, n: int) -> None:
        self.log_zeta = math.log(zeta)
        self._z = np.empty(n)
        self._u = np.empty(n)
        self._u2 = np.empty(n)
        self.evaluations = 0
        self.invalidate()

    def invalidate(self) -> None:
        """The particles moved or were resampled: forget what was computed from them."""
        self._centred: NDArray[np.float64] | None = None
        self._centred2: NDArray[np.float64] | None = None
        self._all_finite = True
        self._finite: NDArray[np.bool_] | None = None
        self._log_ess_at_one: float | None = None
        self._slopes: tuple[float, float, float] | None = None  # f', f'', f''' at the end

    def _log_ess(
        self, delta: float, log_w: NDArray[np.float64], loglik: NDArray[np.float64], slope: bool
    ) -> tuple[float, float, float]:
        """log ESS of the weights w exp(delta L) (delta > 0) and, with ``slope``, its first
        and second derivatives in delta.

        With u = w exp(delta L) (shifted by its largest entry), ESS = (sum u)^2 / sum u^2,
        d log ESS = 2 (E_u L - E_u2 L), d^2 log ESS = 2 Var_u L - 4 Var_u2 L, where E_u and
        Var_u weigh with u, E_u2 and Var_u2 with u^2.
        """
        self.evaluations += 1
        z, u, u2 = self._z, self._u, self._u2
        np.multiply(loglik, delta, out=z)
        z += log_w
        m = float(z.max())
        if not math.isfinite(m):
            return -math.inf, math.nan, math.nan
        z -= m
        np.exp(z, out=u)
        s1 = float(u.sum())
        np.multiply(u, u, out=u2)
        s2 = float(u2.sum())
        log_ess = 2.0 * math.log(s1) - math.log(s2)
        if not slope:
            return log_ess, math.nan, math.nan
        assert self._centred is not None and self._centred2 is not None
        mean1, mean2 = float(u @ self._centred) / s1, float(u2 @ self._centred) / s2
        var1 = float(u @ self._centred2) / s1 - mean1 * mean1
        var2 = float(u2 @ self._centred2) / s2 - mean2 * mean2
        return log_ess, 2.0 * (mean1 - mean2), 2.0 * var1 - 4.0 * var2

    def _prepare(self, loglik: NDArray[np.float64]) -> None:
        finite = np.isfinite(loglik)
        self._all_finite = bool(finite.all())
        self._finite = None if self._all_finite else finite
        top = float(loglik[finite].max())
        self._centred = np.where(finite, loglik - top, 0.0)
        self._centred2 = self._centred * self._centred

    def _slopes_at_zero(self, log_w: NDArray[np.float64]) -> tuple[float, float, float]:
        """f'(0), f''(0): carried over from the last step, or from the current weights."""
        if self._slopes is not None:
            return self._slopes
        assert self._centred is not None and self._centred2 is not None
        kept = log_w if self._finite is None else np.where(self._finite, log_w, -np.inf)
        w = np.exp(kept - float(kept.max()))
        if self._all_finite and float(w.min()) == 1.0:  # equal weights: f'(0) = 0
            return 0.0, -2.0 * float(np.var(self._centred)), 0.0
        self.evaluations += 1
        w2 = w * w
        s1, s2 = float(w.sum()), float(w2.sum())
        mean1, mean2 = float(w @ self._centred) / s1, float(w2 @ self._centred) / s2
        var1 = float(w @ self._centred2) / s1 - mean1 * mean1
        var2 = float(w2 @ self._centred2) / s2 - mean2 * mean2
        return 2.0 * (mean1 - mean2), 2.0 * var1 - 4.0 * var2, 0.0

    def next_gamma(
        self,
        gamma: float,
        log_w: NDArray[np.float64],
        loglik: NDArray[np.float64],
        ess_now: float,
    ) -> float:
        """gamma_s with ESS_s = zeta ``ess_now``, or 1 when no smaller one exists.

        ``log_w`` are the current log-weights (with ESS ``ess_now``), ``loglik`` the
        log-likelihood at the particles (-inf allowed: such particles get weight 0 at any
        gamma above the current one).
        """
        log_target = self.log_zeta + math.log(ess_now)
        if self._centred is None:
            self._prepare(loglik)
        f0 = -self.log_zeta
        if not self._all_finite:
            # dropping the zero-likelihood particles may already cost more than zeta
            kept = ess(np.where(np.isfinite(loglik), log_w, -np.inf))
            if kept < math.exp(log_target):
                return float(np.nextafter(gamma, 2.0))
            f0 = math.log(kept) - log_target
        delta_max = 1.0 - gamma
        if self._log_ess_at_one is None:
            self._log_ess_at_one = self._log_ess(delta_max, log_w, loglik, slope=False)[0]
        if self._log_ess_at_one >= log_target:
            return 1.0
        delta = self._solve(gamma, delta_max, log_w, loglik, log_target, f0)
        new_gamma = min(gamma + delta, 1.0)
        if new_gamma <= gamma:
            return float(np.nextafter(gamma, 2.0))
        return new_gamma

    def _solve(
        self,
        gamma: float,
        delta_max: float,
        log_w: NDArray[np.float64],
        loglik: NDArray[np.float64],
        log_target: float,
        f0: float,
    ) -> float:
        """The root of log ESS(delta) = log target in (0, delta_max): Halley's method from the
        root of the quadratic model at 0, kept inside a bracket (bisection when it leaves)."""
        lo, hi = 0.0, delta_max  # log ESS above the target at lo, below it at hi
        s0, c0, t0 = self._slopes_at_zero(log_w)
        disc = s0 * s0 - 2.0 * c0 * f0
        delta = 2.0 * f0 / (math.sqrt(disc) - s0) if disc >= 0 and math.sqrt(disc) > s0 else -1.0
        for _ in range(2 if delta > 0.0 else 0):  # Newton on the cubic model (f''' = t0)
            slope = s0 + c0 * delta + 0.5 * t0 * delta * delta
            if slope < 0.0:
                delta -= (f0 + delta * (s0 + delta * (0.5 * c0 + delta * t0 / 6.0))) / slope
        # error allowed in gamma_s: Brent's tolerance in the previous implementation
        tol = 1e-14 + GAMMA_RTOL * gamma
        for _ in range(_MAX_ITER):
            if not lo < delta < hi:
                delta = 0.5 * (lo + hi)
            f, d1, d2 = self._log_ess(delta, log_w, loglik, slope=True)
            delta_eval = delta
            f -= log_target
            if f > 0.0:
                lo = delta
            elif f < 0.0:
                hi = delta
            else:
                break
            step = math.nan
            if d1 < 0.0:
                newton = f / d1
                denom = 1.0 - 0.5 * newton * d2 / d1
                step = newton / denom if denom > 0.5 else newton
            new = delta - step
            if lo < new < hi:
                # Halley converges cubically: the error of ``new`` is about |step|^3 / delta^2
                if abs(step) ** 3 <= 0.01 * (tol + GAMMA_RTOL * new) * new * new:
                    delta = new
                    break
                delta = new
            else:  # left the bracket (or log ESS rises here): bisect
                delta = 0.5 * (lo + hi)
                if hi - lo <= tol + GAMMA_RTOL * delta:
                    break
        # f', f'' and f''' where the next step starts (Taylor from the last evaluation)
        t1 = (d2 - c0) / delta_eval
        h = delta - delta_eval
        self._slopes = (d1 + h * (d2 + 0.5 * h * t1), d2 + h * t1, t1)
        return delta
